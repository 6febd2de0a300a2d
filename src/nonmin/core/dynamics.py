"""Constraint inertia M̄, C̄, virtual mass, forward dynamics and constraint forces.

Equations (paper numbering, corrected per ``ERRATA.md`` where marked):

* (Mbar)  ``M̄ = PMP + μQ`` — SPD whenever M is positive definite on N(A).
* (Cbar2) ``C̄ = PCP + PM(ΛP + PΛᵀ) − μΛP`` — makes ``dM̄/dt − 2C̄`` skew (Christoffel C).
* (optimum_mu) ``λmin≠0(PMP) ≤ μ ≤ λmax(PMP)``; we use ``μ = tr(PMP)/(n − r)``, which lies in
  that interval and needs no eigen-decomposition.
* (ddq_sim), corrected sign (ERRATA 1):
  ``qdd = M̄⁻¹ [ P (f + f_g − C qd − M Ω qd) + μ Ω qd ]``.
  Implemented in the drift-tolerant form that does not assume ``qd ∈ N`` and needs only
  ``Ȧ qd`` (= ``adot_qd``):

  ``qdd = M̄⁻¹ [ P (f + h) + (μI − PM) w ]``,  ``w = −A⁺ (Ȧ qd)``,

  which satisfies ``A qdd + Ȧ qd = 0`` and ``P (M qdd − f − h) = 0`` exactly; for ``qd ∈ N``
  ``w = Λ qd = Ω qd``, so it *is* the corrected (ddq_sim). Passing the Baumgarte-augmented bias
  (:func:`baumgarte_bias`) as ``adot_qd`` gives the stabilized form.
* (fc_R)  ``f_c = −S (f + h − M Ω qd)`` ≡ ``M qdd − f − h`` (= ``Aᵀλ`` of the KKT system).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .. import _engine  # type: ignore[attr-defined]  # the compiled extension (no stubs)
from .. import _validation as V
from . import _fast
from .linalg import (
    FloatArray,
    RangeBasis,
    cho_solve,
    cholesky,
    matvec,
    pseudo_inverse,
    range_basis,
    resolve_rtol,
)

_ENGINE_FAST = _fast.ENGINE_FAST

__all__ = [
    "DynamicsSolution",
    "baumgarte_bias",
    "constraint_force",
    "constraint_inertia",
    "coriolis_bar",
    "forward_dynamics",
    "optimal_virtual_mass",
    "position_correction",
    "solve_dynamics",
]


# --------------------------------------------------------------------------- helpers


def _mbar(M: FloatArray, P: FloatArray, mu: FloatArray) -> FloatArray:
    n = M.shape[-1]
    if n and _fast.engine_on():  # engine/src/core_dynamics.cpp: constraint_inertia
        st = _fast.strided([(M, (n, n)), (P, (n, n)), (mu, ())])
        if st is not None:
            bshape, N, ((Mb, sM), (Pb, sP), (mub, smu)) = st
            out = np.empty((N, n, n))
            _engine.core_mbar(Mb, Pb, mub, sM, sP, smu, N, n, out, _fast.engine_threads(N))
            return out.reshape((*bshape, n, n))
    Q = np.eye(n) - P
    return P @ M @ P + np.asarray(mu)[..., None, None] * Q


def _optimal_mu(PMP: FloatArray, M: FloatArray, rank: ArrayLike) -> FloatArray:
    n = M.shape[-1]
    if PMP.ndim == 2 and n:  # one state: the same quotients without the batch's masks and errstate
        dof1 = n - int(np.asarray(rank))
        mu1 = np.trace(PMP) / dof1 if dof1 > 0 else np.trace(M) / n
        return np.asarray(mu1 if mu1 > 0 else 1.0)
    dof = n - np.asarray(rank)
    tr_pmp = np.trace(PMP, axis1=-2, axis2=-1)
    tr_m = np.trace(M, axis1=-2, axis2=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        mu = np.where(dof > 0, tr_pmp / np.maximum(dof, 1), tr_m / n)
    # Degenerate inputs (M = 0 on a fully constrained system): any μ > 0 works; use 1.
    return np.where(mu > 0, mu, 1.0)


def _check_dynamics_inputs(
    M: ArrayLike, h: ArrayLike, A: ArrayLike, adot_qd: ArrayLike, f: ArrayLike | None
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray | None]:
    Mm = V.symmetric(M, "M")
    n = Mm.shape[-1]
    hv = V.vector(h, "h", n)
    Am = V.matrix(A, "A", None, n)
    ad = V.vector(adot_qd, "adot_qd", Am.shape[-2])
    fv = None if f is None else V.vector(f, "f", n)
    shapes = [("M", Mm.shape[:-2]), ("h", hv.shape[:-1]), ("A", Am.shape[:-2]), ("adot_qd", ad.shape[:-1])]
    if fv is not None:
        shapes.append(("f", fv.shape[:-1]))
    V.batch_shape(shapes)
    return Mm, hv, Am, ad, fv


class DynamicsSolution(NamedTuple):
    """Everything one evaluation of the projection dynamics produces.

    Attributes
    ----------
    qdd : ndarray, shape (..., n)
        Generalized acceleration.
    f_c : ndarray, shape (..., n)
        Generalized constraint force (``Aᵀλ``, computed without multipliers).
    P : ndarray, shape (..., n, n)
        Null-space projector used.
    rank : ndarray of int, shape (...)
        Numerical rank of A used.
    mu : ndarray, shape (...)
        Virtual mass used.
    L : ndarray, shape (..., n, n)
        Cholesky factor of M̄ (reusable, e.g. for :func:`cond_mbar`).
    """

    qdd: FloatArray
    f_c: FloatArray
    P: FloatArray
    rank: NDArray[np.intp]
    mu: FloatArray
    L: FloatArray


def _solve(
    M: FloatArray,
    g: FloatArray,
    basis: RangeBasis,
    adot_qd: FloatArray,
    mu: FloatArray | None,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Unchecked kernel: returns qdd, P, mu, L for total applied force g = f + h."""
    n = M.shape[-1]
    Q = basis.range_projector()
    P = np.eye(n) - Q
    PM = P @ M
    PMP = PM @ P
    mu_a = _optimal_mu(PMP, M, basis.rank) if mu is None else np.asarray(mu, dtype=float)
    Mbar = PMP + mu_a[..., None, None] * Q
    L = cholesky(Mbar)
    w = -basis.solve(adot_qd)
    rhs = matvec(P, g) + mu_a[..., None] * w - matvec(PM, w)
    qdd = cho_solve(L, rhs)
    return qdd, P, mu_a, L


