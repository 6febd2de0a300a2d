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
    if risky.any():
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
    if L.ndim == 2 and L.size and (L.diagonal() ** 2).min() > SPD_RTOL * Mbar.diagonal().max():
        return L  # one state (the common call): the same test on its two extremes
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
    # One state: the same sums (the same einsum over the same slices) without the batch's
    # broadcasting and ellipsis indexing, which took half the time of a call at n ≤ 15.
    if L.ndim == 2 and b.ndim == 1:
        y1 = np.empty(n)
        for i in range(n):
            y1[i] = (b[i] - np.einsum("j,j->", L[i, :i], y1[:i])) / L[i, i]
        x1 = np.empty(n)
        for i in range(n - 1, -1, -1):
            x1[i] = (y1[i] - np.einsum("j,j->", L[i + 1 :, i], x1[i + 1 :])) / L[i, i]
        return x1
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


# --------------------------------------------------------------------------- certified LQ
# The specification of the engine's rank-revealing certified LQ (engine/src/core_lq.cpp,
# docs/theory.md rule 3): the shortcut that proves, without an SVD, which rank the SVD rule of
# rule 3 decides on the equilibrated live rows of A, and skips rows that are redundant to
# round-off (a permanently redundant constraint, e.g. Bricard's mechanism).

#: Up to this many rows the certificate is the Frobenius one (``‖L‖_F ‖L⁻¹‖_F``), above it the
#: Cholesky factorization of ``L Lᵀ − τ I`` (C++ ``DENSE_INVERSE_MAX_ROWS``).
DENSE_INVERSE_MAX_ROWS = 32
#: The Frobenius certificate's margin for ``rtol ≤ QR_MARGIN_RTOL`` (else 1).
QR_MARGIN = 10.0
QR_MARGIN_RTOL = 1e-6
#: The Cholesky certificate proves ``σ_min > CERT_SLACK · max(rtol, CERT_FLOOR) · σ_max``.
CERT_FLOOR = 1e-5
CERT_SLACK = 1.01


def redundant_row_tol(m: int, n: int) -> float:
    """Residual norm at or below which a unit row is skipped as redundant: ``m n ε``.

    The Householder LQ of the ``m × n`` equilibrated rows is backward stable row by row with
    ``‖Δx_i‖ ≤ γ̃_{mn} ‖x_i‖ ≈ m n u`` (Higham, *Accuracy and Stability*, Thm 19.4): a row that
    is exactly a combination of the rows kept before it leaves a residual of that order.
    """
    return float(m) * float(n) * float(np.finfo(np.float64).eps)


class CertifiedLQ(NamedTuple):
    """The rank-revealing LQ ``B[kept] = L Q`` of unit rows ``B`` and what it proved.

    Attributes
    ----------
    certified : bool
        True when the certificate proves that the SVD rule (σ ≤ rtol σ_max is zero) on ``B``
        keeps exactly ``rank`` singular values; False: the SVD decides (nothing else is to be
        used then).
    rank : int
        Rows kept ``r``.
    kept, skipped : ndarray of int, shapes (r,), (m − r,)
        Indices of the kept and skipped rows of ``B``.
    L : ndarray, shape (r, r)
        Lower triangular factor of the kept rows.
    Q : ndarray, shape (r, n)
        Orthonormal rows spanning the kept rows (= R(Bᵀ) when certified).
    residuals : ndarray, shape (m − r,)
        Each skipped row's residual norm against the rows kept before it.
    """

    certified: bool
    rank: int
    kept: NDArray[np.intp]
    skipped: NDArray[np.intp]
    L: FloatArray
    Q: FloatArray
    residuals: FloatArray

    def solve(self, b: FloatArray) -> FloatArray:
        """Minimum-norm solution ``x = Qᵀ L⁻¹ b[kept]`` of ``B x = b`` (b consistent), shape (n,)."""
        y = np.linalg.solve(self.L, np.asarray(b, dtype=np.float64)[self.kept]) if self.rank else np.zeros(0)
        return np.asarray(self.Q.T @ y)


