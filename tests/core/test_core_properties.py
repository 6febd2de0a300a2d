"""Property tests (hypothesis) of the projectors and the constraint inertia (issue #2).

Random SPD M, and coupled singular M that is positive definite only on N(A); A full rank,
rank deficient, with duplicated rows, zero rows, all zero, m > n and m = 0.
"""

from __future__ import annotations

import numpy as np
import pytest
from core_testlib import (
    EIG_RTOL,
    MU_RTOL,
    OBLIQUE_RTOL,
    PROJ_TOL,
    basis_of_nullspace,
    rel,
    systems,
)
from hypothesis import given
from hypothesis import strategies as st

from nonmin.core import (
    actuation_projectors,
    constraint_force_projector,
    constraint_inertia,
    forward_dynamics,
    lambda_matrix,
    nullspace_projector,
    optimal_virtual_mass,
)
from nonmin.errors import InfeasibleActuationError

both_masses = st.booleans().flatmap(lambda s: systems(singular_mass=s))


@given(systems())
def test_nullspace_projector_is_orthogonal_projector_onto_nullspace(sys_):
    _M, A, r, _ = sys_
    n = A.shape[1]
    P, rank = nullspace_projector(A)
    assert int(rank) == r
    assert np.abs(P @ P - P).max() <= PROJ_TOL
    assert np.abs(P - P.T).max() <= PROJ_TOL
    if A.shape[0]:
        assert np.abs(A @ P).max() <= PROJ_TOL * max(np.abs(A).max(), 1.0) * n
    # P is exactly the projector onto an independently computed null space basis
    Z = basis_of_nullspace(A, r)
    assert np.abs(P - Z @ Z.T).max() <= 1e3 * PROJ_TOL
    assert abs(np.trace(P) - (n - r)) <= PROJ_TOL * n


@given(both_masses)
def test_constraint_force_projector_identities(sys_):
    """S² = S, QS = S, SQ = Q, PS = 0, M Sᵀ = S M (eqs. (S_definition), ((I-P)R))."""
    M, A, _r, _ = sys_
    n = A.shape[1]
    P, _ = nullspace_projector(A)
    Q = np.eye(n) - P
    mu = optimal_virtual_mass(M, P)
    S = constraint_force_projector(M, P, mu)
    scale = max(np.linalg.norm(S), 1.0)
    tol = OBLIQUE_RTOL * scale**2
    assert np.abs(S @ S - S).max() <= tol
    assert np.abs(Q @ S - S).max() <= tol
    assert np.abs(S @ Q - Q).max() <= tol
    assert np.abs(P @ S).max() <= tol
    MS = np.abs(M).max() * scale
    assert np.abs(M @ S.T - S @ M).max() <= OBLIQUE_RTOL * MS
    # independent of μ
    S2 = constraint_force_projector(M, P, 1e3 * mu)
    assert np.abs(S2 - S).max() <= MU_RTOL * scale


@given(both_masses)
def test_constraint_inertia_inverse_and_spectrum(sys_):
    """M̄⁻¹P = P M̄⁻¹ = (PMP)⁺ (Appendix C); λ(M̄) = {μ (r times)} ∪ nonzero λ(PMP) (lamb(M_bar))."""
    M, A, r, _ = sys_
    n = A.shape[1]
    P, _ = nullspace_projector(A)
    mu = float(optimal_virtual_mass(M, P))
    Mbar = constraint_inertia(M, P, mu)
    assert np.abs(Mbar - Mbar.T).max() <= PROJ_TOL * np.abs(Mbar).max()
    Z = basis_of_nullspace(A, r)
    # (PMP)⁺ from the reduced matrix ZᵀMZ (independent of nonmin): Z (ZᵀMZ)⁻¹ Zᵀ
    pinv_pmp = Z @ np.linalg.solve(Z.T @ M @ Z, Z.T) if n - r else np.zeros((n, n))
    Minv = np.linalg.inv(Mbar)
    scale = np.abs(pinv_pmp).max() + 1e-300
    assert np.abs(Minv @ P - pinv_pmp).max() <= OBLIQUE_RTOL * max(scale, 1.0 / mu)
    assert np.abs(P @ Minv - Minv @ P).max() <= OBLIQUE_RTOL * max(scale, 1.0 / mu)
    # spectrum
    ev = np.sort(np.linalg.eigvalsh(Mbar))
    red = np.linalg.eigvalsh(Z.T @ M @ Z) if n - r else np.zeros(0)
    expected = np.sort(np.concatenate([np.full(r, mu), red]))
    assert np.abs(ev - expected).max() <= EIG_RTOL * ev.max()
    # the optimal μ lies in [λmin≠0(PMP), λmax(PMP)] (optimum_mu), so cond(M̄) = cond(ZᵀMZ)
    if n - r:
        assert red.min() * (1 - EIG_RTOL) <= mu <= red.max() * (1 + EIG_RTOL)
        cond = ev.max() / ev.min()
        assert abs(cond - red.max() / red.min()) <= EIG_RTOL * cond * 10