# --------------------------------------------------------------------------- public kernels


def constraint_inertia(M: ArrayLike, P: ArrayLike, mu: ArrayLike) -> FloatArray:
    """Constraint inertia matrix ``M̄ = PMP + μQ`` (paper, eq. (Mbar)).

    Parameters
    ----------
    M : array_like, shape (..., n, n)
        Symmetric inertia matrix (positive definite on N(A); may be singular elsewhere).
    P : array_like, shape (..., n, n)
        Null-space projector (:func:`~nonmin.core.nullspace_projector`).
    mu : float or array_like, shape (...)
        Virtual mass μ > 0.

    Returns
    -------
    Mbar : ndarray, shape (..., n, n)
        Symmetric; eigenvalues ``{μ (r times)} ∪ nonzero eig(PMP)`` (eq. (lamb(M_bar))).
    """
    Mm = V.symmetric(M, "M")
    Pm = V.symmetric(P, "P", Mm.shape[-1])
    mu_a = V.positive_scalar_or_batch(mu, "mu")
    return _mbar(Mm, Pm, mu_a)


def optimal_virtual_mass(M: ArrayLike, P: ArrayLike) -> FloatArray:
    """A virtual mass inside the optimal interval of eq. (optimum_mu).

    Returns ``μ = tr(PMP)/(n − r)``, the mean of the nonzero eigenvalues of PMP, which lies in
    ``[λmin≠0(PMP), λmax(PMP)]`` and so minimizes ``cond(M̄) = λmax/λmin≠0(PMP)``. For a fully
    constrained system (``r = n``) it returns ``tr(M)/n``.

    Parameters
    ----------
    M : array_like, shape (..., n, n)
    P : array_like, shape (..., n, n)

    Returns
    -------
    mu : ndarray, shape (...)
    """
    Mm = V.symmetric(M, "M")
    n = Mm.shape[-1]
    Pm = V.symmetric(P, "P", n)
    if n and _fast.engine_on():  # engine/src/core_dynamics.cpp: optimal_virtual_mass
        st = _fast.strided([(Mm, (n, n)), (Pm, (n, n))])
        if st is not None:
            bshape, N, ((Mb, sM), (Pb, sP)) = st
            out = np.empty(N)
            _engine.core_optimal_mu(Mb, Pb, sM, sP, N, n, out, _fast.engine_threads(N))
            return out.reshape(bshape)
    rank = n - np.rint(np.trace(Pm, axis1=-2, axis2=-1))
    return _optimal_mu(Pm @ Mm @ Pm, Mm, rank)


