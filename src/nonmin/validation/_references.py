"""Reference solutions and scores used by the validation suite.

* tabulated exact solutions shipped in ``nonmin/data/validation`` (A01, A02 N = 2, A03),
* the exact 1-DOF reduction of the A02 N four-bar in its parallelogram mode,
* the period of A04 Bricard's mechanism by quadrature of its 1-DOF energy integral,
* the Test Set for IVP Solvers' significant-digit score.
"""

from __future__ import annotations

import math
from importlib import resources

import numpy as np
from numpy.typing import NDArray
from scipy.integrate import solve_ivp

from ..errors import InputError, ShapeError

__all__ = [
    "A02_N2_B0_AT_10S",
    "A02_N2_VB0_AT_10S",
    "a02_parallelogram_reference",
    "a04_bricard_period",
    "load_a01_exact",
    "load_a02_n2_exact",
    "load_a03_reference",
    "significant_digits",
]

FloatArray = NDArray[np.float64]

#: A02, N = 2: B0 at t = 10 s in the parallelogram mode (benchmark statement).
A02_N2_B0_AT_10S = (0.3284581115, 0.9445185382)
#: A02, N = 2: velocity of B0 at t = 10 s.
A02_N2_VB0_AT_10S = (1.4230514702, -0.4948688455)



def _load_csv(name: str) -> FloatArray:
    ref = resources.files("nonmin").joinpath("data", "validation", name)
    with resources.as_file(ref) as p:
        return np.loadtxt(p, delimiter=",", comments="#", dtype=np.float64)


def load_a01_exact(horizon: float = 2000.0) -> FloatArray:
    """Exact A01 pendulum solution (Jacobi elliptic functions), start at (+1, 0).

    Parameters
    ----------
    horizon : {10.0, 2000.0}
        10 s file (0.01 s steps) or 2000 s file (0.5 s steps).

    Returns
    -------
    ndarray, shape (N, 5)
        Columns t, x, y, vx, vy of point P1.
    """
    if horizon == 10.0:
        return _load_csv("A01_pendulum_exact_0-10s.csv")
    if horizon == 2000.0:
        return _load_csv("A01_pendulum_exact_0-2000s.csv")
    raise InputError(f"horizon must be 10.0 or 2000.0 (the tabulated files), got {horizon!r}")


def load_a02_n2_exact() -> FloatArray:
    """Exact A02 (N = 2) motion of B0, t = 0..20 s every 0.01 s: columns t, x, y, vx, vy."""
    return _load_csv("A02_NfourBar_N2_exact_0-20s.csv")


def load_a03_reference() -> tuple[tuple[str, ...], FloatArray]:
    """Test Set reference y(0.03) of Andrews' mechanism: 27 names and values."""
    ref = resources.files("nonmin").joinpath(
        "data", "validation", "A03_andrews_testset_reference_t0.03.csv"
    )
    names: list[str] = []
    values: list[float] = []
    with resources.as_file(ref) as p:
        for line in p.read_text(encoding="utf-8").splitlines():
            if not line or line.startswith("#") or line.startswith("index"):
                continue
            _, name, value = line.split(",")
            names.append(name)
            values.append(float(value))
    return tuple(names), np.asarray(values)


def a02_parallelogram_reference(
    n: int, t: FloatArray, *, g: float = 9.81, rtol: float = 1e-13, atol: float = 1e-13
) -> tuple[FloatArray, FloatArray]:
    """Crank angle of the A02 N four-bar in its parallelogram mode (exact 1-DOF reduction).

    ``I θ̈ = −g c cos θ`` with ``I = (N+1)/3 + N``, ``c = (N+1)/2 + N``, ``θ(0) = π/2``,
    ``θ̇(0) = −1 rad/s`` (unit links and masses), integrated with DOP853.

    Parameters
    ----------
    n : int
        Number of four-bar loops (N ≥ 1).
    t : array_like, shape (T,)
        Increasing sample times starting at 0.

    Returns
    -------
    theta, theta_dot : ndarray, shape (T,)
    """
    if n < 1:
        raise InputError(f"n must be ≥ 1, got {n}")
    t = np.asarray(t, dtype=np.float64)
    if t.ndim != 1 or t.size < 1:
        raise ShapeError(f"t must have shape (T,) with T ≥ 1, got {t.shape}")
    inertia = (n + 1) / 3.0 + n
    c = (n + 1) / 2.0 + n

    def rhs(_t: float, y: FloatArray) -> list[float]:
        return [y[1], -g * c * math.cos(y[0]) / inertia]

    sol = solve_ivp(
        rhs,
        (0.0, float(t[-1])),
        [math.pi / 2.0, -1.0],
        method="DOP853",
        rtol=rtol,
        atol=atol,
        t_eval=t,
    )
    if not sol.success:  # pragma: no cover - smooth ODE
        raise RuntimeError(f"A02 reference integration failed: {sol.message}")
    return sol.y[0], sol.y[1]


