"""Projectors of the non-minimal formulation: P, Q, Λ, Ṗ, and the oblique projectors R, Γ, S.

Notation (paper, Sec. 2): ``A qd = 0``, ``P = I − A⁺A`` (orthogonal projector onto N = N(A)),
``Q = I − P``, ``Λ = −A⁺Ȧ``, ``Ω = Λ − Λᵀ``, ``r = rank A``.
All kernels are batched over leading dimensions.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .. import _engine  # type: ignore[attr-defined]  # the compiled extension (no stubs)
from .. import _validation as V
from ..errors import InfeasibleActuationError
from . import _fast
from .linalg import FloatArray, cholesky, range_basis, resolve_rtol

__all__ = [
    "actuation_projectors",
    "constraint_force_projector",
    "lambda_matrix",
    "nullspace_projector",
    "projector_derivative",
]


def nullspace_projector(
    A: ArrayLike, *, rtol: float | None = None
) -> tuple[FloatArray, NDArray[np.intp]]:
    """Orthogonal projector onto the null space of the constraint matrix.

    ``P = I − A⁺A`` (paper, definition before eq. (eq_(I-P)ddq)); ``P² = P = Pᵀ``, ``A P = 0``.

    Parameters
    ----------
    A : array_like, shape (..., m, n)
        Constraint matrix; ``m = 0`` (no active constraint) gives ``P = I``. Rank-deficient,
        duplicated, zero rows and ``m > n`` are all allowed.
    rtol : float, optional
        Relative singular-value cutoff (see :mod:`nonmin.core.linalg`); default
        :data:`~nonmin.core.linalg.DEFAULT_RTOL`.

    Returns
    -------
    P : ndarray, shape (..., n, n)
        The projector.
    rank : ndarray of int, shape (...)
        The numerical rank ``r`` of A that was used (``dim N(A) = n − r``).

    Examples
    --------
    >>> import numpy as np
    >>> from nonmin.core import nullspace_projector
    >>> P, r = nullspace_projector(np.array([[1.0, 1.0], [2.0, 2.0]]))
    >>> int(r), np.allclose(P, [[0.5, -0.5], [-0.5, 0.5]])
    (1, True)
    """
    Am = V.matrix(A, "A")
    basis = range_basis(Am, rtol)
    return basis.nullspace_projector(), basis.rank


def lambda_matrix(A: ArrayLike, Adot: ArrayLike, *, rtol: float | None = None) -> FloatArray:
    """``Λ = −A⁺Ȧ`` (paper, Remark 1), shape (..., n, n).

    A⁺ is the pseudo-inverse of A truncated to its numerical rank. ``PΛ = 0``; ``Λᵀ P = 0``.

    Parameters
    ----------
    A : array_like, shape (..., m, n)
        Constraint matrix.
    Adot : array_like, shape (..., m, n)
        Its time derivative Ȧ.
    rtol : float, optional
        Rank tolerance (see :mod:`nonmin.core.linalg`).

    Returns
    -------
    ndarray, shape (..., n, n)
        Λ.
    """
    from .linalg import pseudo_inverse

    Am = V.matrix(A, "A")
    Ad = V.matrix(Adot, "Adot", Am.shape[-2], Am.shape[-1])
    return -(pseudo_inverse(Am, rtol) @ Ad)


def projector_derivative(A: ArrayLike, Adot: ArrayLike, *, rtol: float | None = None) -> FloatArray:
    """Time derivative of P: ``Ṗ = ΛP + PΛᵀ`` (paper, eq. (OmegaP), Appendix A).

    Valid where the rank of A is locally constant (ERRATA 6): P is discontinuous where it
    changes. Shape (..., n, n).

    Parameters
    ----------
    A : array_like, shape (..., m, n)
        Constraint matrix.
    Adot : array_like, shape (..., m, n)
        Its time derivative Ȧ.
    rtol : float, optional
        Rank tolerance (see :mod:`nonmin.core.linalg`).

    Returns
    -------
    ndarray, shape (..., n, n)
        Ṗ (symmetric).
    """
    Am = V.matrix(A, "A")
    Lam = lambda_matrix(Am, Adot, rtol=rtol)
    P = range_basis(Am, rtol).nullspace_projector()
    LP = Lam @ P
    return LP + np.swapaxes(LP, -1, -2)


def actuation_projectors(
    B: ArrayLike, P: ArrayLike, *, rtol: float | None = None
) -> tuple[FloatArray, FloatArray]:
    """Actuation projectors ``Γ = (PB)⁺`` and ``R = BΓ`` (paper, eqs. (p1_inverse), (Q_definition)).

    ``u = Γ f_∥`` is the minimum-norm actuator force producing the admissible force
    ``f_∥ = P f``, and ``f = R f_∥`` the generalized force the actuators then exert.
    Corrected per ERRATA 4: ``Γ = (PB)⁺`` (not ``(BᵀPB)⁻¹BᵀP``, which fails with redundant
    actuation); ``R² = R``, ``RP = R``, ``RQ = 0`` always and ``PR = P`` exactly when the
    actuation condition ``rank(PB) = n − rank(A)`` holds.

    Parameters
    ----------
    B : array_like, shape (..., n, k)
        Input matrix (``f = B u``).
    P : array_like, shape (..., n, n)
        Null-space projector of the active constraints.
    rtol : float, optional
        Relative cutoff for the rank of PB.

    Returns
    -------
    R : ndarray, shape (..., n, n)
    Gamma : ndarray, shape (..., k, n)

    Raises
    ------
    InfeasibleActuationError
        If ``rank(PB) < n − rank(A)``: some admissible force cannot be produced.
    """
    Pm = V.symmetric(P, "P")
    n = Pm.shape[-1]
    Bm = V.matrix(B, "B", n, None)
    tol = resolve_rtol(rtol)
    k = Bm.shape[-1]
    if n and _fast.engine_on():  # engine/src/core_dynamics.cpp: actuation_projectors
        st = _fast.strided([(Bm, (n, k)), (Pm, (n, n))])
        if st is not None:
            bshape, N, ((Bb, sB), (Pb, sP)) = st
            R = np.empty((N, n, n))
            G = np.empty((N, k, n))
            rank_pb = np.empty(N, dtype=np.int64)
            dofs = np.empty(N, dtype=np.int64)
            _engine.core_actuation(Bb, Pb, sB, sP, N, n, k, tol, R, G, rank_pb, dofs,
                                   _fast.engine_threads(N))  # fmt: skip
            _check_actuation(rank_pb, dofs)
            return R.reshape((*bshape, n, n)), G.reshape((*bshape, k, n))
    PB = Pm @ Bm
    U, s, Vh = np.linalg.svd(PB, full_matrices=False)
    if s.shape[-1] == 0:
        keep = np.zeros(s.shape, dtype=bool)
    else:
        # Cutoff relative to the actuators' own scale (largest column norm of B), not to
        # s_max(PB): when P annihilates B up to round-off, PB is noise and its rank is 0.
        bscale = np.sqrt(np.max(np.einsum("...ij,...ij->...j", Bm, Bm), axis=-1))
        ref = np.maximum(np.maximum(s[..., 0], bscale), np.finfo(float).tiny)
        keep = s > tol * ref[..., None]
    rank_pb = np.count_nonzero(keep, axis=-1)
    dof = np.rint(np.trace(Pm, axis1=-2, axis2=-1)).astype(int)
    _check_actuation(rank_pb, dof)
    inv_s = np.where(keep, 1.0 / np.where(keep, s, 1.0), 0.0)
    Gamma = (np.swapaxes(Vh, -1, -2) * inv_s[..., None, :]) @ np.swapaxes(U, -1, -2)
    R = Bm @ Gamma
    return R, Gamma


def _check_actuation(rank_pb: NDArray[np.integer], dof: NDArray[np.integer]) -> None:
    """Raise :class:`InfeasibleActuationError` for the first state with rank(PB) < n − rank(A)."""
    if np.any(rank_pb < dof):
        idx = np.argwhere(np.atleast_1d(rank_pb < dof))[0]
        rp = int(np.atleast_1d(rank_pb)[tuple(idx)])
        dd = int(np.atleast_1d(dof)[tuple(idx)])
        raise InfeasibleActuationError(
            f"actuation is infeasible: rank(PB) = {rp} < n − rank(A) = {dd}; the actuators "
            "cannot produce every admissible generalized force (need N(A) ⊆ R(PB))"
        )


def constraint_force_projector(M: ArrayLike, P: ArrayLike, mu: ArrayLike) -> FloatArray:
    """Oblique projector ``S = I − M M̄⁻¹ P`` (paper, eq. (S_definition)).

    ``f_c = −S (f + h − M Ω qd)`` (eq. (fc_R)). ``S² = S``, ``QS = S``, ``SQ = Q``, ``PS = 0``,
    ``M Sᵀ = S M``. Independent of μ > 0.

    Parameters
    ----------
    M : array_like, shape (..., n, n)
    P : array_like, shape (..., n, n)
    mu : float or array_like, shape (...)
        Virtual mass μ > 0.

    Returns
    -------
    S : ndarray, shape (..., n, n)
    """
    Mm = V.symmetric(M, "M")
    n = Mm.shape[-1]
    Pm = V.symmetric(P, "P", n)
    mu_a = V.positive_scalar_or_batch(mu, "mu")
    if n and _fast.engine_on():  # engine/src/core_dynamics.cpp: constraint_force_projector
        st = _fast.strided([(Mm, (n, n)), (Pm, (n, n)), (mu_a, ())])
        if st is not None:
            bshape, N, ((Mb, sM), (Pb, sP), (mub, smu)) = st
            S = np.empty((N, n, n))
            status = np.empty(N, dtype=np.int64)
            _engine.core_force_projector(Mb, Pb, mub, sM, sP, smu, N, n, S, status,
                                         _fast.engine_threads(N))  # fmt: skip
            if not status.any():
                return S.reshape((*bshape, n, n))
            # M̄ not positive definite: the NumPy path below raises the typed error
    from .dynamics import _mbar

    Mbar = _mbar(Mm, Pm, mu_a)
    L = cholesky(Mbar)
    # X = M̄⁻¹ P solved column by column (batched): M̄ X = P
    X = _cho_solve_mat(L, np.broadcast_to(Pm, Mbar.shape))
    return np.eye(n) - Mm @ X


def _cho_solve_mat(L: FloatArray, Bm: FloatArray) -> FloatArray:
    """Solve ``L Lᵀ X = B`` for matrix right-hand sides (batched)."""
    from .linalg import cho_solve

    cols = [cho_solve(L, np.ascontiguousarray(Bm[..., :, j])) for j in range(Bm.shape[-1])]
    return np.stack(cols, axis=-1)