def coriolis_bar(
    M: ArrayLike,
    C: ArrayLike,
    A: ArrayLike,
    Adot: ArrayLike,
    mu: ArrayLike,
    *,
    rtol: float | None = None,
) -> FloatArray:
    """``C̄ = PCP + PM(ΛP + PΛᵀ) − μΛP`` (paper, eq. (Cbar2)).

    With the Christoffel-symbol C, ``dM̄/dt − 2C̄`` is skew-symmetric (Theorem 1) wherever the
    rank of A is locally constant. Only (Cbar2) has this property (ERRATA 3).

    Parameters
    ----------
    M, C : array_like, shape (..., n, n)
        Inertia matrix and Christoffel Coriolis matrix.
    A, Adot : array_like, shape (..., m, n)
        Constraint matrix and its time derivative.
    mu : float or array_like, shape (...)
    rtol : float, optional

    Returns
    -------
    Cbar : ndarray, shape (..., n, n)
    """
    Mm = V.symmetric(M, "M")
    n = Mm.shape[-1]
    Cm = V.square(C, "C", n)
    Am = V.matrix(A, "A", None, n)
    Ad = V.matrix(Adot, "Adot", Am.shape[-2], n)
    mu_a = V.positive_scalar_or_batch(mu, "mu")
    if n and _fast.engine_on():  # engine/src/core_dynamics.cpp: coriolis_bar
        m = Am.shape[-2]
        st = _fast.strided([(Mm, (n, n)), (Cm, (n, n)), (Am, (m, n)), (Ad, (m, n)), (mu_a, ())])
        if st is not None:
            bshape, N, ((Mb, sM), (Cb, sC), (Ab, sA), (Db, sD), (mub, smu)) = st
            out = np.empty((N, n, n))
            _engine.core_cbar(Mb, Cb, Ab, Db, mub, sM, sC, sA, sD, smu, N, n, m,
                              resolve_rtol(rtol), out, _fast.engine_threads(N))  # fmt: skip
            return out.reshape((*bshape, n, n))
    P = range_basis(Am, rtol).nullspace_projector()
    Lam = -(pseudo_inverse(Am, rtol) @ Ad)
    LP = Lam @ P
    return P @ Cm @ P + P @ Mm @ (LP + np.swapaxes(LP, -1, -2)) - mu_a[..., None, None] * LP


def solve_dynamics(
    M: ArrayLike,
    h: ArrayLike,
    A: ArrayLike,
    adot_qd: ArrayLike,
    f: ArrayLike | None = None,
    *,
    mu: ArrayLike | None = None,
    rtol: float | None = None,
) -> DynamicsSolution:
    """Accelerations and constraint forces in one factorization (corrected eqs. (ddq_sim), (fc_R)).

    Parameters
    ----------
    M, h, A, adot_qd, f, mu, rtol
        As in :func:`forward_dynamics`.

    Returns
    -------
    DynamicsSolution
        ``qdd``, ``f_c``, ``P``, ``rank``, ``mu`` and the Cholesky factor ``L`` of M̄.
    """
    fast = _fast.solve(M, h, A, adot_qd, f, mu, rtol, _fast.ALL)  # compiled backend (_fast)
    if fast is not None:
        qdd_c, fc_c, P_c, L_c, rank_c, mu_c = fast
        return DynamicsSolution(qdd=qdd_c, f_c=fc_c, P=P_c, rank=rank_c, mu=mu_c, L=L_c)
    return _solve_dynamics_numpy(M, h, A, adot_qd, f, mu, rtol)


