"""Impact map at constraint activation (not in the paper; see ERRATA "Beyond the paper").

Plastic impact (restitution 0): ``qd⁺ = M̄⁻¹ P M qd⁻``, impulse ``M (qd⁺ − qd⁻) = −S M qd⁻``.
It equals the classical mass-orthogonal projection ``(I − M⁻¹Aᵀ(AM⁻¹Aᵀ)⁺A) qd⁻``, does not
depend on μ, works for rank-deficient A and M singular off N(A), and loses exactly Carnot's
energy ``½ (qd⁻ − qd⁺)ᵀ M (qd⁻ − qd⁺)``. With Newton's restitution coefficient e:
``qd⁺ = qd⁻ + (1 + e)(qd⁺_plastic − qd⁻)``, so ``A qd⁺ = −e A qd⁻``.
The same map is the post-step velocity correction onto ``A qd = 0`` in the mass metric.

Simultaneous impacts (several unilateral contacts closing at one instant, possibly redundant,
each with its own restitution ``e_i``): :func:`simultaneous_impact`, Newton's law per contact in
inequality form, ``qd⁺ = argmin ½‖v − qd⁻‖²_M`` over ``{A_b v = 0, a_i v ≥ e_i max(−a_i qd⁻, 0)}``
(docs/theory.md, "Simultaneous impacts"). The minimizer is unique, so the result depends neither
on the order of the contacts nor on a split of the impulse between redundant rows; it is found
without multipliers by :func:`polyhedral_projection` (the optimum is the mass-metric projection
onto the affine hull of its own active face, and the projections onto affine hulls are the
kernel's ``forward`` solves with zero force). With one contact, or one restitution for a set
that all approaches, it is :func:`impact_map` of the set.
"""

from __future__ import annotations

from itertools import combinations
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .. import _validation as V
from ..errors import InputError, SimulationError
from . import _fast
from .dynamics import _optimal_mu, forward_dynamics
from .linalg import FloatArray, cho_solve, cholesky, matvec, range_basis, resolve_rtol

__all__ = ["PolyhedralProjection", "SimultaneousImpact", "impact_map", "polyhedral_projection",
           "simultaneous_impact"]

#: Largest number of inequality rows :func:`polyhedral_projection` takes (its search visits
#: subsets of them, pruned: supersets of a feasible or empty face are skipped).
MAX_INEQUALITY_ROWS = 16

#: Relative tolerance of feasibility and of "at equality" (relative to the size of the terms
#: of the row, ``Σ_j |a_ij x_j| + |r_i|``).
FEASIBILITY_RTOL = 1e-9


def impact_map(
    M: ArrayLike,
    A: ArrayLike,
    qd_minus: ArrayLike,
    *,
    restitution: float = 0.0,
    mu: ArrayLike | None = None,
    rtol: float | None = None,
) -> FloatArray:
    """Post-impact velocity when the constraints ``A qd = 0`` become active.

    Not in the paper: ERRATA, "Impact map at constraint activation" (plastic map
    ``qd⁺ = M̄⁻¹PM qd⁻``, extended with Newton's restitution).

    Parameters
    ----------
    M : array_like, shape (..., n, n)
        Inertia matrix (positive definite on N(A)).
    A : array_like, shape (..., m, n)
        Constraint matrix of the constraints active *after* the impact.
    qd_minus : array_like, shape (..., n)
        Pre-impact velocity.
    restitution : float, default 0.0
        Newton coefficient of restitution ``e ∈ [0, 1]``; 0 is plastic.
    mu : float or array_like, optional
        Virtual mass (the result does not depend on it).
    rtol : float, optional
        Rank tolerance.

    Returns
    -------
    qd_plus : ndarray, shape (..., n)
        ``qd⁻ + (1 + e)(M̄⁻¹PM qd⁻ − qd⁻)``.

    Examples
    --------
    >>> import numpy as np
    >>> from nonmin.core import impact_map
    >>> impact_map(np.eye(2), [[0.0, 1.0]], [1.0, -2.0]).round(12).tolist()
    [1.0, 0.0]
    """
    Mm = V.symmetric(M, "M")
    n = Mm.shape[-1]
    Am = V.matrix(A, "A", None, n)
    v = V.vector(qd_minus, "qd_minus", n)
    e = V.nonnegative_float(restitution, "restitution", 1.0)
    mu_v = None if mu is None else V.positive_scalar_or_batch(mu, "mu")
    if n and _fast.engine_on():  # engine/src/core_dynamics.cpp: impact_map
        out = _fast.engine_solver_kernel(0, Mm, Am, v, mu_v, e, resolve_rtol(rtol))
        if out is not None:
            return out
    basis = range_basis(Am, rtol)
    Q = basis.range_projector()
    P = np.eye(n) - Q
    PM = P @ Mm
    PMP = PM @ P
    mu_a = _optimal_mu(PMP, Mm, basis.rank) if mu_v is None else mu_v
    L = cholesky(PMP + np.asarray(mu_a)[..., None, None] * Q)
    plastic = cho_solve(L, matvec(PM, v))
    return v + (1.0 + e) * (plastic - v)


