"""The rank-revealing certified LQ (``nonmin.core.linalg.certified_lq``, the specification of
``lq_certified`` / ``lq_sparse`` in engine/src/core_lq.cpp): rows redundant to round-off are
skipped and the certificate proves the SVD rule's rank; near-singular rows make it refuse.

References: ``numpy.linalg.svd`` (the rule σ ≤ rtol σ_max on the equilibrated rows),
``numpy.linalg.matrix_rank`` and ``numpy.linalg.pinv``; the engine's decision
(``_engine.core_solve_info``: method, rank) and its solve against the NumPy backend.
"""

from __future__ import annotations

import numpy as np
import pytest
from core_testlib import random_spd
from hypothesis import given, settings
from hypothesis import strategies as st

from nonmin import _engine as E
from nonmin.core import solve_dynamics, use_backend
from nonmin.core.linalg import certified_lq, redundant_row_tol

SVD, LQ_INVERSE, LQ_PROFILE = 0, 1, 2


def _unit(A: np.ndarray) -> np.ndarray:
    return A / np.linalg.norm(A, axis=1, keepdims=True)


def _svd_rank(B: np.ndarray, rtol: float) -> int:
    s = np.linalg.svd(B, compute_uv=False)
    return int(np.count_nonzero(s > rtol * s[0]))


def _redundant(rng: np.random.Generator, n: int, k: int, extra: int, kind: str) -> np.ndarray:
    """k independent random rows and `extra` rows exactly dependent on them, shuffled."""
    A0 = rng.standard_normal((k, n))
    rows = []
    for _ in range(extra):
        if kind == "duplicate":
            rows.append(A0[rng.integers(k)] * rng.choice([-3.0, 1.0, 0.5]))
        else:  # a combination of two or three rows
            idx = rng.choice(k, size=min(k, int(rng.integers(2, 4))), replace=False)
            rows.append(rng.uniform(-2, 2, idx.size) @ A0[idx])
    A = np.vstack([A0, *rows]) if rows else A0
    return A[rng.permutation(A.shape[0])]


def _check_certified(B: np.ndarray, rtol: float, lq) -> None:
    """What the certificate claims, against the SVD: the rank, R(Bᵀ), the min-norm solve."""
    assert lq.certified
    assert lq.rank == _svd_rank(B, rtol) == np.linalg.matrix_rank(B)
    _, s, Vh = np.linalg.svd(B)
    Vk = Vh[: lq.rank]
    tol = 1e-12 + 1e-14 / s[lq.rank - 1]  # (both subspaces to round-off / σ_r)
    assert np.max(np.abs(lq.Q.T @ lq.Q - Vk.T @ Vk)) < tol
    assert np.max(np.abs(lq.Q @ lq.Q.T - np.eye(lq.rank))) < 1e-13
    x_true = np.random.default_rng(0).standard_normal(B.shape[1])
    b = B @ x_true  # consistent
    err = np.max(np.abs(lq.solve(b) - np.linalg.pinv(B, rcond=rtol) @ b))
    assert err < 1e2 * tol * (1 + np.max(np.abs(x_true)))
    assert np.all(lq.residuals <= 1e-8)


@settings(max_examples=60, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    n=st.integers(2, 12),
    kind=st.sampled_from(["duplicate", "combination"]),
    certificate=st.sampled_from(["frobenius", "profile"]),
)
def test_redundant_rows_skipped_and_certified(seed, n, kind, certificate):
    rng = np.random.default_rng(seed)
    k = int(rng.integers(1, n + 1))
    extra = int(rng.integers(1, 5))
    B = _unit(_redundant(rng, n, k, extra, kind))
    lq = certified_lq(B, 1e-10, certificate=certificate)
    # a Gaussian k × n block is well conditioned except with tiny probability: certified
    if np.linalg.svd(B, compute_uv=False)[k - 1] > 1e-3:
        _check_certified(B, 1e-10, lq)
        assert lq.rank == k and lq.skipped.size == extra


@pytest.mark.parametrize("rtol", [1e-10, 1e-4, 1e-2])
def test_duplicated_scaled_and_combined_rows(rtol):
    rng = np.random.default_rng(3)
    A0 = rng.standard_normal((4, 7))
    A = np.vstack([A0, -2.0 * A0[1], A0[0] + 3.0 * A0[2], A0[3], A0[0] - A0[1] + A0[2] - A0[3]])
    B = _unit(A)
    for cert in ("frobenius", "profile"):
        lq = certified_lq(B, rtol, certificate=cert)
        _check_certified(B, rtol, lq)
        assert lq.rank == 4 and list(lq.skipped) == [4, 5, 6, 7]
    # more rows than columns: every row past the n-th kept one leaves no residual
    W = _unit(np.vstack([rng.standard_normal((3, 3)), rng.standard_normal((2, 3))]))
    lq = certified_lq(W, rtol)
    _check_certified(W, rtol, lq)
    assert lq.rank == 3 and np.all(lq.residuals <= redundant_row_tol(5, 3))