def _solve_dynamics_numpy(
    M: ArrayLike,
    h: ArrayLike,
    A: ArrayLike,
    adot_qd: ArrayLike,
    f: ArrayLike | None,
    mu: ArrayLike | None,
    rtol: float | None,
) -> DynamicsSolution:
    """Reference NumPy evaluation of :func:`solve_dynamics` (validates its inputs)."""
    Mm, hv, Am, ad, fv = _check_dynamics_inputs(M, h, A, adot_qd, f)
    mu_a = None if mu is None else V.positive_scalar_or_batch(mu, "mu")
    g = hv if fv is None else hv + fv
    basis = range_basis(Am, rtol)
    qdd, P, mu_used, L = _solve(Mm, g, basis, ad, mu_a)
    f_c = matvec(Mm, qdd) - g
    return DynamicsSolution(qdd=qdd, f_c=f_c, P=P, rank=basis.rank, mu=mu_used, L=L)


def forward_dynamics(
    M: ArrayLike,
    h: ArrayLike,
    A: ArrayLike,
    adot_qd: ArrayLike,
    f: ArrayLike | None = None,
    *,
    mu: ArrayLike | None = None,
    rtol: float | None = None,
) -> FloatArray:
    """Generalized acceleration of the constrained system (corrected eq. (ddq_sim)).

    ``qdd = M̄⁻¹ [ P (f + h) + (μI − PM) w ]``, ``w = −A⁺ (Ȧ qd)``; for admissible ``qd ∈ N``
    this is ``M̄⁻¹ [ P (f + f_g − C qd − M Ω qd) + μ Ω qd ]`` (ERRATA 1: the printed signs of
    the Ω terms are wrong). The result satisfies ``A qdd + Ȧ qd = 0`` and
    ``M qdd + C qd = f_g + f + f_c`` with ``f_c ∈ N(A)^⊥``; it does not depend on μ. At a
    singular or redundant configuration it is the least-squares (Gauss) solution.

    Parameters
    ----------
    M : array_like, shape (..., n, n)
        Inertia matrix; symmetric, positive definite on N(A).
    h : array_like, shape (..., n)
        ``h = f_g − C qd`` (Pinocchio: ``h = −nle``).
    A : array_like, shape (..., m, n)
        Active constraint matrix (``m = 0`` allowed).
    adot_qd : array_like, shape (..., m)
        ``Ȧ qd`` (Pinocchio's ``γ`` in ``J qdd + γ = 0``); any acceleration-level bias, e.g.
        from :func:`baumgarte_bias` or a rheonomic constraint.
    f : array_like, shape (..., n), optional
        Applied generalized force (actuation, springs, dampers); zero if omitted.
    mu : float or array_like, shape (...), optional
        Virtual mass; default :func:`optimal_virtual_mass`.
    rtol : float, optional
        Rank tolerance (see :mod:`nonmin.core.linalg`).

    Returns
    -------
    qdd : ndarray, shape (..., n)

    Raises
    ------
    ShapeError, NonFiniteError, NotSymmetricError
        Invalid inputs.
    NotPositiveDefiniteError
        If M is not positive definite on N(A).

    Examples
    --------
    A point pendulum in Cartesian coordinates, at rest at (1, 0):

    >>> import numpy as np
    >>> from nonmin.core import forward_dynamics
    >>> qdd = forward_dynamics(np.eye(2), [0.0, -9.81], [[1.0, 0.0]], [0.0])
    >>> np.allclose(qdd, [0.0, -9.81])
    True
    """
    engine = _ENGINE_FAST[0]  # the C++ engine's entry for one regular state (else None)
    if engine is not None:
        qdd = engine(M, h, A, adot_qd, f, mu, rtol, 0)
        if qdd is not None:
            return qdd  # type: ignore[no-any-return]
    fast = _fast.solve(M, h, A, adot_qd, f, mu, rtol, _fast.QDD)
    if fast is not None:
        return fast
    return _solve_dynamics_numpy(M, h, A, adot_qd, f, mu, rtol).qdd


