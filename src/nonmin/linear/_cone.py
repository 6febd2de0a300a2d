"""The second-order tangent cone of a configuration manifold at a singular configuration.

At a configuration q₀ where the position-level rows A = ∂φ/∂q lose rank, a curve of the
manifold ``q(s) = q₀ + s v + s²/2 a + …`` must satisfy, order by order,

    A v = 0,        A a + φ''[v, v] = 0,

and the second equation is solvable for a iff ``wᵀ φ''[v, v] = 0`` for every w in the left
null space N(Aᵀ). With Z an orthonormal basis of N(A) and v = Z c, the admissible tangent
directions are the common zeros of the p = dim N(Aᵀ) quadratic forms

    H_i = Zᵀ (Σ_j w_ij ∇²φ_j) Z    (k × k, k = dim N(A)),        cᵀ H_i c = 0.

Every branch's tangent space lies in that cone. :func:`quadratic_cone` decomposes the common
zero set of quadratic forms into linear subspaces by exact splits, never by sampling:

* a semidefinite form vanishes exactly on its kernel (restrict to it);
* an indefinite form of rank 2, λ₁ (u₁·c)² + λ₂ (u₂·c)² with λ₁ > 0 > λ₂, is the product
  (√λ₁ u₁·c − √−λ₂ u₂·c)(√λ₁ u₁·c + √−λ₂ u₂·c): its zero set is two hyperplanes (recurse on
  each);
* when no form of the current list splits, the degenerate members of the pencils
  ``R_b − λ R_a`` of two forms (λ a real generalized eigenvalue) are tried;
* when all forms vanish on the current subspace it is a component.

If at some step no member found splits (an indefinite form of rank ≥ 3 on the subspace: a
curved cone such as x² + y² − z², or a pencil whose splitting members were not found) the
decomposition is not certified: :attr:`ConeDecomposition.exact` is False and
:attr:`ConeDecomposition.reason` says where.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

#: Relative size (to the largest eigenvalue of the normalized forms) below which an eigenvalue of
#: a quadratic form restricted to a subspace counts as zero. The forms come from exact
#: second derivatives (round-off ~1e-15 relative), so 1e-8 separates round-off from geometry.
CONE_RTOL = 1e-8


#: Lines of the decomposition closer than this (sine of their angle) are one line.
MERGE_ANGLE = 1e-4


@dataclass(frozen=True)
class ConeDecomposition:
    """The common zero set of quadratic forms as a union of linear subspaces.

    Attributes
    ----------
    subspaces : tuple of ndarray, each of shape (k, l_j)
        Orthonormal bases of the maximal linear subspaces (none contained in another).
    exact : bool
        True when every step was an exact split, so the union of ``subspaces`` is the whole
        zero set; False when a step found no splitting form (the subspaces found are in the
        zero set, but parts of it may be missing).
    reason : str
        Why the decomposition is not exact ('' when it is).
    """

    subspaces: tuple[FloatArray, ...]
    exact: bool
    reason: str


def _orth_complement(U: FloatArray, normals: FloatArray) -> FloatArray:
    """Orthonormal basis of {U x : normalsᵀ (U x) = 0} (normals: (k, j))."""
    N = U.T @ normals  # (l, j)
    if N.size == 0:
        return U
    _, s, vh = np.linalg.svd(N.T, full_matrices=True)  # rows of N.T: constraints on x
    r = int(np.sum(s > 1e-12 * max(float(s.max(initial=0.0)), 1e-300)))
    X = vh[r:].T
    return U @ X


def _classify(R: FloatArray, tol: float) -> tuple[str, FloatArray, FloatArray]:
    """('zero' | 'definite' | 'semidefinite' | 'pair' | 'none', eigenvalues, eigenvectors) of
    a symmetric R: 'semidefinite' zero set = kernel; 'pair' = indefinite of rank 2."""
    lam, V = np.linalg.eigh(0.5 * (R + R.T))
    big = float(np.abs(lam).max(initial=0.0))
    if big <= tol:
        return "zero", lam, V
    nz = np.abs(lam) > tol
    pos, neg = bool(np.any(lam[nz] > 0)), bool(np.any(lam[nz] < 0))
    if not (pos and neg):
        return ("definite" if int(nz.sum()) == R.shape[0] else "semidefinite"), lam, V
    if int(nz.sum()) == 2:
        return "pair", lam, V
    return "none", lam, V


def _unit(H: FloatArray) -> FloatArray | None:
    S = 0.5 * (H + H.T)
    nrm = float(np.abs(np.linalg.eigvalsh(S)).max(initial=0.0))
    if nrm <= 0.0:
        return None
    S = S / nrm
    i = int(np.argmax(np.abs(S)))  # a sign convention, to recognize repeats
    return S if S.flat[i] > 0 else -S


def _pencil_members(forms: list[FloatArray], tol: float, limit: int = 64) -> list[FloatArray]:
    """Degenerate members β R_a − α R_b of the pencils of pairs of forms ((α, β) a real
    generalized eigenvalue pair). A common kernel of R_a and R_b is deflated first: the members
    of a pencil that is singular everywhere (all members share a kernel) are then found where
    their rank drops further."""
    import scipy.linalg as sla

    out: list[FloatArray] = []

    def add(H: FloatArray) -> None:
        u = _unit(H)
        if u is not None and not any(float(np.abs(u - v).max()) <= 1e-9 for v in out):
            out.append(u)

    ell = forms[0].shape[0] if forms else 0
    for a in range(len(forms)):
        for b in range(a + 1, len(forms)):
            Ra, Rb = forms[a], forms[b]
            _, sv, vh = np.linalg.svd(np.vstack([Ra, Rb]))
            r = int(np.sum(sv > tol))
            Q = vh[:r].T  # complement of the common kernel
            if r == 0:
                continue
            A2, B2 = Q.T @ Ra @ Q, Q.T @ Rb @ Q
            try:
                w = sla.eigvals(A2, B2, homogeneous_eigvals=True)
            except (np.linalg.LinAlgError, ValueError):
                continue
            for al, be in zip(w[0], w[1], strict=True):
                # a real pair (α, β) up to a common phase
                z = al if abs(al) >= abs(be) else be
                ph = np.conj(z) / abs(z) if abs(z) > 0 else 1.0
                al, be = al * ph, be * ph
                if abs(al.imag) > 1e-8 * max(abs(al), abs(be)) or abs(be.imag) > 1e-8 * max(abs(al), abs(be)):
                    continue
                add(float(be.real) * Ra - float(al.real) * Rb)
            if len(out) >= limit * max(ell, 1):
                return out
    return out


def quadratic_cone(forms: list[FloatArray], tol: float = CONE_RTOL) -> ConeDecomposition:
    """Decompose ``{c ∈ R^k : cᵀ H_i c = 0 for all i}`` into maximal linear subspaces.

    Parameters
    ----------
    forms : list of ndarray, each of shape (k, k)
        Symmetric matrices (each is normalized to unit spectral norm here).
    tol : float
        Relative zero threshold of eigenvalues (:data:`CONE_RTOL`).

    Returns
    -------
    ConeDecomposition
    """
    if not forms:
        raise ValueError("quadratic_cone needs at least one form (or the whole space is the cone)")
    k = forms[0].shape[0]
    normed = []
    for H in forms:
        S = 0.5 * (H + H.T)
        nrm = float(np.abs(np.linalg.eigvalsh(S)).max(initial=0.0)) if k else 0.0
        if nrm > 0.0:
            normed.append(S / nrm)
    found: list[FloatArray] = []
    failures: list[str] = []

    def rec(U: FloatArray, depth: int) -> None:
        ell = U.shape[1]
        if ell == 0:
            return
        R = [U.T @ H @ U for H in normed]
        live = [Ri for Ri in R if _classify(Ri, tol)[0] != "zero"]
        if not live:
            found.append(U)
            return
        if ell == 1:
            return  # a nonzero form on a line vanishes only at 0
        tiers: list[list[FloatArray]] = [live]
        for tier in range(3):
            if tier == 1:
                tiers.append(_pencil_members(live, tol))
            elif tier == 2:
                tiers.append(_pencil_members(tiers[1], tol))
            cands = tiers[tier]
            best: tuple[int, str, FloatArray, FloatArray] | None = None
            for Ri in cands:
                kind, lam, V = _classify(Ri, tol)
                rank = {"definite": 0, "semidefinite": 1, "pair": 2}.get(kind)
                if rank is not None and (best is None or rank < best[0]):
                    best = (rank, kind, lam, V)
            if best is None:
                continue
            _, kind, lam, V = best
            if kind == "definite":
                return
            if kind == "semidefinite":
                nzm = np.abs(lam) > tol
                rec(_orth_complement(U, U @ V[:, nzm]), depth + 1)
                return
            i1 = int(np.argmax(lam))
            i2 = int(np.argmin(lam))
            a = np.sqrt(lam[i1]) * V[:, i1]
            b = np.sqrt(-lam[i2]) * V[:, i2]
            for nrm in (a - b, a + b):
                rec(_orth_complement(U, (U @ nrm)[:, None]), depth + 1)
            return
        failures.append(
            f"on a subspace of dimension {ell}, no form of the {len(live)} nonzero ones nor of "
            "the degenerate members of their pairwise pencils (two levels) is semidefinite or of rank 2 "
            "(a curved cone, or a pencil whose splitting members were not found)"
        )

    rec(np.eye(k), 0)
    # maximal subspaces only, without repeats; two lines closer than MERGE_ANGLE are one (a
    # double root of the forms, split by round-off into two lines ~sqrt(u) apart: their mean
    # is the root to round-off)
    found.sort(key=lambda B: -B.shape[1])
    keep: list[FloatArray] = []
    for B in found:
        dup = False
        for i, C in enumerate(keep):
            if C.shape[1] >= B.shape[1] and float(np.linalg.norm(B - C @ (C.T @ B))) <= MERGE_ANGLE:
                if C.shape[1] == 1 and B.shape[1] == 1:
                    m = C[:, 0] + np.sign(float(C[:, 0] @ B[:, 0])) * B[:, 0]
                    keep[i] = (m / np.linalg.norm(m))[:, None]
                dup = True
                break
        if not dup:
            keep.append(B)
    return ConeDecomposition(tuple(keep), not failures, "; ".join(failures))