@given(both_masses)
def test_acceleration_is_independent_of_virtual_mass(sys_):
    M, A, _r, rng = sys_
    n, m = A.shape[1], A.shape[0]
    mscale = np.abs(M).max() or 1.0  # M = 0 happens: fully constrained, singular M
    h = rng.standard_normal(n) * mscale
    gamma = A @ rng.standard_normal(n)  # consistent bias
    P, _ = nullspace_projector(A)
    mu = float(optimal_virtual_mass(M, P))
    q0 = forward_dynamics(M, h, A, gamma)
    q1 = forward_dynamics(M, h, A, gamma, mu=1e-3 * mu)
    q2 = forward_dynamics(M, h, A, gamma, mu=1e3 * mu)
    s = np.linalg.norm(q0) + np.linalg.norm(h) / mscale
    assert rel(q1, q0, s) <= MU_RTOL
    assert rel(q2, q0, s) <= MU_RTOL
    if m:
        assert np.linalg.norm(A @ q0 + gamma) <= REF_ABS * (np.linalg.norm(A) * s + 1.0)


REF_ABS = 1e-10


@given(systems(), st.integers(0, 2**32 - 1), st.sampled_from(["generic", "redundant", "identity"]))
def test_actuation_projectors_feasible(sys_, seed, btype):
    """R² = R, RP = R, RQ = 0, PR = P and Γ = (PB)⁺ when rank(PB) = n − r (ERRATA 4)."""
    _, A, r, _ = sys_
    n = A.shape[1]
    rng = np.random.default_rng([seed, 7])  # a stream distinct from the one that made A
    if btype == "identity":
        B = np.eye(n)
    else:
        k = (n - r) + (0 if btype == "generic" else int(rng.integers(1, 4)))
        B = rng.standard_normal((n, max(k, 1)))
    P, _ = nullspace_projector(A)
    R, Gamma = actuation_projectors(B, P)
    s = max(np.linalg.norm(R), 1.0)
    assert np.abs(R @ R - R).max() <= OBLIQUE_RTOL * s**2
    assert np.abs(R @ P - R).max() <= OBLIQUE_RTOL * s
    assert np.abs(R @ (np.eye(n) - P)).max() <= OBLIQUE_RTOL * s
    assert np.abs(P @ R - P).max() <= OBLIQUE_RTOL * s
    # independent Γ: with Z an orthonormal basis of N, (PB)⁺ = (ZᵀB)⁺Zᵀ, ZᵀB full row rank
    Z = basis_of_nullspace(A, r)
    ZB = Z.T @ B
    Gamma_ref = ZB.T @ np.linalg.solve(ZB @ ZB.T, Z.T) if n - r else np.zeros((B.shape[1], n))
    assert np.abs(Gamma - Gamma_ref).max() <= OBLIQUE_RTOL * s * max(np.abs(Gamma_ref).max(), 1)
    # u = Γ f_∥ reproduces every admissible force: P B Γ f_∥ = f_∥
    f_par = P @ rng.standard_normal(n)
    assert np.linalg.norm(P @ B @ (Gamma @ f_par) - f_par) <= OBLIQUE_RTOL * s * (
        np.linalg.norm(f_par) + 1
    )


@given(systems(kinds=("full", "deficient", "duplicated", "zero_rows", "all_zero", "empty")),
       st.integers(0, 2**32 - 1))
def test_actuation_projectors_infeasible_raise(sys_, seed):
    """rank(PB) < n − r raises InfeasibleActuationError (too few actuators for N(A))."""
    _, A, r, _ = sys_
    n = A.shape[1]
    if n - r == 0:
        return
    rng = np.random.default_rng([seed, 7])  # a stream distinct from the one that made A
    B = rng.standard_normal((n, n - r - 1)) if n - r > 1 else np.zeros((n, 1))
    P, _ = nullspace_projector(A)
    with pytest.raises(InfeasibleActuationError, match=r"rank\(PB\) = \d+ < n − rank\(A\) = \d+"):
        actuation_projectors(B, P)