def constraint_force(
    M: ArrayLike,
    h: ArrayLike,
    A: ArrayLike,
    adot_qd: ArrayLike,
    f: ArrayLike | None = None,
    *,
    mu: ArrayLike | None = None,
    rtol: float | None = None,
) -> FloatArray:
    """Generalized constraint force ``f_c = −S (f + h − M Ω qd)`` (paper, eq. (fc_R)).

    Computed without Lagrange multipliers; equals ``Aᵀλ`` of the KKT solution where that exists
    and stays finite and unique where λ does not (redundant or singular A). Arguments as in
    :func:`forward_dynamics`.

    Returns
    -------
    f_c : ndarray, shape (..., n)
    """
    engine = _ENGINE_FAST[0]
    if engine is not None:
        fc = engine(M, h, A, adot_qd, f, mu, rtol, 1)
        if fc is not None:
            return fc  # type: ignore[no-any-return]
    fast = _fast.solve(M, h, A, adot_qd, f, mu, rtol, _fast.FC)
    if fast is not None:
        return fast
    return _solve_dynamics_numpy(M, h, A, adot_qd, f, mu, rtol).f_c


def baumgarte_bias(
    adot_qd: ArrayLike,
    velocity_residual: ArrayLike,
    position_residual: ArrayLike | None = None,
    *,
    alpha: float = 0.0,
    beta: float = 0.0,
) -> FloatArray:
    """Acceleration bias with Baumgarte terms: ``Ȧ qd + 2α (A qd) + β² φ``.

    Passing it as ``adot_qd`` to :func:`forward_dynamics` enforces
    ``d²φ/dt² + 2α dφ/dt + β² φ = 0`` (the drift-tolerant form of ERRATA "Drift").

    Parameters
    ----------
    adot_qd : array_like, shape (..., m)
    velocity_residual : array_like, shape (..., m)
        ``A qd`` (plus ``∂φ/∂t`` for rheonomic rows).
    position_residual : array_like, shape (..., m), optional
        ``φ(q)``; zero rows for nonholonomic constraints.
    alpha, beta : float
        Baumgarte gains (1/s), ``≥ 0``.
    """
    a = V.nonnegative_float(alpha, "alpha")
    b = V.nonnegative_float(beta, "beta")
    ad = V.as_float_array(adot_qd, "adot_qd")
    m = ad.shape[-1] if ad.ndim else 0
    out = ad + 2.0 * a * V.vector(velocity_residual, "velocity_residual", m)
    if position_residual is not None:
        out = out + b * b * V.vector(position_residual, "position_residual", m)
    return out


def position_correction(
    M: ArrayLike,
    A: ArrayLike,
    phi: ArrayLike,
    *,
    mu: ArrayLike | None = None,
    rtol: float | None = None,
) -> FloatArray:
    """Minimum mass-metric correction onto ``φ = 0`` (one Gauss–Newton step): ``Δq = Sᵀ(−A⁺φ)``.

    ``Δq`` minimizes ``½ ΔqᵀMΔq`` subject to ``A Δq = −φ``; it needs M positive definite only
    on N(A) (ERRATA, "Drift"). Iterate ``q ← q + Δq`` to converge onto the manifold.

    Parameters
    ----------
    M : array_like, shape (..., n, n)
    A : array_like, shape (..., m, n)
        ``∂φ/∂q`` at q.
    phi : array_like, shape (..., m)
    mu, rtol : optional

    Returns
    -------
    dq : ndarray, shape (..., n)
    """
    Mm = V.symmetric(M, "M")
    n = Mm.shape[-1]
    Am = V.matrix(A, "A", None, n)
    ph = V.vector(phi, "phi", Am.shape[-2])
    mu_v = None if mu is None else V.positive_scalar_or_batch(mu, "mu")
    if n and _fast.engine_on():  # engine/src/core_dynamics.cpp: position_correction
        dq = _fast.engine_solver_kernel(1, Mm, Am, ph, mu_v, 0.0, resolve_rtol(rtol))
        if dq is not None:
            return dq
    basis = range_basis(Am, rtol)
    x = -basis.solve(ph)
    # Sᵀ x = x − P M̄⁻¹ M x
    Q = basis.range_projector()
    P = np.eye(n) - Q
    PMP = P @ Mm @ P
    mu_a = _optimal_mu(PMP, Mm, basis.rank) if mu_v is None else mu_v
    L = cholesky(PMP + np.asarray(mu_a)[..., None, None] * Q)
    return x - matvec(P, cho_solve(L, matvec(Mm, x)))