class PolyhedralProjection(NamedTuple):
    """Result of :func:`polyhedral_projection`.

    Attributes
    ----------
    x : ndarray, shape (n,)
        The minimizer.
    at_bound : ndarray of bool, shape (m_in,)
        Inequality rows at equality at ``x`` (within :data:`FEASIBILITY_RTOL`).
    """

    x: FloatArray
    at_bound: NDArray[np.bool_]


def _row_scale(A: FloatArray, x: FloatArray, r: FloatArray) -> FloatArray:
    """Size of the terms of each row of ``A x + r`` (its round-off is ~eps × that)."""
    return np.abs(A).sum(axis=1) * float(np.max(np.abs(x), initial=0.0)) + np.abs(r) + np.finfo(float).tiny


def polyhedral_projection(
    M: ArrayLike,
    x0: ArrayLike,
    A_eq: ArrayLike,
    r_eq: ArrayLike,
    A_in: ArrayLike,
    r_in: ArrayLike,
    *,
    rtol: float | None = None,
) -> PolyhedralProjection:
    """Mass-metric projection of ``x0`` onto a polyhedron, without multipliers.

    ``x = argmin ½ (x − x0)ᵀ M (x − x0)`` subject to ``A_eq x + r_eq = 0`` and
    ``A_in x + r_in ≥ 0`` (not in the paper; docs/theory.md, "Simultaneous impacts").

    The minimizer ``x*`` is unique (M positive definite on N(A_eq)). It is the projection of
    ``x0`` onto the affine set ``{A_eq x + r_eq = 0, A_W x + r_W = 0}`` of its own active rows
    W (the optimality conditions of both problems coincide there), and every such projection
    that is feasible lies in the polyhedron, so ``x*`` is the feasible face projection nearest
    to ``x0``. Each face projection is one solve ``Δ = forward_dynamics(M, 0, A_F, A_F x0 + r_F)``
    (the minimum-M-norm Δ with ``A_F (x0 + Δ) + r_F = 0``, for redundant and rank-deficient
    ``A_F`` alike). Faces are visited by size; supersets of a feasible face (never nearer) and
    of an empty one (inconsistent rows) are skipped.

    Parameters
    ----------
    M : array_like, shape (n, n)
    x0 : array_like, shape (n,)
    A_eq : array_like, shape (m_eq, n)
    r_eq : array_like, shape (m_eq,)
    A_in : array_like, shape (m_in, n)
        ``m_in ≤`` :data:`MAX_INEQUALITY_ROWS`.
    r_in : array_like, shape (m_in,)
    rtol : float, optional
        Rank tolerance of the solves.

    Returns
    -------
    PolyhedralProjection

    Raises
    ------
    InputError
        More than :data:`MAX_INEQUALITY_ROWS` inequality rows.
    SimulationError
        The polyhedron is empty.

    Examples
    --------
    >>> import numpy as np
    >>> from nonmin.core import polyhedral_projection
    >>> r = polyhedral_projection(np.eye(2), [0.0, -1.0], np.zeros((0, 2)), [], [[0.0, 1.0]], [0.0])
    >>> r.x.round(12).tolist(), r.at_bound.tolist()
    ([0.0, 0.0], [True])
    """
    Mm = V.symmetric(M, "M")
    n = Mm.shape[-1]
    x = V.vector(x0, "x0", n)
    Ae = V.matrix(A_eq, "A_eq", None, n)
    re = V.vector(r_eq, "r_eq", Ae.shape[0])
    Ai = V.matrix(A_in, "A_in", None, n)
    ri = V.vector(r_in, "r_in", Ai.shape[0])
    m_in = Ai.shape[0]
    if m_in > MAX_INEQUALITY_ROWS:
        raise InputError(f"A_in: at most {MAX_INEQUALITY_ROWS} inequality rows, got {m_in}")
    if _fast.engine_on():  # engine/src/sim_events.cpp: polyhedral_projection (the same search)
        c = np.ascontiguousarray
        found, xe, ab = _fast._engine.polyhedral_projection(
            c(Mm), c(x), c(Ae.reshape(-1, n)), c(re), c(Ai.reshape(-1, n)), c(ri), resolve_rtol(rtol))
        if found:
            return PolyhedralProjection(np.asarray(xe), np.asarray(ab) != 0.0)
    zero = np.zeros(n)
    tol = FEASIBILITY_RTOL
    feasible: list[int] = []
    empty: list[int] = []
    best: tuple[float, FloatArray] | None = None
    eq_res0: FloatArray | None = None
    for size in range(m_in + 1):
        for face in combinations(range(m_in), size):
            mask = sum(1 << i for i in face)
            if any(f & mask == f for f in feasible) or any(f & mask == f for f in empty):
                continue
            A = np.vstack((Ae, Ai[list(face)]))
            r = np.concatenate((re, ri[list(face)]))
            dx = forward_dynamics(Mm, zero, A, A @ x + r, rtol=rtol) if A.shape[0] else zero
            xf = x + dx
            res = np.abs(A @ xf + r)
            scale = _row_scale(A, np.maximum(np.abs(xf), np.abs(x)), r)
            m_eq = Ae.shape[0]
            if eq_res0 is None:  # the equality rows' own (least-squares) residual
                eq_res0 = res[:m_eq]
            if np.any(res[m_eq:] > tol * scale[m_eq:]) or np.any(res[:m_eq] > eq_res0 + tol * scale[:m_eq]):
                empty.append(mask)
                continue
            g = Ai @ xf + ri
            if np.all(g >= -tol * _row_scale(Ai, np.maximum(np.abs(xf), np.abs(x)), ri)):
                feasible.append(mask)
                d = float(dx @ Mm @ dx)
                if best is None or d < best[0]:
                    best = (d, xf)
    if best is None:
        raise SimulationError("polyhedral_projection: the constraints admit no point (empty polyhedron)")
    xs = best[1]
    at = np.abs(Ai @ xs + ri) <= tol * _row_scale(Ai, np.maximum(np.abs(xs), np.abs(x)), ri)
    return PolyhedralProjection(xs, at)