def test_actuation_pendulum_horizontal_force_is_feasible():
    """ERRATA 4: N ⊆ R(B) is not necessary: a pendulum pushed horizontally is actuated."""
    q = np.array([np.sin(0.3), -np.cos(0.3)])
    P, _ = nullspace_projector(q[None, :])
    B = np.array([[1.0], [0.0]])
    R, _ = actuation_projectors(B, P)
    assert np.allclose(P @ R, P, atol=PROJ_TOL)


@given(systems(kinds=("full", "deficient", "duplicated", "zero_rows", "wide")))
def test_lambda_annihilated_by_P_and_Q_Omega_only_on_admissible_velocities(sys_):
    """PΛ = ΛᵀP = 0 (eq. (PLambda)); QΩqd = Ωqd = Λqd for qd ∈ N, but QΩ ≠ Ω (ERRATA 3)."""
    _, A, r, rng = sys_
    n = A.shape[1]
    Adot = (A @ np.linalg.pinv(A)) @ rng.standard_normal(A.shape)  # Ȧ consistent with A
    Lam = lambda_matrix(A, Adot)
    P, _ = nullspace_projector(A)
    Q = np.eye(n) - P
    s = max(np.abs(Lam).max(), 1.0)
    assert np.abs(P @ Lam).max() <= PROJ_TOL * s * n
    assert np.abs(Lam.T @ P).max() <= PROJ_TOL * s * n
    Om = Lam - Lam.T
    qd = basis_of_nullspace(A, r) @ rng.standard_normal(n - r)
    assert np.abs(Q @ Om @ qd - Om @ qd).max() <= PROJ_TOL * s * n * (1 + np.abs(qd).max())
    assert np.abs(Om @ qd - Lam @ qd).max() <= PROJ_TOL * s * n * (1 + np.abs(qd).max())
    # as matrices QΩ − Ω = PΛᵀ, which is not zero in general
    assert np.abs((Q @ Om - Om) - P @ Lam.T).max() <= PROJ_TOL * s * n


@given(both_masses, st.integers(0, 2**32 - 1))
def test_row_scaling_of_A_changes_nothing(sys_, seed):
    """Rows of A (and γ) scaled by 10^±4: same rank, P and qdd (row equilibration, policy 2).

    (Row norms that differ by more than 1/rtol = 1e10 are not covered: policy 1 then declares
    the small row vanished; see test_rank_tolerance_is_observable_and_overridable.)"""
    M, A, r, rng = sys_
    n, m = A.shape[1], A.shape[0]
    scale = 10.0 ** np.random.default_rng([seed, 3]).uniform(-4, 4, m)
    mscale = np.abs(M).max() or 1.0
    h = rng.standard_normal(n) * mscale
    gamma = A @ rng.standard_normal(n)
    P, rank = nullspace_projector(A)
    Ps, rank_s = nullspace_projector(A * scale[:, None])
    assert int(rank_s) == int(rank) == r
    assert np.abs(Ps - P).max() <= 1e3 * PROJ_TOL
    q0 = forward_dynamics(M, h, A, gamma)
    q1 = forward_dynamics(M, h, A * scale[:, None], gamma * scale)
    s = np.linalg.norm(q0) + np.linalg.norm(h) / mscale
    assert rel(q1, q0, s) <= MU_RTOL


def test_rank_tolerance_is_observable_and_overridable():
    """A row that is dependent up to 1e-8 (relative): independent at the default rtol = 1e-10,
    dependent at rtol = 1e-6; the rank used is returned and the result follows it."""
    A = np.array([[1.0, 0.0, 0.0], [1.0, 1e-8, 0.0]])
    M = np.diag([1.0, 2.0, 3.0])
    h = np.array([1.0, -1.0, 0.5])
    _, r_default = nullspace_projector(A)
    _, r_loose = nullspace_projector(A, rtol=1e-6)
    assert (int(r_default), int(r_loose)) == (2, 1)
    q_default = forward_dynamics(M, h, A, np.zeros(2))
    q_loose = forward_dynamics(M, h, A, np.zeros(2), rtol=1e-6)
    assert abs(q_default[1]) <= 1e-12  # second coordinate fixed too
    # second coordinate (almost) free: the kept direction is (1, 5e-9, 0)
    assert abs(q_loose[1] - h[1] / M[1, 1]) <= 1e-8
    # policy 1: a row whose norm is ≤ rtol·max row norm has vanished (rank 1, not 2)
    _, r_vanished = nullspace_projector(np.array([[1.0, 0.0, 0.0], [0.0, 1e-11, 0.0]]))
    assert int(r_vanished) == 1
