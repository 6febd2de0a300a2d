"""Theorem 1(2): ``dM̄/dt − 2C̄`` is skew along trajectories, with (Cbar2) and a Christoffel C.

Three hand-written mechanisms (M(q), f_g(q), A(q), Ȧ(q, qd)); Christoffel symbols by
complex-step differentiation of M(q) (exact to round-off). A short trajectory is integrated
with scipy's ``solve_ivp`` (DOP853, tight tolerances) using ``nonmin.core.forward_dynamics``;
at sample times ``dM̄/dt`` is a central difference in time of ``M̄(q(t))`` (constant μ) on the
dense output, and ``dM̄/dt − 2C̄`` must be skew relative to its norm.

(a) four-bar in dependent absolute joint angles (n = 3, two loop-closure rows);
(b) point pendulum in Cartesian coordinates (n = 2, M constant, C = 0);
(c) free rigid body with a unit quaternion (n = 7, M singular along the quaternion direction,
    norm constraint).

Also: the finite-difference dM̄/dt equals the analytic ``ṖMP + PṀP + PMṖ − μṖ`` with
``Ṗ = ΛP + PΛᵀ`` (eq. (OmegaP), Appendix A); eq. (EqMotion2) ``M̄qdd + C̄qd = P(f + f_g)``
holds; and the paper's other form ``C̄' = PC + (PM − μI)Ω`` gives the same ``C̄'qd = C̄qd`` but
is NOT skew (ERRATA 3).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from nonmin.core import (
    constraint_inertia,
    coriolis_bar,
    forward_dynamics,
    lambda_matrix,
    nullspace_projector,
    optimal_virtual_mass,
    projector_derivative,
)

#: ‖sym(dM̄/dt − 2C̄)‖ / ‖dM̄/dt − 2C̄‖ (limited by the time finite difference, ~1e-10 here).
SKEW_RTOL = 1e-7
#: finite-difference dM̄/dt against the analytic ṖMP + PṀP + PMṖ − μṖ.
FD_RTOL = 1e-7
#: residual of (EqMotion2) relative to ‖P f_g‖ + ‖C̄qd‖.
EQ_RTOL = 1e-8
#: the wrong form C̄' must miss skewness by at least this much (it is O(1) in practice).
NOT_SKEW_MIN = 1e-2
#: time step of the 4th-order central difference, integration tolerances, sample times
DELTA = 2.5e-4
RTOL_IVP, ATOL_IVP = 1e-12, 1e-12
T_SAMPLES = (0.07, 0.19, 0.33, 0.46)
T_END = 0.5
CSTEP = 1e-30


@dataclass(frozen=True)
class Mechanism:
    name: str
    mass: Callable[[np.ndarray], np.ndarray]  # complex-safe
    gravity: Callable[[np.ndarray], np.ndarray]
    jac: Callable[[np.ndarray], np.ndarray]
    jac_dot: Callable[[np.ndarray, np.ndarray], np.ndarray]
    q0: np.ndarray
    qd0: np.ndarray


def mass_derivatives(mech: Mechanism, q: np.ndarray) -> np.ndarray:
    """D[k] = ∂M/∂q_k by complex step (exact to round-off for analytic M)."""
    n = q.size
    D = np.empty((n, n, n))
    for k in range(n):
        qc = q.astype(complex)
        qc[k] += 1j * CSTEP
        D[k] = mech.mass(qc).imag / CSTEP
    return D


def christoffel(mech: Mechanism, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
    """C_ij = Σ_k ½(∂_k M_ij + ∂_j M_ik − ∂_i M_jk) qd_k."""
    D = mass_derivatives(mech, q)
    t1 = np.einsum("kij,k->ij", D, qd)
    t2 = np.einsum("jik,k->ij", D, qd)
    t3 = np.einsum("ijk,k->ij", D, qd)
    return 0.5 * (t1 + t2 - t3)


def rhs(mech: Mechanism):
    def f(_t, y):
        n = y.size // 2
        q, qd = y[:n], y[n:]
        M = mech.mass(q).real
        h = mech.gravity(q) - christoffel(mech, q, qd) @ qd
        A = mech.jac(q)
        qdd = forward_dynamics(M, h, A, mech.jac_dot(q, qd) @ qd)
        return np.concatenate([qd, qdd])

    return f


# --------------------------------------------------------------------------- (a) four-bar

L0, L1, L2, L3 = 1.0, 0.4, 1.2, 0.9
m1, m2, m3, G = 1.0, 1.5, 1.2, 9.81


def _fourbar_mass(q):
    c12 = np.cos(q[0] - q[1])
    z = 0 * q[0]  # keeps complex type under complex step
    return np.array(
        [
            [m1 * L1**2 / 3 + m2 * L1**2 + z, m2 * L1 * L2 / 2 * c12, z],
            [m2 * L1 * L2 / 2 * c12, m2 * L2**2 / 3 + z, z],
            [z, z, m3 * L3**2 / 3 + z],
        ]
    )


def _fourbar_gravity(q):
    c = np.cos(q)
    return -G * np.array([(m1 * L1 / 2 + m2 * L1) * c[0], m2 * L2 / 2 * c[1], m3 * L3 / 2 * c[2]])


def _fourbar_jac(q):
    s, c = np.sin(q), np.cos(q)
    return np.array([[-L1 * s[0], -L2 * s[1], L3 * s[2]], [L1 * c[0], L2 * c[1], -L3 * c[2]]])


def _fourbar_jac_dot(q, qd):
    s, c = np.sin(q), np.cos(q)
    return np.array(
        [
            [-L1 * c[0] * qd[0], -L2 * c[1] * qd[1], L3 * c[2] * qd[2]],
            [-L1 * s[0] * qd[0], -L2 * s[1] * qd[1], L3 * s[2] * qd[2]],
        ]
    )


def _fourbar_initial():
    th1 = 1.0
    tip = L1 * np.array([np.cos(th1), np.sin(th1)])
    piv = np.array([L0, 0.0])
    d = np.linalg.norm(piv - tip)
    a = (L2**2 - L3**2 + d**2) / (2 * d)
    hgt = np.sqrt(L2**2 - a**2)
    u = (piv - tip) / d
    J = tip + a * u + hgt * np.array([-u[1], u[0]])  # upper assembly
    q0 = np.array([th1, *np.arctan2(*(J - tip)[::-1]).reshape(1), np.arctan2(J[1], J[0] - L0)])
    A = _fourbar_jac(q0)
    x = np.linalg.solve(A[:, 1:], -A[:, 0] * 2.0)
    return q0, np.array([2.0, *x])


FOURBAR = Mechanism("fourbar", _fourbar_mass, _fourbar_gravity, _fourbar_jac, _fourbar_jac_dot,
                    *_fourbar_initial())

# --------------------------------------------------------------------------- (b) pendulum

MP, LP = 0.8, 1.3


def _pend_mass(q):
    return MP * np.eye(2) + 0 * q[0]


PENDULUM = Mechanism(
    "pendulum",
    _pend_mass,
    lambda q: np.array([0.0, -MP * G]),
    lambda q: q[None, :].copy(),
    lambda q, qd: qd[None, :].copy(),
    LP * np.array([np.sin(0.5), -np.cos(0.5)]),
    1.5 * np.array([np.cos(0.5), np.sin(0.5)]),
)

# --------------------------------------------------------------------------- (c) rigid body

MB = 2.0
JB = np.diag([0.1, 0.2, 0.3])


def _G(e):
    w, x, y, z = e
    return np.array([[-x, w, z, -y], [-y, -z, w, x], [-z, y, -x, w]])


def _body_mass(q):
    Gm = _G(q[3:])
    M = np.zeros((7, 7), dtype=np.result_type(q, float))
    M[:3, :3] = MB * np.eye(3)
    M[3:, 3:] = 4.0 * Gm.T @ JB @ Gm  # singular: G e = 0
    return M


def _body_initial():
    e = np.array([0.9, 0.2, -0.3, 0.25])
    e /= np.linalg.norm(e)
    omega = np.array([3.0, 0.5, -1.0])  # tumbling about the intermediate axis
    ed = 0.5 * _G(e).T @ omega
    return np.concatenate([np.zeros(3), e]), np.concatenate([[1.0, 0.0, 2.0], ed])


BODY = Mechanism(
    "rigid_body_quaternion",
    _body_mass,
    lambda q: np.array([0.0, 0.0, -MB * G, 0.0, 0.0, 0.0, 0.0]),
    lambda q: np.concatenate([np.zeros(3), q[3:]])[None, :],
    lambda q, qd: np.concatenate([np.zeros(3), qd[3:]])[None, :],
    *_body_initial(),
)

MECHANISMS = [FOURBAR, PENDULUM, BODY]


# --------------------------------------------------------------------------- the checks


def _trajectory(mech: Mechanism):
    y0 = np.concatenate([mech.q0, mech.qd0])
    sol = solve_ivp(rhs(mech), (0.0, T_END), y0, method="DOP853", rtol=RTOL_IVP, atol=ATOL_IVP,
                    dense_output=True)
    assert sol.success, sol.message
    return sol


def _mbar_at(mech: Mechanism, q, mu):
    P, _ = nullspace_projector(mech.jac(q))
    return constraint_inertia(mech.mass(q).real, P, mu)


def _sym_ratio(D):
    return float(np.linalg.norm(D + D.T) / np.linalg.norm(D))


@pytest.fixture(scope="module", params=MECHANISMS, ids=[m.name for m in MECHANISMS])
def sampled(request):
    mech = request.param
    sol = _trajectory(mech)
    n = mech.q0.size
    P0, _ = nullspace_projector(mech.jac(mech.q0))
    # any constant μ > 0 (Theorem 1); 2.5× the optimum so that M̄ is not a multiple of I for the
    # pendulum (with μ = m it is, and the test would be trivial)
    mu = 2.5 * float(optimal_virtual_mass(mech.mass(mech.q0).real, P0))
    out = []
    for t in T_SAMPLES:
        y = sol.sol(t)
        q, qd = y[:n], y[n:]
        Mb = {k: _mbar_at(mech, sol.sol(t + k * DELTA)[:n], mu) for k in (-2, -1, 1, 2)}
        Mbar_dot = (Mb[-2] - 8 * Mb[-1] + 8 * Mb[1] - Mb[2]) / (12 * DELTA)
        out.append((q, qd, Mbar_dot))
    return mech, mu, out, sol


def test_mass_matrix_singularity_of_quaternion_body():
    """Case (c) really has M singular along the quaternion direction (and PD on N(A))."""
    q = BODY.q0
    M = BODY.mass(q)
    ev = np.linalg.eigvalsh(M)
    assert ev.min() <= 1e-14 * ev.max()
    assert np.linalg.norm(M @ np.concatenate([np.zeros(3), q[3:]])) <= 1e-14
    P, _ = nullspace_projector(BODY.jac(q))
    assert np.linalg.eigvalsh(P @ M @ P + np.eye(7) - P).min() > 1e-3


def test_dMbar_dt_minus_2Cbar_is_skew(sampled):
    mech, mu, samples, _ = sampled
    for q, qd, Mbar_dot in samples:
        M = mech.mass(q).real
        C = christoffel(mech, q, qd)
        Cbar = coriolis_bar(M, C, mech.jac(q), mech.jac_dot(q, qd), mu)
        D = Mbar_dot - 2 * Cbar
        assert np.linalg.norm(D) > 1e-3  # not trivially zero
        assert _sym_ratio(D) <= SKEW_RTOL, (mech.name, _sym_ratio(D))


def test_finite_difference_matches_projector_derivative(sampled):
    """dM̄/dt = ṖMP + PṀP + PMṖ − μṖ with Ṗ = ΛP + PΛᵀ (eq. (OmegaP), Appendix A)."""
    mech, mu, samples, _ = sampled
    for q, qd, Mbar_dot in samples:
        M = mech.mass(q).real
        Mdot = np.einsum("kij,k->ij", mass_derivatives(mech, q), qd)
        A, Adot = mech.jac(q), mech.jac_dot(q, qd)
        P, _ = nullspace_projector(A)
        Pd = projector_derivative(A, Adot)
        analytic = Pd @ M @ P + P @ Mdot @ P + P @ M @ Pd - mu * Pd
        err = np.linalg.norm(Mbar_dot - analytic) / np.linalg.norm(analytic)
        assert err <= FD_RTOL, (mech.name, err)


def test_eq_motion2_holds_along_trajectory(sampled):
    """M̄ qdd + C̄ qd = P (f + f_g) (eq. (EqMotion2)) with qdd from forward_dynamics."""
    mech, mu, samples, _ = sampled
    for q, qd, _ in samples:
        M = mech.mass(q).real
        C = christoffel(mech, q, qd)
        A, Adot = mech.jac(q), mech.jac_dot(q, qd)
        P, _ = nullspace_projector(A)
        qdd = forward_dynamics(M, mech.gravity(q) - C @ qd, A, Adot @ qd)
        Cbar = coriolis_bar(M, C, A, Adot, mu)
        lhs = constraint_inertia(M, P, mu) @ qdd + Cbar @ qd
        rhs_ = P @ mech.gravity(q)
        scale = np.linalg.norm(rhs_) + np.linalg.norm(Cbar @ qd)
        assert np.linalg.norm(lhs - rhs_) <= EQ_RTOL * scale, mech.name


def test_other_form_Cbar_prime_is_not_skew(sampled):
    """ERRATA 3: C̄' = PC + (PM − μI)Ω has C̄'qd = C̄qd but dM̄/dt − 2C̄' is not skew."""
    mech, mu, samples, _ = sampled
    worst = 0.0
    for q, qd, Mbar_dot in samples:
        M = mech.mass(q).real
        C = christoffel(mech, q, qd)
        A, Adot = mech.jac(q), mech.jac_dot(q, qd)
        P, _ = nullspace_projector(A)
        Lam = lambda_matrix(A, Adot)
        Om = Lam - Lam.T
        Cp = P @ C + (P @ M - mu * np.eye(q.size)) @ Om
        Cbar = coriolis_bar(M, C, A, Adot, mu)
        assert np.linalg.norm(Cp @ qd - Cbar @ qd) <= EQ_RTOL * np.linalg.norm(Cbar @ qd)
        worst = max(worst, _sym_ratio(Mbar_dot - 2 * Cp))
    assert worst >= NOT_SKEW_MIN, (mech.name, worst)