@pytest.mark.parametrize("eps", [1e-13, 1e-12, 1e-9, 1e-7])
@pytest.mark.parametrize("certificate", ["frobenius", "profile"])
def test_near_singular_rows_refuse(eps, certificate):
    """A row off the span of the others by eps (not exactly dependent: above round-off): kept,
    so the certificate refuses (σ_min below its floor) and the SVD decides; the Frobenius one
    (few rows, no floor) certifies full rank where σ_min ≫ 10 rtol σ_max, as the SVD rule."""
    rng = np.random.default_rng(7)
    A0 = rng.standard_normal((5, 8))
    d = rng.standard_normal(8)
    d -= np.linalg.lstsq(A0.T, d, rcond=None)[0] @ A0  # orthogonal to R(A0ᵀ)
    row = A0[0] + A0[3] + eps * d / np.linalg.norm(d)
    B = _unit(np.vstack([A0, row]))
    assert redundant_row_tol(6, 8) < eps / 2.0 / 3.0  # (‖row‖ ≲ 3: above the skip threshold)
    lq = certified_lq(B, 1e-10, certificate=certificate)
    assert lq.skipped.size == 0
    if eps >= 1e-7 and certificate == "frobenius":  # (no floor: σ_min ≈ 3e-8 ≫ 10 · rtol)
        _check_certified(B, 1e-10, lq)
    else:
        assert not lq.certified
    # and the SVD decides: 5 at rtol 1e-10 for eps ≤ 1e-12, 6 above
    assert _svd_rank(B, 1e-10) == (5 if eps <= 1e-12 else 6)


def test_inconsistent_bias_keeps_the_row_and_refuses():
    """A duplicated row whose bias differs (inconsistent: the least-squares solution is the
    SVD's): the row is not skipped, the certificate refuses; a consistent bias is skipped."""
    rng = np.random.default_rng(2)
    A0 = _unit(rng.standard_normal((3, 6)))
    B = np.vstack([A0, A0[1]])
    b = np.array([0.3, -1.0, 2.0, -1.0])
    assert certified_lq(B, 1e-10, b=b).certified
    b[3] = -0.5
    lq = certified_lq(B, 1e-10, b=b)
    assert not lq.certified and lq.skipped.size == 0
    W = _unit(rng.standard_normal((4, 3)))  # m > n: no residual, the bias decides
    assert certified_lq(W, 1e-10, b=W @ np.ones(3)).certified
    assert not certified_lq(W, 1e-10, b=W @ np.ones(3) + np.array([0, 0, 0, 1e-3])).certified


def test_skipped_rows_above_rtol_refuse():
    """A tiny rtol (below the skipped rows' residuals): the SVD rule would keep them, so the
    certificate refuses although the row was skipped."""
    rng = np.random.default_rng(11)
    A0 = rng.standard_normal((3, 5))
    B = _unit(np.vstack([A0, A0[0] + A0[1]]))
    lq = certified_lq(B, 1e-10)
    assert lq.certified and lq.rank == 3
    e_f = float(np.linalg.norm(lq.residuals))
    if e_f > 0.0:
        assert not certified_lq(B, 0.5 * e_f).certified


# ------------------------------------------------------------------ the engine's decision


def _info(M, h, A, g, rtol):
    return E.core_solve_info(np.ascontiguousarray(M), h, np.ascontiguousarray(A), g, rtol)


