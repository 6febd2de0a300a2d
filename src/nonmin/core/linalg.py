"""Rank-revealing decompositions, the tolerance policy and SPD solves.

Tolerance policy
----------------
Rank decisions about the constraint matrix ``A`` (shape ``(..., m, n)``) are made on the
*row-equilibrated* matrix ``D A``, ``D = diag(1/‖a_i‖)``:

1. a row whose norm is ``≤ rtol · max_i ‖a_i‖`` is treated as a zero row (it vanished, e.g. the
   gradient of a constraint at a singular point of φ);
2. every other row is scaled to unit length (this changes neither N(A) nor the minimum-norm
   solution of a consistent system ``A x = b``);
3. the SVD ``D A = U Σ Vᵀ`` is computed and singular values ``σ_i ≤ rtol · σ_max`` are treated
   as zero. The number kept is the rank ``r`` used everywhere downstream and is returned.

Equilibration makes the decision independent of the units of each constraint row (Andrews'
mechanism has lengths ~1e-2 m), and the relative cutoff makes it independent of an overall
scale. The default ``rtol`` is :data:`DEFAULT_RTOL` = 1e-10: far above round-off in ``A``
(~1e-16 relative), far below the singular values that matter (a configuration must be within
~1e-10 rad of a singular one to be declared singular). Every public kernel takes ``rtol=`` to
override it.

The pseudo-inverse applied to a vector is the minimum-norm solution of the equilibrated system,
``x = (DA)⁺ D b``; it equals ``A⁺ b`` whenever ``b ∈ R(A)`` (always the case for consistent
constraints) and is the D-weighted least-squares solution otherwise. :func:`pseudo_inverse`
returns the exact Moore–Penrose ``A⁺`` (of the rank-truncated ``A``) for the paper's Λ = −A⁺Ȧ.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from ..errors import NotPositiveDefiniteError

#: Sums of squares outside [ROW_NORM_SMALL, ROW_NORM_BIG] are recomputed scaled in
#: :func:`row_norms` (the plain formula over- or underflows near 1e±308).
ROW_NORM_BIG = 1e300
ROW_NORM_SMALL = 1e-290

FloatArray = NDArray[np.float64]

#: Default relative singular-value cutoff for rank decisions on the equilibrated A.
DEFAULT_RTOL: float = 1e-10

#: M̄ is declared not positive definite when a Cholesky pivot satisfies
#: ``L_ii² ≤ SPD_RTOL · max_j M̄_jj`` (i.e. cond(M̄) ≳ 1/SPD_RTOL) or when Cholesky fails.
SPD_RTOL: float = 1e-13


def resolve_rtol(rtol: float | None) -> float:
    """Return the rank tolerance to use (``DEFAULT_RTOL`` when ``rtol`` is None)."""
    if rtol is None:
        return DEFAULT_RTOL
    val = float(rtol)
    if not (0.0 < val < 1.0):
        from ..errors import InputError

        raise InputError(f"rtol must lie in (0, 1), got {rtol!r}")
    return val


class RangeBasis(NamedTuple):
    """Rank-revealing factorization of a (batch of) constraint matrices A.

    Attributes
    ----------
    U : ndarray, shape (..., m, k)
        Left singular vectors of the equilibrated matrix ``D A`` (``k = min(m, n)``).
    s : ndarray, shape (..., k)
        Singular values of ``D A`` in decreasing order.
    Vh : ndarray, shape (..., k, n)
        Right singular vectors (rows); the kept rows span R(Aᵀ) = N(A)^⊥.
    keep : ndarray of bool, shape (..., k)
        Which singular values are above the cutoff.
    inv_s : ndarray, shape (..., k)
        ``1/s`` where kept, 0 elsewhere.
    d : ndarray, shape (..., m)
        Row scaling (``1/‖a_i‖``; 0 for rows treated as zero).
    rank : ndarray of int, shape (...)
        Numerical rank used.
    n : int
        Number of columns of A.
    """

    U: FloatArray
    s: FloatArray
    Vh: FloatArray
    keep: NDArray[np.bool_]
    inv_s: FloatArray
    d: FloatArray
    rank: NDArray[np.intp]
    n: int

    def range_projector(self) -> FloatArray:
        """``Q = A⁺A``, the orthogonal projector onto N(A)^⊥ = R(Aᵀ); shape (..., n, n)."""
        Vk = self.Vh * self.keep[..., None]
        return np.swapaxes(Vk, -1, -2) @ Vk

    def nullspace_projector(self) -> FloatArray:
        """``P = I − A⁺A``, the orthogonal projector onto N(A); shape (..., n, n)."""
        return np.eye(self.n) - self.range_projector()

    def solve(self, b: FloatArray) -> FloatArray:
        """Minimum-norm solution ``x = (DA)⁺ D b`` of ``A x = b``; b shape (..., m) -> (..., n)."""
        if self.U.shape[-2] == 0:
            return np.zeros((*np.broadcast_shapes(b.shape[:-1], self.U.shape[:-2]), self.n))
        c = np.einsum("...mk,...m->...k", self.U, self.d * b) * self.inv_s
        return np.einsum("...kn,...k->...n", self.Vh, c)

    def pinv(self) -> FloatArray:
        """The pseudo-inverse ``(DA)⁺ D`` as a matrix, shape (..., n, m)."""
        Vt = np.swapaxes(self.Vh, -1, -2) * self.inv_s[..., None, :]
        return (Vt @ np.swapaxes(self.U, -1, -2)) * self.d[..., None, :]


def range_basis(A: FloatArray, rtol: float | None = None) -> RangeBasis:
    """Rank-revealing SVD of the row-equilibrated constraint matrix (see module docstring).

    Parameters
    ----------
    A : ndarray, shape (..., m, n)
        Constraint matrix (already validated). ``m = 0`` is allowed.
    rtol : float, optional
        Relative cutoff; :data:`DEFAULT_RTOL` if None.

    Returns
    -------
    RangeBasis
    """
    tol = resolve_rtol(rtol)
    batch = A.shape[:-2]
    m, n = A.shape[-2], A.shape[-1]
    if m == 0 or n == 0:
        k = 0
        return RangeBasis(
            U=np.zeros((*batch, m, k)),
            s=np.zeros((*batch, k)),
            Vh=np.zeros((*batch, k, n)),
            keep=np.zeros((*batch, k), dtype=bool),
            inv_s=np.zeros((*batch, k)),
            d=np.zeros((*batch, m)),
            rank=np.zeros(batch, dtype=np.intp),
            n=n,
        )
    norms = row_norms(A)
    big = np.max(norms, axis=-1, keepdims=True)
    live = norms > tol * big
    d = np.where(live, 1.0 / np.where(live, norms, 1.0), 0.0)
    U, s, Vh = np.linalg.svd(A * d[..., None], full_matrices=False)
    keep = s > tol * s[..., :1]
    inv_s = np.where(keep, 1.0 / np.where(keep, s, 1.0), 0.0)
    rank = np.count_nonzero(keep, axis=-1).astype(np.intp)
    return RangeBasis(U=U, s=s, Vh=Vh, keep=keep, inv_s=inv_s, d=d, rank=rank, n=n)


def row_norms(A: FloatArray) -> FloatArray:
    """Euclidean norms of the rows of ``A`` without overflow or underflow, shape (..., m).

    The plain ``sqrt(Σ a_j²)`` overflows to inf above ~1.3e154 (a row of inf norm then made
    every other row look negligible: they were dropped without a word) and underflows to 0
    below ~1e-154. Rows whose sum of squares leaves ``[ROW_NORM_SMALL, ROW_NORM_BIG]`` are
    recomputed as ``s·‖a/s‖`` with ``s = max_j |a_j|``; the others keep the plain sum (so
    results on ordinary data are bitwise those of the plain formula). NaN stays NaN and an
    infinite entry gives a non-finite norm, so finiteness checks on the norms still work.

    Parameters
    ----------
    A : ndarray, shape (..., m, n)

    Returns
    -------
    ndarray, shape (..., m)
    """
    sq = np.einsum("...ij,...ij->...i", A, A)
    norms = np.sqrt(sq)
    risky = (sq > ROW_NORM_BIG) | (sq < ROW_NORM_SMALL)
    if np.any(risky):
        with np.errstate(invalid="ignore", over="ignore"):
            scale = np.max(np.abs(A), axis=-1, initial=0.0)
            safe = np.where(scale > 0.0, scale, 1.0)
            scaled = A / safe[..., None]
            fixed = scale * np.sqrt(np.einsum("...ij,...ij->...i", scaled, scaled))
        norms = np.where(risky, fixed, norms)
    return np.asarray(norms)


def pseudo_inverse(A: FloatArray, rtol: float | None = None) -> FloatArray:
    """Moore–Penrose pseudo-inverse of the rank-truncated A, shape (..., n, m).

    Rank is decided as in :func:`range_basis`; the pseudo-inverse itself is that of ``A``
    (not of the equilibrated matrix), computed from an SVD of ``A`` truncated to that rank.

    Parameters
    ----------
    A : ndarray, shape (..., m, n)
    rtol : float, optional
        Rank tolerance (default :data:`DEFAULT_RTOL`).

    Returns
    -------
    ndarray, shape (..., n, m)
        A⁺.
    """
    basis = range_basis(A, rtol)
    m, n = A.shape[-2], A.shape[-1]
    if m == 0 or n == 0:
        return np.zeros((*A.shape[:-2], n, m))
    U, s, Vh = np.linalg.svd(A, full_matrices=False)
    idx = np.arange(s.shape[-1])
    keep = idx < basis.rank[..., None]
    inv_s = np.where(keep, 1.0 / np.where(keep & (s > 0), s, 1.0), 0.0)
    return (np.swapaxes(Vh, -1, -2) * inv_s[..., None, :]) @ np.swapaxes(U, -1, -2)


def cholesky(Mbar: FloatArray, name: str = "Mbar") -> FloatArray:
    """Lower Cholesky factor of a batch of SPD matrices, with a typed error.

    Raises
    ------
    NotPositiveDefiniteError
        If any matrix is not numerically positive definite (Cholesky fails, or a pivot is
        below ``SPD_RTOL`` relative to the largest diagonal entry).
    """
    # One arithmetic for single and batched calls (NumPy's LAPACK, same routine per matrix), so
    # that a single call and the same state inside a batch agree bitwise.
    try:
        L = np.asarray(np.linalg.cholesky(Mbar), dtype=np.float64)
    except np.linalg.LinAlgError:
        raise NotPositiveDefiniteError(
            f"{name} = PMP + μQ is not positive definite: the inertia matrix M is not positive "
            "definite on the null space N(A) of the active constraints (a coordinate with no "
            "inertia that no constraint fixes, e.g. a quaternion without its norm constraint)"
        ) from None
    piv = np.diagonal(L, axis1=-2, axis2=-1) ** 2
    scale = np.max(np.diagonal(Mbar, axis1=-2, axis2=-1), axis=-1)
    if np.any(np.min(piv, axis=-1) <= SPD_RTOL * scale):
        ratio = float(np.min(np.min(piv, axis=-1) / scale))
        raise NotPositiveDefiniteError(
            f"{name} = PMP + μQ is numerically singular (smallest Cholesky pivot² / largest "
            f"diagonal = {ratio:.3g} ≤ {SPD_RTOL:g}): M is not positive definite on N(A)"
        )
    return L


def cho_solve(L: FloatArray, b: FloatArray) -> FloatArray:
    """Solve ``L Lᵀ x = b`` for a batch; L shape (..., n, n), b shape (..., n).

    Single and batched calls run the same substitution, so they agree bitwise.
    """
    n = L.shape[-1]
    shape = np.broadcast_shapes(L.shape[:-2], b.shape[:-1])
    L = np.broadcast_to(L, (*shape, n, n))
    y = np.empty((*shape, n))
    b = np.broadcast_to(b, (*shape, n))
    for i in range(n):  # forward substitution L y = b, vectorized over the batch
        y[..., i] = (b[..., i] - np.einsum("...j,...j->...", L[..., i, :i], y[..., :i])) / L[..., i, i]
    x = np.empty_like(y)
    for i in range(n - 1, -1, -1):  # back substitution Lᵀ x = y
        x[..., i] = (y[..., i] - np.einsum("...j,...j->...", L[..., i + 1 :, i], x[..., i + 1 :])) / L[
            ..., i, i
        ]
    return x


def matvec(Mat: FloatArray, v: FloatArray) -> FloatArray:
    """Batched matrix-vector product ``Mat @ v`` with shapes (..., a, b), (..., b) -> (..., a)."""
    return (Mat @ v[..., None])[..., 0]