#: Only a row whose residual is at most this (unit rows) is tested for redundancy.
REDUNDANT_CANDIDATE = 1e-8


#: A skipped row's bias must be the same combination of the kept rows' biases to this relative
#: accuracy (else the SVD's least-squares solution of the inconsistent system is taken).
REDUNDANT_BIAS_RTOL = 1e-10


def _redundant(x: FloatArray, rows: list[FloatArray], s: float, delta: float, bj: float,
               bk: FloatArray) -> bool:
    """Whether a row with residual sum of squares ``s`` is redundant to round-off in ``[B | b]``:
    ``√s ≤ δ (1 + ‖c‖₁)``, ``c L = x[:r]`` its combination of the kept rows (rows of ``L``; the
    round-off of an exactly dependent row grows with the kept rows it combines), and its bias
    ``bj`` that combination of the kept rows' biases ``bk`` to :data:`REDUNDANT_BIAS_RTOL`."""
    if not s <= REDUNDANT_CANDIDATE**2:
        return False
    r = len(rows)
    L = np.array([row[:r] for row in rows]).reshape(r, r)
    c = np.linalg.solve(L.T, x[:r]) if r else np.zeros(0)
    d = delta * (1.0 + float(np.sum(np.abs(c))))
    if not s <= d * d:
        return False
    t = c * bk
    return abs(bj - float(np.sum(t))) <= REDUNDANT_BIAS_RTOL * (abs(bj) + float(np.sum(np.abs(t))))


