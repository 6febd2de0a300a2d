"""The compiled backend (the C++ engine) against the NumPy reference.

* both backends agree to 1e-12 (relative) on random full-rank, rank-deficient, duplicated-row,
  zero-row, all-zero, wide (m > n) and empty constraint matrices, with and without f, μ, rtol;
* on the compiled backend, a single call and the same state inside a batch agree bitwise
  (serial and threaded batches);
* invalid input and M not positive definite on N(A) raise the same typed errors.
"""

from __future__ import annotations

import numpy as np
import pytest
from core_testlib import KINDS, random_A, random_spd

from nonmin.core import (
    constraint_force,
    forward_dynamics,
    get_backend,
    set_backend,
    solve_dynamics,
    use_backend,
)
from nonmin.errors import (
    InputError,
    NonFiniteError,
    NotPositiveDefiniteError,
    NotSymmetricError,
    ShapeError,
)

#: The compiled backends under test (each test that takes ``backend`` runs on each).
COMPILED = ("engine",)


@pytest.fixture(params=COMPILED)
def backend(request):
    return request.param


#: compiled vs NumPy: both are backward stable; differences are round-off times cond(M̄) ≲ 1e3.
BACKEND_RTOL = 1e-12


def _case(seed: int, kind: str, n: int, m: int):
    rng = np.random.default_rng(seed)
    A, r = random_A(rng, kind, n, m)
    M = random_spd(rng, n) * 10.0 ** rng.uniform(-2, 2)
    h = rng.standard_normal(n)
    f = rng.standard_normal(n)
    gam = rng.standard_normal(A.shape[0])
    if A.shape[0]:  # consistent bias: γ ∈ R(A) (duplicated rows get duplicated entries)
        gam = A @ rng.standard_normal(n)
    return M, h, A, gam, f, r


def _close(a, b, rtol=BACKEND_RTOL, floor=1e-300):
    """max|a − b| ≤ rtol · max(max|b|, floor) (floor: the size of the inputs' contribution)."""
    a = np.asarray(a)
    b = np.asarray(b)
    scale = max(float(np.max(np.abs(b), initial=0.0)), floor)
    return float(np.max(np.abs(a - b), initial=0.0)) <= rtol * scale


def _fc_scale(M, qdd, h, f=None):
    """Natural size of f_c = M qdd − h − f (its entries are differences of terms this big)."""
    g = np.abs(h) + (0.0 if f is None else np.abs(f))
    return float(np.max(np.abs(M)) * np.max(np.abs(qdd)) + np.max(g))


def _both(backend, fn, *args, **kw):
    with use_backend("numpy"):
        ref = fn(*args, **kw)
    with use_backend(backend):
        got = fn(*args, **kw)
    return got, ref


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("seed", range(6))
def test_backends_agree_single(kind, seed, backend):
    n = 2 + seed
    M, h, A, gam, f, r = _case(seed, kind, n, 1 + (3 * seed) % 7)
    got, ref = _both(backend, solve_dynamics, M, h, A, gam, f)
    ascale = float(np.max(np.abs(h)) + np.max(np.abs(f))) / float(np.linalg.eigvalsh(M)[0])
    fscale = _fc_scale(M, ref.qdd, h, f)
    assert int(got.rank) == int(ref.rank) == r
    assert got.qdd.shape == ref.qdd.shape == (n,)
    assert _close(got.qdd, ref.qdd, floor=ascale)
    assert _close(got.f_c, ref.f_c, floor=fscale)
    assert np.max(np.abs(got.P - ref.P)) <= 1e-12
    assert _close(got.L, ref.L, 1e-10)
    assert _close(got.mu, ref.mu)
    assert np.shape(got.mu) == np.shape(ref.mu) and np.shape(got.rank) == np.shape(ref.rank)
    q1, q0 = _both(backend, forward_dynamics, M, h, A, gam, f)
    assert _close(q1, q0, floor=ascale)
    c1, c0 = _both(backend, constraint_force, M, h, A, gam)
    assert _close(c1, c0, floor=_fc_scale(M, ref.qdd, h, f))


