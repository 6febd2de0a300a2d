"""Shared generators, tolerances and independent reference solvers for the tests of nonmin.core.

Nothing here imports nonmin's algorithms: the reference solvers (KKT, Udwadia–Kalaba, the
classical impact projection, the mass-metric correction) are written from their textbook
definitions so that they are independent cross-checks of the projection method.
"""

from __future__ import annotations

import numpy as np
from hypothesis import strategies as st

# --------------------------------------------------------------------------- named tolerances

#: Identities of orthogonal projectors (entries O(1)): P² = P = Pᵀ, A P = 0, ...
PROJ_TOL = 1e-12
#: Identities involving M̄⁻¹ or the oblique projectors R, S, relative to the norms involved.
OBLIQUE_RTOL = 1e-9
#: Eigenvalues of M̄ against {μ} ∪ nonzero eig(PMP), relative to λmax.
EIG_RTOL = 1e-10
#: Accelerations / forces against the KKT and Udwadia–Kalaba references (issue #2: 1e-10).
REF_RTOL = 1e-10
#: qdd for two very different virtual masses μ (the problem is then worse conditioned).
MU_RTOL = 1e-8

def available_backends() -> tuple[str, ...]:
    """The dynamics backends of nonmin.core: the NumPy reference and the C++ engine."""
    return ("numpy", "engine")


KINDS = ("full", "deficient", "duplicated", "zero_rows", "all_zero", "wide", "empty")


def random_spd(rng: np.random.Generator, n: int, cond: float = 1e2) -> np.ndarray:
    """A random SPD matrix with eigenvalues log-uniform in [1, cond], random scale."""
    Qm, _ = np.linalg.qr(rng.standard_normal((n, n)))
    ev = np.exp(rng.uniform(0.0, np.log(cond), n))
    M = (Qm * ev) @ Qm.T
    return 0.5 * (M + M.T)


def random_A(rng: np.random.Generator, kind: str, n: int, m: int) -> tuple[np.ndarray, int]:
    """A constraint matrix of the given kind and its exact rank.

    kinds: full (rank min(m, n), m ≤ n), deficient (rank < min(m, n)), duplicated (exact and
    scaled copies of rows), zero_rows (some rows exactly zero), all_zero, wide (m > n),
    empty (m = 0).
    """
    if kind == "empty":
        return np.zeros((0, n)), 0
    if kind == "all_zero":
        return np.zeros((max(m, 1), n)), 0
    if kind == "full":
        m = min(max(m, 1), n)
        return rng.standard_normal((m, n)) * rng.uniform(0.1, 10.0, (m, 1)), m
    if kind == "wide":
        m = n + 1 + (m % 3)
        return rng.standard_normal((m, n)), n
    if kind == "deficient":
        m = max(m, 2)
        r = int(rng.integers(1, min(m, n)))  # 1 ≤ r < min(m, n)  (n ≥ 2 for this kind)
        return rng.standard_normal((m, r)) @ rng.standard_normal((r, n)), r
    if kind == "duplicated":
        k = min(max(m // 2, 1), n)
        base = rng.standard_normal((k, n))
        copies = base[rng.integers(0, k, size=k + 1)]
        scale = np.where(rng.uniform(size=(k + 1, 1)) < 0.5, 1.0, -2.5)
        A = np.vstack([base, copies * scale])
        return A[rng.permutation(A.shape[0])], k
    if kind == "zero_rows":
        k = min(max(m // 2, 1), n)
        base = rng.standard_normal((k, n))
        A = np.vstack([base, np.zeros((k, n))])
        return A[rng.permutation(2 * k)], k
    raise ValueError(kind)


def basis_of_nullspace(A: np.ndarray, rank: int) -> np.ndarray:
    """Orthonormal basis Z (n, n−r) of N(A) from a plain SVD (independent of nonmin)."""
    n = A.shape[1]
    if A.shape[0] == 0:
        return np.eye(n)
    _, _, Vh = np.linalg.svd(A)
    return Vh[rank:].T


def singular_mass_pd_on_nullspace(
    rng: np.random.Generator, A: np.ndarray, rank: int
) -> np.ndarray:
    """A coupled, singular M that is positive definite on N(A) (needs rank ≥ 1).

    ``M = W − v vᵀ/(vᵀW⁻¹v)`` with W SPD and v ∈ R(Aᵀ): M ⪰ 0 with the single null vector
    ``z = W⁻¹v``, and ``A z ≠ 0`` because ``vᵀz > 0`` while v ⟂ N(A).
    """
    n = A.shape[1]
    W = random_spd(rng, n, 10.0)
    _, _, Vh = np.linalg.svd(A)
    v = Vh[:rank].T @ rng.standard_normal(rank)
    M = W - np.outer(v, v) / (v @ np.linalg.solve(W, v))
    return 0.5 * (M + M.T)


@st.composite
def systems(draw, kinds=KINDS, singular_mass: bool = False, max_n: int = 7):
    """Hypothesis strategy: (M, A, rank, rng) for a random mechanism-like system."""
    kind = draw(st.sampled_from(kinds))
    n = draw(st.integers(1 if kind != "deficient" else 2, max_n))
    m = draw(st.integers(0, 9))
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    A, r = random_A(rng, kind, n, m)
    if singular_mass and r >= 1:
        M = singular_mass_pd_on_nullspace(rng, A, r)
    else:
        M = random_spd(rng, n) * 10.0 ** rng.uniform(-3, 3)
    return M, A, r, rng


# --------------------------------------------------------------------------- reference solvers


def kkt_solve(M, A, g, gamma):
    """KKT system ``[[M, −Aᵀ], [A, 0]] [qdd; λ] = [g; −γ]``; A full row rank. Returns qdd, λ."""
    n, m = M.shape[0], A.shape[0]
    K = np.block([[M, -A.T], [A, np.zeros((m, m))]])
    sol = np.linalg.solve(K, np.concatenate([g, -gamma]))
    return sol[:n], sol[n:]


def inv_sqrt_spd(M):
    w, V = np.linalg.eigh(M)
    return (V / np.sqrt(w)) @ V.T


def udwadia_kalaba(M, A, g, gamma, rcond=1e-10):
    """Udwadia–Kalaba: ``qdd = a + M^{-1/2}(A M^{-1/2})⁺(b − A a)``, a = M⁻¹g, b = −γ."""
    a = np.linalg.solve(M, g)
    if A.shape[0] == 0:
        return a
    Mih = inv_sqrt_spd(M)
    pinv = np.linalg.pinv(A @ Mih, rtol=rcond)
    return a + Mih @ (pinv @ (-gamma - A @ a))


def classical_impact(M, A, v, rcond=1e-10):
    """Classical mass-orthogonal projection ``(I − M⁻¹Aᵀ(AM⁻¹Aᵀ)⁺A) v`` (M SPD)."""
    if A.shape[0] == 0:
        return v.copy()
    Minv = np.linalg.inv(M)
    G = A @ Minv @ A.T
    Gp = np.linalg.pinv(0.5 * (G + G.T), rtol=rcond, hermitian=True)
    return v - Minv @ A.T @ (Gp @ (A @ v))


def rel(a, b, scale=None):
    """Relative difference ‖a − b‖ / max(‖b‖, scale, tiny)."""
    s = np.linalg.norm(b) if scale is None else max(np.linalg.norm(b), scale)
    return float(np.linalg.norm(np.asarray(a) - np.asarray(b)) / max(s, 1e-300))