def certified_lq(B: FloatArray, rtol: float | None = None, *, b: FloatArray | None = None,
                 certificate: str | None = None) -> CertifiedLQ:
    """Rank-revealing certified LQ of equilibrated rows (the engine's shortcut of rule 3).

    The rows are taken in order; reflector ``k`` (Householder, from the right) pivots on column
    ``k``. A row whose residual against the rows kept before it (its entries in the columns
    not pivoted yet) has norm ``ρ ≤ δ (1 + ‖c‖₁)`` (``ρ ≤`` :data:`REDUNDANT_CANDIDATE`,
    ``δ =`` :func:`redundant_row_tol`, ``c`` its combination of the kept rows) is *skipped*: it
    is treated as a vanished row, provided its bias is the same combination of the kept rows'
    biases (to :data:`REDUNDANT_BIAS_RTOL`). With ``X = B`` in the reflectors' basis, ``X = [L₁₁ 0; L₂₁ E]`` (kept rows,
    then skipped ones) and ``‖E‖₂ ≤ e_F = √Σρ²`` (a residual against every kept row is at most
    the one against the rows kept before it). By Weyl's inequality ``σ_{r+1}(X) ≤ e_F`` and
    ``σ_r(X) ≥ σ_min(L₁₁) − e_F``; ``σ_max(X) ≥ max_a ‖L_a‖`` and
    ``σ_max(X)² ≤ ‖L₁₁‖² + Σ_skipped ‖b_s‖²``. The certificate holds when

    * ``margin · e_F < rtol · max_a ‖L_a‖`` (the SVD rule drops the skipped directions), and
    * ``σ_min(L₁₁) > rt · σ_max(X) + e_F`` (it keeps the others), proved either by
      ``‖L⁻¹‖_F⁻¹ > margin · rtol · √(‖L‖_F² + Σ‖b_s‖²) + e_F`` (``certificate="frobenius"``,
      margin :data:`QR_MARGIN`) or by the Cholesky factorization of ``L Lᵀ − τ I`` with
      ``√τ = rt · √(‖L Lᵀ‖∞ + Σ‖b_s‖²) + e_F``, ``rt = CERT_SLACK · max(rtol, CERT_FLOOR)``
      (``"profile"``, margin :data:`CERT_SLACK`).

    Without skipped rows both are the engine's earlier certificates unchanged. Near-singular
    rows (residual above round-off but below the certificate's floor) make it refuse.

    Parameters
    ----------
    B : ndarray, shape (m, n)
        Row-equilibrated live rows (unit norms) of ``D A``.
    b : ndarray, shape (m,), optional
        The equilibrated bias ``D b`` (default zeros): a row redundant in ``B`` whose bias is not
        the same combination (an inconsistent system) is kept, and the certificate refuses.
    rtol : float, optional
        The rank rule's relative cutoff (default :data:`DEFAULT_RTOL`).
    certificate : {"frobenius", "profile"}, optional
        Default: Frobenius up to :data:`DENSE_INVERSE_MAX_ROWS` rows, else profile (as the engine).

    Returns
    -------
    CertifiedLQ
    """
    tol = resolve_rtol(rtol)
    X = np.asarray(B, dtype=np.float64)
    m, n = X.shape
    if certificate is None:
        certificate = "frobenius" if m <= DENSE_INVERSE_MAX_ROWS else "profile"
    delta = redundant_row_tol(m, n)
    bias = np.zeros(m) if b is None else np.asarray(b, dtype=np.float64)
    refused = False
    refl: list[tuple[FloatArray, float]] = []
    rows: list[FloatArray] = []
    kept: list[int] = []
    skipped: list[int] = []
    res: list[float] = []
    for j in range(m):
        x = X[j].copy()
        for v, beta in refl:  # the reflectors of the rows kept so far
            x -= beta * float(x @ v) * v
        p = len(kept)
        s = float(x[p:] @ x[p:]) if p < n else 0.0
        if _redundant(x, rows, s, delta, float(bias[j]), bias[kept]):
            skipped.append(j)
            res.append(float(np.sqrt(s)))
            continue
        if p >= n:  # no residual left but an inconsistent bias: the SVD decides
            refused = True
            break
        alpha = -np.sqrt(s) if x[p] >= 0.0 else np.sqrt(s)
        v = np.zeros(n)
        v[p:] = x[p:]
        v[p] -= alpha
        refl.append((v, 2.0 / float(v @ v)))
        row = np.zeros(n)
        row[:p] = x[:p]
        row[p] = alpha
        rows.append(row)
        kept.append(j)
    r = len(kept)
    L = np.array([row[:r] for row in rows]).reshape(r, r)
    Q = np.eye(n)[:r]
    for v, beta in reversed(refl):
        Q = Q - beta * np.outer(Q @ v, v)
    e_f = float(np.sqrt(np.sum(np.square(res))))
    skip_n2 = float(np.sum(np.square(X[skipped]))) if skipped else 0.0
    row2max = float(np.max(np.sum(L * L, axis=1))) if r else 0.0
    ok = r > 0 and not refused
    if ok and certificate == "frobenius":
        margin = QR_MARGIN if tol <= QR_MARGIN_RTOL else 1.0
        fi = float(np.sum(np.square(np.linalg.inv(L))))
        if skipped:
            ok = margin * e_f < tol * np.sqrt(row2max)
            bound = margin * tol * np.sqrt(float(np.sum(L * L)) + skip_n2) + e_f
            ok = ok and bound * np.sqrt(fi) < 1.0
        else:
            ok = np.sqrt(float(np.sum(L * L))) * np.sqrt(fi) * margin * tol < 1.0
    elif ok:
        T = L @ L.T
        rt = CERT_SLACK * max(tol, CERT_FLOOR)
        tnorm = float(np.max(np.sum(np.abs(T), axis=1)))
        tau = rt * rt * tnorm
        if skipped:
            ok = CERT_SLACK * e_f < tol * np.sqrt(row2max)
            tau = (rt * np.sqrt(tnorm + skip_n2) + e_f) ** 2
        if ok:
            try:
                np.linalg.cholesky(T - tau * np.eye(r))
            except np.linalg.LinAlgError:
                ok = False
    return CertifiedLQ(
        certified=bool(ok),
        rank=r,
        kept=np.asarray(kept, dtype=np.intp),
        skipped=np.asarray(skipped, dtype=np.intp),
        L=L,
        Q=Q,
        residuals=np.asarray(res),
    )