@pytest.mark.parametrize(("n", "m", "density"), [(15, 14, 0.2), (9, 8, 0.35), (12, 5, 0.3),
                                                (12, 6, 0.5)])
@pytest.mark.parametrize("seed", range(4))
def test_backends_agree_on_sparse_constraint_jacobians(n, m, density, seed, backend):
    """Sparse A (absolute coordinates: few nonzeros per row), where the certified LQ skips the
    exact zeros of its reflectors and of L: the NumPy path's solution, in the null-space form
    (n − m ≤ m) and the range form alike; zero diagonal entries included."""
    rng = np.random.default_rng(1000 * n + 10 * m + seed)
    A = np.zeros((m, n))
    while np.linalg.cond(A) > 1e3:  # full rank and well conditioned (the tolerance below is
        # round-off times cond; a random sparse A is often nearly rank deficient)
        A = rng.standard_normal((m, n)) * (rng.uniform(size=(m, n)) < density)
        A[:, 0] = 0.0  # an empty column: the first pivot comes from elsewhere
    M = np.diag(rng.uniform(0.5, 3.0, n)) if seed % 2 else random_spd(rng, n)
    h, f, gam = rng.standard_normal(n), rng.standard_normal(n), rng.standard_normal(m)
    got, ref = _both(backend, solve_dynamics, M, h, A, gam, f)
    ascale = float(np.max(np.abs(h)) + np.max(np.abs(f))) / float(np.linalg.eigvalsh(M)[0])
    assert int(got.rank) == int(ref.rank) == m
    assert _close(got.qdd, ref.qdd, floor=ascale)
    assert _close(got.f_c, ref.f_c, floor=_fc_scale(M, ref.qdd, h, f))
    assert np.max(np.abs(got.P - ref.P)) <= 1e-12


@pytest.mark.parametrize("kind", ["full", "duplicated", "deficient", "empty"])
def test_backends_agree_options(kind, backend):
    M, h, A, gam, f, _ = _case(11, kind, 5, 4)
    for kw in ({"mu": 0.37}, {"rtol": 1e-6}, {"mu": 250.0, "rtol": 1e-12}):
        got, ref = _both(backend, solve_dynamics, M, h, A, gam, f, **kw)
        assert _close(got.qdd, ref.qdd)
        assert _close(got.f_c, ref.f_c, floor=_fc_scale(M, ref.qdd, h, f))
        assert int(got.rank) == int(ref.rank)
        assert np.allclose(got.mu, ref.mu, rtol=1e-14)
    # lists instead of arrays, integer entries
    if A.shape[0]:
        got, ref = _both(backend, forward_dynamics, M.tolist(), list(h), A.tolist(), list(gam))
        assert _close(got, ref)
    got, ref = _both(backend, forward_dynamics, np.eye(3, dtype=int), [0, 0, -1], [[1, 0, 0]], [0])
    assert np.array_equal(got, ref)


def _batch(n: int, m: int, N: int, seed: int = 3):
    rng = np.random.default_rng(seed)
    kinds = ["full", "deficient", "duplicated", "zero_rows", "all_zero"]
    Ms, hs, As, gs, fs = [], [], [], [], []
    for i in range(N):
        kind = kinds[i % len(kinds)]
        A, _ = random_A(rng, kind, n, m)
        A = np.vstack([A, np.zeros((m - A.shape[0], n))])[:m] if A.shape[0] < m else A[:m]
        Ms.append(random_spd(rng, n) * 10.0 ** rng.uniform(-2, 2))
        hs.append(rng.standard_normal(n))
        fs.append(rng.standard_normal(n))
        As.append(A)
        gs.append(A @ rng.standard_normal(n))
    return np.array(Ms), np.array(hs), np.array(As), np.array(gs), np.array(fs)