class SimultaneousImpact(NamedTuple):
    """Result of :func:`simultaneous_impact`.

    Attributes
    ----------
    qd_plus : ndarray, shape (n,)
    normal_velocity : ndarray, shape (m_c,)
        ``A_c qd⁺`` (≥ the Newton targets ``e_i max(−a_i qd⁻, 0)``).
    closed : ndarray of bool, shape (m_c,)
        Contacts whose normal velocity is zero after the impact (plastic, or at rest and kept
        closed); the others separate.
    """

    qd_plus: FloatArray
    normal_velocity: FloatArray
    closed: NDArray[np.bool_]


def simultaneous_impact(
    M: ArrayLike,
    A_bilateral: ArrayLike,
    A_contact: ArrayLike,
    qd_minus: ArrayLike,
    *,
    restitution: ArrayLike = 0.0,
    rtol: float | None = None,
) -> SimultaneousImpact:
    """Post-impact velocity when a set of unilateral contacts closes at one instant.

    Not in the paper (docs/theory.md, "Simultaneous impacts"): Newton's restitution per
    contact in inequality form,
    ``qd⁺ = argmin ½ (v − qd⁻)ᵀ M (v − qd⁻)`` subject to ``A_b v = 0`` (bilateral constraints
    active after the impact) and ``a_i v ≥ e_i max(−a_i qd⁻, 0)`` for every contact row
    ``a_i`` of ``A_c``. Its optimality conditions are the Newton impact LCP
    ``0 ≤ Λ_i ⊥ a_i qd⁺ + e_i a_i qd⁻ ≥ 0`` of the impulse ``M(qd⁺ − qd⁻) = A_bᵀΛ_b + A_cᵀΛ_c``,
    but the velocity is unique even when the rows are redundant and Λ is not. Contacts that the
    impact pushes apart (``a_i qd⁺`` above its target) separate; with one restitution e for
    contacts that all approach, ``qd⁺`` is :func:`impact_map` of the set.

    Parameters
    ----------
    M : array_like, shape (n, n)
    A_bilateral : array_like, shape (m_b, n)
        Rows held as equalities (``m_b = 0`` allowed).
    A_contact : array_like, shape (m_c, n)
        Contact rows (gap derivative; the gap is ≥ 0), ``m_c ≤`` :data:`MAX_INEQUALITY_ROWS`.
    qd_minus : array_like, shape (n,)
    restitution : float or array_like, shape (m_c,)
        Newton coefficients ``e_i ∈ [0, 1]``.
    rtol : float, optional
        Rank tolerance.

    Returns
    -------
    SimultaneousImpact

    Examples
    --------
    A bar (mass 1, inertia 1/3, coordinates x, y, θ) falling flat at 1 m/s onto three
    points at −1, 0 and 1, with e = 0.5: it bounces at 0.5 m/s without spin.

    >>> import numpy as np
    >>> from nonmin.core import simultaneous_impact
    >>> M = np.diag([1.0, 1.0, 1.0 / 3.0])
    >>> A = np.array([[0.0, 1.0, -1.0], [0.0, 1.0, 0.0], [0.0, 1.0, 1.0]])
    >>> r = simultaneous_impact(M, np.zeros((0, 3)), A, [0.0, -1.0, 0.0], restitution=0.5)
    >>> r.qd_plus.round(12).tolist(), r.closed.tolist()
    ([0.0, 0.5, 0.0], [False, False, False])
    """
    Mm = V.symmetric(M, "M")
    n = Mm.shape[-1]
    Ab = V.matrix(A_bilateral, "A_bilateral", None, n)
    Ac = V.matrix(A_contact, "A_contact", None, n)
    v = V.vector(qd_minus, "qd_minus", n)
    m_c = Ac.shape[0]
    e = np.broadcast_to(np.asarray(restitution, dtype=float), (m_c,)).copy() if m_c else np.zeros(0)
    if not np.all((e >= 0.0) & (e <= 1.0)):
        raise InputError(f"restitution must lie in [0, 1], got {restitution!r}")
    u = Ac @ v
    target = e * np.maximum(-u, 0.0)
    res = polyhedral_projection(Mm, v, Ab, np.zeros(Ab.shape[0]), Ac, -target, rtol=rtol)
    un = Ac @ res.x
    closed = np.abs(un) <= FEASIBILITY_RTOL * _row_scale(Ac, np.maximum(np.abs(res.x), np.abs(v)), np.zeros(m_c))
    return SimultaneousImpact(res.x, un, closed)