def significant_digits(
    y: FloatArray, ref: FloatArray, *, rtol: float, atol: float
) -> tuple[float, FloatArray]:
    """The Test Set for IVP Solvers' significant-digit score.

    ``scd = min_i −log10(|y_i − ref_i| / (atol/rtol + |ref_i|))`` (Mazzia & Magherini).

    Parameters
    ----------
    y, ref : array_like, shape (k,)
        Computed and reference values.
    rtol, atol : float
        The tolerances the solver ran with (they set the absolute floor ``atol/rtol``).

    Returns
    -------
    score : float
        The minimum over components (``inf`` if every component is exact).
    per_component : ndarray, shape (k,)
    """
    y = np.asarray(y, dtype=np.float64)
    ref = np.asarray(ref, dtype=np.float64)
    if y.shape != ref.shape:
        raise ShapeError(f"y and ref must have the same shape, got {y.shape} and {ref.shape}")
    err = np.abs(y - ref) / (atol / rtol + np.abs(ref))
    with np.errstate(divide="ignore"):
        per = -np.log10(err)
    return float(np.min(per)), per


# ------------------------------------------------------------------------------- A04 period
#: A04 joints in chain order (ground → rod1 → … → rod5 → ground): point and axis at the
#: tabulated configuration (shared/benchmarks/README.md).
_A04_JOINTS = (
    ((0.0, 0.0, 0.0), (0.0, 1.0, 0.0)),
    ((1.0, 0.0, 0.0), (0.0, 0.0, 1.0)),
    ((1.0, -1.0, 0.0), (1.0, 0.0, 0.0)),
    ((1.0, -1.0, 1.0), (0.0, 1.0, 0.0)),
    ((0.0, -1.0, 1.0), (0.0, 0.0, 1.0)),
    ((0.0, 0.0, 1.0), (1.0, 0.0, 0.0)),
)
#: Centres of mass of rod1 … rod5 and the axis (0 x, 1 y, 2 z) each rod lies along.
_A04_COMS = ((0.5, 0.0, 0.0), (1.0, -0.5, 0.0), (1.0, -1.0, 0.5), (0.5, -1.0, 1.0), (0.0, -0.5, 1.0))
_A04_ALONG = (0, 1, 2, 0, 1)


def _hat(w: FloatArray) -> FloatArray:
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


def _a04_poses(theta: FloatArray) -> list[FloatArray]:
    """Cumulative products ``exp(ξ₁θ₁)…exp(ξ_jθ_j)`` (4×4), j = 1 … 6 (product of exponentials
    of the revolute twists about the tabulated axes; the sixth closes the loop: identity)."""
    out = []
    T = np.eye(4)
    for (p, w), th in zip(_A04_JOINTS, theta, strict=True):
        K = _hat(np.asarray(w))
        R = np.eye(3) + math.sin(th) * K + (1.0 - math.cos(th)) * (K @ K)
        E = np.eye(4)
        E[:3, :3] = R
        E[:3, 3] = (np.eye(3) - R) @ np.asarray(p)
        T = T @ E
        out.append(T)
    return out


def _a04_closure(theta: FloatArray) -> FloatArray:
    """Loop closure residual (6,): rotation vector to first order and translation of the product."""
    T = _a04_poses(theta)[-1]
    R = T[:3, :3]
    return np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1], *(2.0 * T[:3, 3])]) / 2.0


def _a04_jacobian(theta: FloatArray) -> FloatArray:
    """Spatial Jacobian (6, 6): column j is the twist (ω, v) of joint j in the world frame."""
    P = _a04_poses(theta)
    cols = []
    pre = np.eye(4)
    for j, (p, w) in enumerate(_A04_JOINTS):
        wj = pre[:3, :3] @ np.asarray(w)
        pj = pre[:3, :3] @ np.asarray(p) + pre[:3, 3]
        cols.append(np.concatenate([wj, np.cross(pj, wj)]))
        pre = P[j]
    return np.array(cols).T


def _a04_tangent(theta: FloatArray) -> FloatArray:
    """dθ/dθ₁ along the one-parameter motion (the Jacobian has rank 5: one row is redundant)."""
    J = _a04_jacobian(theta)
    return np.concatenate([[1.0], np.linalg.lstsq(J[:, 1:], -J[:, 0], rcond=None)[0]])


