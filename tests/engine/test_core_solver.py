"""The engine's core Solver (engine/src/core_solver.cpp) against the NumPy specification.

``nonmin._engine.core_solve_one`` / ``core_solve_batch`` / ``core_min_norm`` are the Solver's
bindings; the reference is ``nonmin.core.dynamics._solve_dynamics_numpy`` and
``nonmin.core.range_basis`` (NumPy's LAPACK SVD). Generators of tests/core (core_testlib):
regular, redundant (duplicated and scaled rows), vanished rows, all-zero, rank-deficient
(singular), wide (m > n), m = 0, and more than 32 rows (the divide-and-conquer SVD path).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "core"))

from core_testlib import KINDS, random_A, random_spd

from nonmin import _engine as E
from nonmin.core import range_basis
from nonmin.core.dynamics import _solve_dynamics_numpy
from nonmin.core.linalg import DEFAULT_RTOL, SPD_RTOL

SYM = 1e-9
#: Engine vs NumPy: both backward stable, differences are round-off times cond(M̄) ≲ 1e3.
RTOL = 1e-12


def _case(seed, kind, n, m):
    rng = np.random.default_rng(seed)
    A, r = random_A(rng, kind, n, m)
    M = random_spd(rng, n) * 10.0 ** rng.uniform(-2, 2)
    h, f = rng.standard_normal(n), rng.standard_normal(n)
    gam = A @ rng.standard_normal(n) if A.shape[0] else np.zeros(0)
    return M, h, np.ascontiguousarray(A), gam, f, r


def _check(M, h, A, gam, f, mu=None, rtol=None, r=None):
    out = E.core_solve_one(M, h, A, gam, f, 0.0 if mu is None else mu,
                           DEFAULT_RTOL if rtol is None else rtol, SPD_RTOL, SYM, 2)  # fmt: skip
    ref = _solve_dynamics_numpy(M, h, A, gam, f, mu, rtol)
    assert out is not None
    q, fc, P, L, rank, mu_used = out
    assert rank == int(ref.rank)
    if r is not None:
        assert rank == r
    g = h if f is None else h + f
    # round-off grows with cond(M̄) (a μ far from the eigenvalues of PMP makes it large)
    tol = max(RTOL, 1e-15 * float(np.linalg.cond(ref.L @ ref.L.T)))
    # q̈ is formed from terms as large as (g + f_c)/λ_min(M) (P M w, μ w)
    big = max(float(np.max(np.abs(g))), float(np.max(np.abs(ref.f_c), initial=0.0)))
    ascale = big / float(np.linalg.eigvalsh(M)[0])
    qs = max(float(np.max(np.abs(ref.qdd))), ascale)
    assert np.max(np.abs(q - ref.qdd)) <= tol * qs
    fs = float(np.max(np.abs(M)) * qs + np.max(np.abs(g)))
    assert np.max(np.abs(fc - ref.f_c)) <= tol * fs
    assert np.max(np.abs(P - ref.P)) <= 1e-12
    assert np.max(np.abs(L - ref.L)) <= 1e-10 * np.max(np.abs(ref.L))
    assert mu_used == pytest.approx(float(ref.mu), rel=1e-12)
    # forward (q̈ only) and (q̈, rank) give bitwise the same q̈
    q0 = E.core_solve_one(M, h, A, gam, f, 0.0 if mu is None else mu,
                          DEFAULT_RTOL if rtol is None else rtol, SPD_RTOL, SYM, 0)  # fmt: skip
    assert np.array_equal(q0, q)
    return out


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("seed", range(8))
def test_solver_matches_numpy_on_every_kind(kind, seed):
    M, h, A, gam, f, r = _case(seed, kind, 2 + seed, 1 + (3 * seed) % 9)
    _check(M, h, A, gam, f, r=r)
    _check(M, h, A, gam, None, r=r)
    _check(M, h, A, gam, f, mu=0.37)
    _check(M, h, A, gam, f, rtol=1e-6)


def test_vanished_rows_and_row_scaling():
    """A row of relative norm ≤ rtol has vanished (rule 1); rows scaled by 1e±4 change nothing."""
    rng = np.random.default_rng(5)
    M, h, f = random_spd(rng, 6), rng.standard_normal(6), rng.standard_normal(6)
    A = rng.standard_normal((3, 6))
    A[1] *= 1e-11  # vanished
    out = _check(M, h, A, A @ rng.standard_normal(6), f)
    assert out[4] == 2
    A2 = rng.standard_normal((4, 6)) * np.array([[1e4], [1e-4], [1.0], [3e2]])
    _check(M, h, A2, A2 @ rng.standard_normal(6), f, r=4)


@pytest.mark.parametrize(("kind", "m", "n"), [("full", 40, 45), ("deficient", 40, 45),
                                              ("duplicated", 70, 45), ("zero_rows", 80, 50)])
def test_many_rows_take_the_divide_and_conquer_svd(kind, m, n):
    M, h, A, gam, f, r = _case(m + n, kind, n, m)
    assert A.shape[0] > 32
    _check(M, h, A, gam, f, r=r)


def test_min_norm_is_the_equilibrated_pseudo_inverse():
    for seed, kind in enumerate(KINDS * 3):
        rng = np.random.default_rng(seed)
        n = 3 + seed % 5
        A, r = random_A(rng, kind, n, 2 + seed % 7)
        A = np.ascontiguousarray(A)
        b = rng.standard_normal(A.shape[0])
        x = np.empty(n)
        rank = E.core_min_norm(A, b, DEFAULT_RTOL, x)
        basis = range_basis(A)
        assert rank == int(basis.rank) == r
        ref = basis.solve(b)
        assert np.max(np.abs(x - ref)) <= 1e-12 * max(1.0, float(np.max(np.abs(ref))))


def _status(x):
    return x if isinstance(x, int) else None


def test_irregular_states_return_their_status():
    """Non-finite input, asymmetric M, M̄ not positive definite, wrong sizes: the status code,
    no result (the Python layer re-runs NumPy for the typed error), never NaN; arrays that are
    not one state's: None."""
    I2, z2, a, z1 = np.eye(2), np.zeros(2), np.ones((1, 2)), np.zeros(1)
    args = dict(mu=0.0, rtol=DEFAULT_RTOL, spd_rtol=SPD_RTOL, sym_rtol=SYM, what=0)
    nan = np.array([[1.0, np.nan], [np.nan, 1.0]])
    assert _status(E.core_solve_one(nan, z2, a, z1, None, **args)) == 1
    assert _status(E.core_solve_one(I2, np.array([0.0, np.inf]), a, z1, None, **args)) == 1
    assert _status(E.core_solve_one(I2, z2, a, np.array([np.nan]), None, **args)) == 1
    assert _status(E.core_solve_one(I2, z2, a, z1, np.array([np.nan, 0.0]), **args)) == 1
    asym = np.array([[1.0, 0.5], [0.0, 1.0]])
    assert _status(E.core_solve_one(asym, z2, a, z1, None, **args)) == 3
    M = np.diag([1.0, 2.0, 0.0])
    assert _status(E.core_solve_one(M, np.zeros(3), np.array([[1.0, 1.0, 0.0]]), z1, None,
                                    **args)) == 2  # fmt: skip
    assert _status(E.core_solve_one(I2, np.zeros(3), a, z1, None, **args)) == 4
    assert _status(E.core_solve_one(I2, z2, np.ones((1, 3)), z1, None, **args)) == 4
    assert E.core_solve_one(I2[None], z2, a, z1, None, **args) is None