def test_skewness_needs_the_christoffel_C():
    """Another valid factorization C_alt (same C_alt qd = C qd) breaks skewness (ERRATA 3):
    ``C_alt = Ṁ − ½ [qdᵀ ∂M/∂q_i]_i``. Shows the skew test is sensitive to the choice of C.

    On the rigid body (dim N = 6): with a one-dimensional N (the four-bar) ``P X P`` is a
    multiple of ``zzᵀ`` and the difference is invisible."""
    mech = BODY
    sol = _trajectory(mech)
    n = mech.q0.size
    y = sol.sol(T_SAMPLES[1])
    q, qd = y[:n], y[n:]
    D = mass_derivatives(mech, q)
    C = christoffel(mech, q, qd)
    C_alt = np.einsum("kij,k->ij", D, qd) - 0.5 * np.einsum("ijk,j->ik", D, qd)
    assert np.linalg.norm(C_alt @ qd - C @ qd) <= 1e-12 * np.linalg.norm(C @ qd)
    M, A, Adot = mech.mass(q).real, mech.jac(q), mech.jac_dot(q, qd)
    P, _ = nullspace_projector(A)
    mu = float(optimal_virtual_mass(M, P))
    Pd = projector_derivative(A, Adot)
    Mbar_dot = Pd @ M @ P + P @ np.einsum("kij,k->ij", D, qd) @ P + P @ M @ Pd - mu * Pd
    good = Mbar_dot - 2 * coriolis_bar(M, C, A, Adot, mu)
    bad = Mbar_dot - 2 * coriolis_bar(M, C_alt, A, Adot, mu)
    assert _sym_ratio(good) <= SKEW_RTOL
    assert _sym_ratio(bad) >= NOT_SKEW_MIN


def test_projector_derivative_matches_finite_difference(sampled):
    """Ṗ = ΛP + PΛᵀ (eq. (OmegaP), Appendix A (dotP-A+)) against dP/dt along the trajectory."""
    mech, _, _, sol = sampled
    n = mech.q0.size
    for t in T_SAMPLES:
        y = sol.sol(t)
        q, qd = y[:n], y[n:]
        Pk = {k: nullspace_projector(mech.jac(sol.sol(t + k * DELTA)[:n]))[0] for k in (-2, -1, 1, 2)}
        Pdot_fd = (Pk[-2] - 8 * Pk[-1] + 8 * Pk[1] - Pk[2]) / (12 * DELTA)
        Pdot = projector_derivative(mech.jac(q), mech.jac_dot(q, qd))
        assert np.linalg.norm(Pdot - Pdot_fd) <= FD_RTOL * np.linalg.norm(Pdot), mech.name