@pytest.mark.parametrize("N", [1, 7, 40])
def test_single_equals_batch_bitwise(N, backend):
    M, h, A, g, f = _batch(6, 4, N)
    with use_backend(backend):
        sol = solve_dynamics(M, h, A, g, f)
        qdd = forward_dynamics(M, h, A, g, f)
        fc = constraint_force(M, h, A, g, f)
        assert np.array_equal(qdd, sol.qdd) and np.array_equal(fc, sol.f_c)
        for i in range(0, N, max(1, N // 13)):
            one = solve_dynamics(M[i], h[i], A[i], g[i], f[i])
            assert np.array_equal(one.qdd, sol.qdd[i])
            assert np.array_equal(one.f_c, sol.f_c[i])
            assert np.array_equal(one.P, sol.P[i]) and np.array_equal(one.L, sol.L[i])
            assert int(one.rank) == int(sol.rank[i]) and float(one.mu) == float(sol.mu[i])
            assert np.array_equal(forward_dynamics(M[i], h[i], A[i], g[i], f[i]), qdd[i])
    with use_backend("numpy"):
        ref = solve_dynamics(M, h, A, g, f)
    for i in range(N):
        assert _close(sol.qdd[i], ref.qdd[i])
        assert _close(sol.f_c[i], ref.f_c[i], floor=_fc_scale(M[i], ref.qdd[i], h[i], f[i]))
    assert np.array_equal(sol.rank, ref.rank)


def test_engine_threaded_batch_bitwise():
    """A batch large enough for the engine's threads (ENGINE_PARALLEL_MIN_BATCH) gives bitwise
    the single calls' results, whatever the thread count."""
    from nonmin.core import _fast

    M, h, A, g, f = _batch(5, 3, 60, seed=9)
    reps = -(-_fast.ENGINE_PARALLEL_MIN_BATCH // 60) + 1
    M, h, A, g, f = (np.concatenate([x] * reps) for x in (M, h, A, g, f))
    with use_backend("engine"):
        sol = solve_dynamics(M, h, A, g, f)
        assert _fast.engine_threads(M.shape[0]) >= 1
        for i in (0, 1, 59, 61, M.shape[0] // 2 + 3, M.shape[0] - 1):
            one = solve_dynamics(M[i], h[i], A[i], g[i], f[i])
            assert np.array_equal(one.qdd, sol.qdd[i]) and np.array_equal(one.f_c, sol.f_c[i])
            assert np.array_equal(one.P, sol.P[i]) and np.array_equal(one.L, sol.L[i])
            assert int(one.rank) == int(sol.rank[i]) and float(one.mu) == float(sol.mu[i])


def test_batch_shapes_and_broadcasting(backend):
    M, h, A, g, _ = _batch(5, 3, 12)
    M4, h4, A4, g4 = M.reshape(3, 4, 5, 5), h.reshape(3, 4, 5), A.reshape(3, 4, 3, 5), g.reshape(3, 4, 3)
    got, ref = _both(backend, solve_dynamics, M4, h4, A4, g4, mu=np.full((3, 4), 2.0))
    assert got.qdd.shape == (3, 4, 5) and got.P.shape == (3, 4, 5, 5) and got.rank.shape == (3, 4)
    assert _close(got.qdd, ref.qdd)
    assert _close(got.f_c, ref.f_c, floor=_fc_scale(M4, ref.qdd, h4))
    # one M shared by a batch of A (broadcast), and a batch of M with one A
    got, ref = _both(backend, forward_dynamics, M[0], h, A, g)
    assert got.shape == (12, 5) and _close(got, ref)
    got, ref = _both(backend, forward_dynamics, M, h[0], A[0], g[0])
    assert got.shape == (12, 5) and _close(got, ref)
    # non-contiguous input
    Mt = np.ascontiguousarray(M.transpose(0, 2, 1)).transpose(0, 2, 1)
    got, ref = _both(backend, forward_dynamics, Mt, h, A, g)
    assert _close(got, ref)


def _not_pd_case():
    # M has no inertia on coordinate 2 and no constraint fixes it.
    M = np.diag([1.0, 2.0, 0.0])
    A = np.array([[1.0, 1.0, 0.0]])
    return M, np.zeros(3), A, np.zeros(1)


def test_not_positive_definite_raised_identically(backend):
    M, h, A, g = _not_pd_case()
    msgs = []
    for name in ("numpy", backend):
        with use_backend(name):
            with pytest.raises(NotPositiveDefiniteError) as exc:
                forward_dynamics(M, h, A, g)
            msgs.append(str(exc.value))
            with pytest.raises(NotPositiveDefiniteError):
                solve_dynamics(np.stack([np.eye(3), M]), np.zeros((2, 3)), np.stack([A, A]), np.zeros((2, 1)))
    assert msgs[0] == msgs[1]
    # constraining the massless coordinate makes it regular again, on both backends
    A2 = np.array([[1.0, 1.0, 0.0], [0.0, 0.0, 3.0]])
    got, ref = _both(backend, forward_dynamics, M, np.array([1.0, -2.0, 5.0]), A2, np.zeros(2))
    assert np.max(np.abs(ref)) > 0.1 and _close(got, ref)


@pytest.mark.parametrize(
    ("args", "err"),
    [
        ((np.array([[1.0, np.nan], [np.nan, 1.0]]), np.zeros(2), np.ones((1, 2)), np.zeros(1)), NonFiniteError),
        ((np.eye(2), np.array([0.0, np.inf]), np.ones((1, 2)), np.zeros(1)), NonFiniteError),
        ((np.eye(2), np.zeros(2), np.array([[1.0, np.nan]]), np.zeros(1)), NonFiniteError),
        ((np.eye(2), np.zeros(2), np.ones((1, 2)), np.array([np.nan])), NonFiniteError),
        ((np.array([[1.0, 0.5], [0.0, 1.0]]), np.zeros(2), np.ones((1, 2)), np.zeros(1)), NotSymmetricError),
        ((np.eye(2), np.zeros(3), np.ones((1, 2)), np.zeros(1)), ShapeError),
        ((np.eye(2), np.zeros(2), np.ones((1, 3)), np.zeros(1)), ShapeError),
        ((np.eye(2), np.zeros(2), np.ones((1, 2)), np.zeros(2)), ShapeError),
        ((np.ones((2, 3)), np.zeros(2), np.ones((1, 2)), np.zeros(1)), ShapeError),
        ((np.eye(2), np.zeros(2), np.ones(2), np.zeros(1)), ShapeError),
        ((np.eye(2)[None].repeat(3, 0), np.zeros((2, 2)), np.ones((1, 2)), np.zeros(1)), ShapeError),
    ],
)
def test_invalid_inputs_same_errors(args, err, backend):
    msgs = []
    for name in ("numpy", backend):
        with use_backend(name), pytest.raises(err) as exc:
            forward_dynamics(*args)
        msgs.append(str(exc.value))
    assert msgs[0] == msgs[1]
    with use_backend(backend), pytest.raises(err):
        forward_dynamics(*args, f=np.zeros(args[0].shape[-1]))
    with use_backend(backend), pytest.raises(NonFiniteError):
        forward_dynamics(np.eye(2), np.zeros(2), np.ones((1, 2)), np.zeros(1), [0.0, np.nan])
    with use_backend(backend), pytest.raises(InputError):
        forward_dynamics(np.eye(2), np.zeros(2), np.ones((1, 2)), np.zeros(1), mu=-1.0)


def test_backend_selection():
    before = get_backend()
    assert before in ("numpy", "engine")
    old = set_backend("numpy")
    try:
        assert get_backend() == "numpy"
        for name in COMPILED:
            with use_backend(name):
                assert get_backend() == name
            assert get_backend() == "numpy"
        with use_backend("auto"):
            assert get_backend() == "engine"  # the default: the C++ engine
    finally:
        set_backend(old)
    assert get_backend() == before
    with pytest.raises(InputError, match="backend must be one of"):
        set_backend("cuda")
    with pytest.raises(InputError, match="backend must be one of"):  # gone with numba (issue 17)
        set_backend("numba")