def _batch(n, m, N, seed=3):
    rng = np.random.default_rng(seed)
    kinds = ["full", "deficient", "duplicated", "zero_rows", "all_zero"]
    Ms, hs, As, gs, fs = [], [], [], [], []
    for i in range(N):
        A, _ = random_A(rng, kinds[i % len(kinds)], n, m)
        A = np.vstack([A, np.zeros((max(m - A.shape[0], 0), n))])[:m]
        Ms.append(random_spd(rng, n) * 10.0 ** rng.uniform(-2, 2))
        hs.append(rng.standard_normal(n))
        fs.append(rng.standard_normal(n))
        As.append(A)
        gs.append(A @ rng.standard_normal(n))
    return np.array(Ms), np.array(hs), np.array(As), np.array(gs), np.array(fs)


@pytest.mark.parametrize("nthreads", [1, 2, 3])
def test_batch_is_bitwise_the_single_calls(nthreads):
    n, m, N = 6, 4, 23
    M, h, A, g, f = _batch(n, m, N)
    qdd, fc = np.empty((N, n)), np.empty((N, n))
    P, L = np.empty((N, n, n)), np.empty((N, n, n))
    st, rk = np.empty(N, np.int64), np.empty(N, np.int64)
    mu, ra = np.empty(N), np.empty(N)
    E.core_solve_batch(M, h, f, A, g, None, n * n, n, n, m * n, m, 0, N, n, m, DEFAULT_RTOL,
                       SPD_RTOL, SYM, qdd, fc, P, L, st, rk, mu, ra, nthreads)  # fmt: skip
    assert not st.any()
    for i in range(N):
        q1, fc1, P1, L1, r1, mu1 = E.core_solve_one(M[i], h[i], A[i], g[i], f[i], 0.0,
                                                    DEFAULT_RTOL, SPD_RTOL, SYM, 2)  # fmt: skip
        assert np.array_equal(q1, qdd[i]) and np.array_equal(fc1, fc[i])
        assert np.array_equal(P1, P[i]) and np.array_equal(L1, L[i])
        assert r1 == rk[i] and mu1 == mu[i]
    # broadcast M (stride 0) and a μ per state
    mus = np.linspace(0.5, 2.0, N)
    E.core_solve_batch(M[0], h, None, A, g, mus, 0, n, 0, m * n, m, 1, N, n, m, DEFAULT_RTOL,
                       SPD_RTOL, SYM, qdd, fc, P, L, st, rk, mu, ra, nthreads)  # fmt: skip
    assert not st.any()
    for i in (0, 7, N - 1):
        q1 = E.core_solve_one(M[0], h[i], A[i], g[i], None, mus[i], DEFAULT_RTOL, SPD_RTOL,
                              SYM, 0)  # fmt: skip
        assert np.array_equal(q1, qdd[i]) and mu[i] == mus[i]