def _a04_solve(s: float, guess: FloatArray) -> FloatArray:
    """The joint angles with θ₁ = s near ``guess`` (Gauss–Newton on θ₂ … θ₆)."""
    th = guess + (s - guess[0]) * _a04_tangent(guess)
    th[0] = s
    for _ in range(30):
        d = np.linalg.lstsq(_a04_jacobian(th)[:, 1:], -_a04_closure(th), rcond=None)[0]
        th[1:] += d
        if float(np.max(np.abs(d))) < 1e-15:
            break
    return th


def _a04_energy(theta: FloatArray, g: float) -> tuple[float, float]:
    """(m(θ₁), V): the kinetic coefficient ``T = ½ m θ̇₁²`` and the potential energy."""
    P = _a04_poses(theta)
    J = _a04_jacobian(theta)
    tan = _a04_tangent(theta)
    mass, width, length = 1.0, 0.1, 1.0
    axial, transverse = mass * width**2 / 6.0, mass * (length**2 + width**2) / 12.0
    twist = np.zeros(6)
    m_eff = 0.0
    V = 0.0
    for i in range(5):
        twist = twist + J[:, i] * tan[i]
        w, v = twist[:3], twist[3:]
        R, c = P[i][:3, :3], P[i][:3, :3] @ np.asarray(_A04_COMS[i]) + P[i][:3, 3]
        cd = v + np.cross(w, c)
        inertia = np.full(3, transverse)
        inertia[_A04_ALONG[i]] = axial
        m_eff += mass * float(cd @ cd) + float(w @ (R @ np.diag(inertia) @ R.T) @ w)
        V += mass * g * float(c[1])
    return m_eff, V


def a04_bricard_period(*, nodes: int = 40, g: float = 9.81) -> float:
    """Period (s) of A04 Bricard's mechanism released from rest, by quadrature.

    Independent of nonmin's models: the loop is written in relative joint angles θ₁ … θ₆ as a
    product of exponentials of the six revolute twists (closure ``exp(ξ₁θ₁)…exp(ξ₆θ₆) = I``,
    6 equations of rank 5). The motion is one-parameter, θ₁ = s increasing from 0 to the other
    turning point s₁ (found as the root of ``V(s) = V(0)``: s₁ = π, where θ₁ = θ₃ = θ₅ and
    θ₂ = θ₄ = θ₆ all along). With ``T = ½ m(s) ṡ²`` and energy conservation,

        period = 2 ∫₀^{s₁} √(m(s) / (2 (V(0) − V(s)))) ds,

    integrated by Gauss–Legendre after ``s = s₁ (1 − cos u)/2``, which removes the
    inverse-square-root end singularities (the integrand is smooth in u). Converged to ~2e-12 s
    (the rounding of V(0) − V(s) near the ends): 4.99171151369 s with 24 … 64 nodes.

    Parameters
    ----------
    nodes : int
        Gauss–Legendre nodes.
    g : float
        Gravity (m/s², along −y).
    """
    from scipy.optimize import brentq

    th = np.zeros(6)
    _, V0 = _a04_energy(th, g)
    # the other turning point: the first s where V climbs back to V(0)
    s, prev = 0.0, th
    while True:
        s_new = s + 0.05
        th_new = _a04_solve(s_new, prev)
        if _a04_energy(th_new, g)[1] - V0 >= 0.0:
            break
        s, prev = s_new, th_new
        if s > 4.0 * math.pi:  # pragma: no cover - the benchmark's motion turns at π
            raise RuntimeError("A04: no turning point found")
    base = prev
    s1 = float(brentq(lambda x: _a04_energy(_a04_solve(x, base), g)[1] - V0, s, s_new, xtol=1e-15, rtol=1e-15))
    x, w = np.polynomial.legendre.leggauss(int(nodes))
    u = 0.5 * math.pi * (x + 1.0)
    total = 0.0
    th = np.zeros(6)
    for ui, wi in zip(u, w, strict=True):
        si = 0.5 * s1 * (1.0 - math.cos(ui))
        while th[0] < si:  # continuation in steps ≤ 0.05 rad
            th = _a04_solve(min(si, th[0] + 0.05), th)
        m_eff, V = _a04_energy(th, g)
        total += 0.5 * math.pi * wi * math.sqrt(m_eff / (2.0 * (V0 - V))) * 0.5 * s1 * math.sin(ui)
    return float(2.0 * total)
