"""Coulomb friction at slipping point contacts: the NumPy specification of the engine's solve.

A slipping contact j carries the tangential force ``F_j = −μ_j s_j N_j`` along its tangential
row ``a_tj`` (the row whose velocity ``a_tj q̇`` is the slip velocity; ``s_j = ±1`` the slip
direction), so the applied force is ``f + Σ_j a_tjᵀ F_j``. Its normal force ``N_j`` is not a
multiplier: it is the component of the projection's constraint force ``f_c`` (eq. (fc_R),
``f_c = −S (f + h − M Ω q̇)``) along the contact's normal row, ``N = λ_n`` in the
multiplier-free split ``λ = ((DA)⁺D)ᵀ f_c`` (the value the release guards read). ``f_c`` is
affine in the applied force, so with ``f_c^(j)`` the constraint force of a unit force along
``a_tj`` alone (``−S a_tjᵀ``):

    N_i = N0_i + Σ_j λ_n,i(f_c^(j)) F_j   ⇔   (I + K D) N = N0,
    K_ij = λ_n,i(f_c^(j)),   D = diag(μ_j s_j).

One contact: ``N = N0 / (1 + μ s K)``. The relation has a unique solution for every ``N0``
exactly when ``W = I + K D`` is a P-matrix (all principal minors positive); otherwise sliding
is inconsistent — Painlevé's paradox: the normal force that sliding needs would have to be
negative, or is undetermined. This module returns the solution and the smallest principal
minor; :func:`nonmin.simulate` reports the inconsistency (``docs/theory.md`` "Coulomb friction").
"""

from __future__ import annotations

from itertools import combinations
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .dynamics import solve_dynamics
from .linalg import range_basis

FloatArray = NDArray[np.float64]

__all__ = ["SlipDynamics", "slip_dynamics"]


class SlipDynamics(NamedTuple):
    """The dynamics with slipping contacts.

    Attributes
    ----------
    qdd : ndarray, shape (n,)
        Acceleration with the friction forces applied.
    f_c : ndarray, shape (n,)
        Constraint force with the friction forces applied.
    N : ndarray, shape (k,)
        Normal force of each slipping contact (NaN when inconsistent).
    F : ndarray, shape (k,)
        Tangential (friction) force ``−μ s N`` of each.
    W : ndarray, shape (k, k)
        ``I + K D`` of the normal-force relation ``W N = N0``.
    N0 : ndarray, shape (k,)
        Normal forces without friction.
    min_minor : float
        Smallest principal minor of W (one contact: ``1 + μ s K``).
    consistent : bool
        ``min_minor > 0`` (W is a P-matrix): else Painlevé's inconsistency.
    """

    qdd: FloatArray
    f_c: FloatArray
    N: FloatArray
    F: FloatArray
    W: FloatArray
    N0: FloatArray
    min_minor: float
    consistent: bool


def _lam(A: FloatArray, f_c: FloatArray, rtol: float | None) -> FloatArray:
    """The multiplier-free split ``λ = ((DA)⁺D)ᵀ f_c`` (the release guards' normal forces)."""
    if A.shape[0] == 0:
        return np.zeros(0)
    return np.asarray(range_basis(A, rtol).pinv().T @ f_c)


def slip_dynamics(
    M: ArrayLike,
    g: ArrayLike,
    A: ArrayLike,
    gamma: ArrayLike,
    normal_rows: ArrayLike,
    A_t: ArrayLike,
    mu: ArrayLike,
    s: ArrayLike,
    *,
    rtol: float | None = None,
) -> SlipDynamics:
    """Accelerations, constraint and normal forces with k slipping contacts, solved exactly.

    Parameters
    ----------
    M : array_like, shape (n, n)
        Mass matrix.
    g : array_like, shape (n,)
        Total applied force without friction, ``f + h`` (eq. (ddq_sim)).
    A : array_like, shape (m, n)
        Active constraint rows (the slipping contacts' normal rows among them, their
        tangential rows not).
    gamma : array_like, shape (m,)
        ``Ȧ q̇`` (the bias of ``A q̈ + γ = 0``).
    normal_rows : array_like of int, shape (k,)
        Each slipping contact's normal row in A.
    A_t : array_like, shape (k, n)
        Their tangential rows (``A_t q̇``: the slip velocities).
    mu, s : array_like, shape (k,)
        Friction coefficients and slip directions (±1).
    rtol : float, optional
        Rank tolerance of the solve and of the split (the core default when None).

    Returns
    -------
    SlipDynamics
    """
    Mm = np.asarray(M, dtype=float)
    gv = np.asarray(g, dtype=float)
    Am = np.asarray(A, dtype=float).reshape(-1, Mm.shape[0])
    gam = np.asarray(gamma, dtype=float).reshape(-1)
    rows = np.asarray(normal_rows, dtype=np.intp).reshape(-1)
    At = np.asarray(A_t, dtype=float).reshape(-1, Mm.shape[0])
    muv = np.asarray(mu, dtype=float).reshape(-1)
    sv = np.asarray(s, dtype=float).reshape(-1)
    k = rows.size
    sol0 = solve_dynamics(Mm, gv, Am, gam, rtol=rtol)
    if k == 0:
        e = np.zeros(0)
        return SlipDynamics(sol0.qdd, sol0.f_c, e, e, np.zeros((0, 0)), e, np.inf, True)
    N0 = _lam(Am, sol0.f_c, rtol)[rows]
    zero = np.zeros(Am.shape[0])
    resp_qdd = np.empty((k, Mm.shape[0]))
    resp_fc = np.empty((k, Mm.shape[0]))
    K = np.empty((k, k))
    for j in range(k):
        sj = solve_dynamics(Mm, At[j], Am, zero, rtol=rtol)  # a unit force along a_tj alone
        resp_qdd[j], resp_fc[j] = sj.qdd, sj.f_c
        K[:, j] = _lam(Am, sj.f_c, rtol)[rows]
    W = np.eye(k) + K * (muv * sv)[None, :]
    minors = [
        float(np.linalg.det(W[np.ix_(sub, sub)])) for size in range(1, k + 1) for sub in combinations(range(k), size)
    ]
    min_minor = min(minors)
    if not min_minor > 0.0:
        nan = np.full(k, np.nan)
        return SlipDynamics(sol0.qdd, sol0.f_c, nan, nan, W, N0, min_minor, False)
    N = np.linalg.solve(W, N0)
    F = -muv * sv * N
    return SlipDynamics(sol0.qdd + F @ resp_qdd, sol0.f_c + F @ resp_fc, N, F, W, N0, min_minor, True)