def _agree(M, h, A, g, rtol, tol=1e-10):
    with use_backend("numpy"):
        ref = solve_dynamics(M, h, A, g, rtol=rtol)
    with use_backend("engine"):
        got = solve_dynamics(M, h, A, g, rtol=rtol)
    assert int(got.rank) == int(ref.rank)
    scale = float(np.max(np.abs(ref.qdd))) + float(np.max(np.abs(h)))
    assert np.max(np.abs(got.qdd - ref.qdd)) <= tol * scale
    assert np.max(np.abs(got.P - ref.P)) <= tol


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), big=st.booleans(), kind=st.sampled_from(["duplicate", "combination"]))
def test_engine_certifies_redundant_rows_as_the_spec(seed, big, kind):
    """Few rows (dense L⁻¹, Frobenius) and many rows (sparse profile): the engine skips the
    redundant rows, certifies (method LQ) and solves as the NumPy backend's SVD."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(40, 60)) if big else int(rng.integers(3, 12))
    k = int(rng.integers(n // 2, n)) if big else int(rng.integers(1, n))
    extra = int(rng.integers(1, 6))
    if big:  # sparse rows (absolute coordinates): a diagonal plus a few entries
        A0 = rng.standard_normal((k, n)) * (rng.uniform(size=(k, n)) < 0.1)
        A0[np.arange(k), np.arange(k)] += 2.0
        A = _redundant_from(rng, A0, extra, kind)
    else:
        A = _redundant(rng, n, k, extra, kind)
    B = _unit(A)
    if np.linalg.svd(B, compute_uv=False)[k - 1] < 1e-3:
        return  # (a badly conditioned draw: nothing to certify)
    spec = certified_lq(B, 1e-10)
    assert spec.certified and spec.rank == k
    M = random_spd(rng, n)
    h = rng.standard_normal(n)
    g = A @ rng.standard_normal(n)  # a consistent bias
    info = _info(M, h, A, g, 1e-10)
    assert info["status"] == 0
    assert info["method"] == (LQ_PROFILE if A.shape[0] > 32 else LQ_INVERSE)
    assert info["rank"] == k
    _agree(M, h, A, g, 1e-10)


def _redundant_from(rng, A0, extra, kind):
    k = A0.shape[0]
    rows = []
    for _ in range(extra):
        if kind == "duplicate":
            rows.append(2.0 * A0[rng.integers(k)])
        else:
            idx = rng.choice(k, size=min(k, 2), replace=False)
            rows.append(rng.uniform(-2, 2, idx.size) @ A0[idx])
    A = np.vstack([A0, *rows])
    return A[rng.permutation(A.shape[0])]


@pytest.mark.parametrize("m_extra", [0, 40])
@pytest.mark.parametrize("eps", [1e-11, 1e-9, 1e-7])
def test_engine_refuses_near_singular(eps, m_extra):
    """Not exactly dependent: the engine takes the SVD (method 0), rank as the NumPy backend
    (few rows at eps = 1e-7: certified full rank, σ_min ≫ 10 rtol)."""
    rng = np.random.default_rng(5)
    n = 8 + m_extra + 4
    A0 = rng.standard_normal((7 + m_extra, n)) * (rng.uniform(size=(7 + m_extra, n)) < (0.3 if m_extra else 1.0))
    A0[np.arange(A0.shape[0]), np.arange(A0.shape[0])] += 1.0
    d = rng.standard_normal(n)
    d -= np.linalg.lstsq(A0.T, d, rcond=None)[0] @ A0
    A = np.vstack([A0, A0[0] + A0[3] + eps * d / np.linalg.norm(d)])
    M = random_spd(rng, n)
    h = rng.standard_normal(n)
    g = A @ rng.standard_normal(n)
    info = _info(M, h, A, g, 1e-10)
    if eps >= 1e-7 and not m_extra:  # few rows (Frobenius, no floor): full rank, as the SVD rule
        assert info["method"] == LQ_INVERSE
    else:
        assert info["method"] == SVD
    assert info["rank"] == _svd_rank(_unit(A), 1e-10)
    _agree(M, h, A, g, 1e-10, tol=max(1e-10, 1e-14 / eps))  # (round-off / σ_min where kept)


def test_bricard_certified_with_its_redundant_row():
    """A04 Bricard (35 coordinates, one permanently redundant row): the engine certifies rank
    m − 1 along the motion instead of falling back to the SVD."""
    from nonmin import library

    mech = library.get("A04_bricard")
    model = mech.model
    q, qd = np.asarray(mech.state.q, dtype=float), np.asarray(mech.state.qd, dtype=float)
    ct = model.constraint_terms(0.0, q, qd, mech.state.active)
    A = np.ascontiguousarray(ct.A)
    m = A.shape[0]
    M = np.ascontiguousarray(model.mass_matrix(q))
    h = np.asarray(model.conservative_force(q) - model.coriolis_force(q, qd), dtype=float)
    info = _info(M, h, A, ct.gamma, 1e-10)
    assert info["status"] == 0 and info["method"] == LQ_PROFILE and info["rank"] == m - 1
    _agree(M, h, A, ct.gamma, 1e-10)
    B = _unit(A)
    spec = certified_lq(B, 1e-10)
    assert spec.certified and spec.rank == m - 1 == _svd_rank(B, 1e-10)
