"""The compiled backend on large sparse constraint matrices (more than 32 rows).

There the certified LQ takes the rows in the order of their first nonzero column and pivots
on the first free column of each row (so a chain of bodies keeps its reflectors and L within
the bodies a constraint couples, whatever the coordinate order), certifies full rank by a
Cholesky factorization of ``L Lᵀ − τ I`` over L's row profile (:data:`LQ_PROFILE`), and a
state it does not certify takes LAPACK's SVD instead of the Jacobi sweeps. The states come
from the A02 N four-bar (a chain of 2N + 1 bars, 6N + 3 coordinates, 6N + 2 pin rows, one
degree of freedom, singular when horizontal) in the parallelogram mode at chosen crank angles,
in the builder's coordinate order (cranks, then couplers: a row profile of ~3N columns) and
with coordinates and rows shuffled. Each result is checked against the NumPy backend.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

pytest.importorskip("numba")

from nonmin.core import solve_dynamics, use_backend
from nonmin.core._fast_kernels import (
    KNOWN_M_DIAGONAL,
    KNOWN_M_VALID,
    KNOWN_PATTERN,
    NO_FACTOR,
    NONFINITE,
    OK,
    scratch,
    solve_again,
    solve_near,
    solve_work,
)
from nonmin.errors import InputError
from nonmin.library import a02_n_four_bar

BACKEND_RTOL = 1e-11


def _parallelogram_state(N: int, theta: float, omega: float = -1.0):
    """q, qd of the N four-bar with every crank at angle θ (builder order: cranks, couplers)."""
    c, s = math.cos(theta), math.sin(theta)
    q, qd = [], []
    for i in range(N + 1):
        q += [i + 0.5 * c, 0.5 * s, theta]
        qd += [-0.5 * s * omega, 0.5 * c * omega, omega]
    for i in range(1, N + 1):
        q += [i - 0.5 + c, s, 0.0]
        qd += [-s * omega, c * omega, 0.0]
    return np.array(q), np.array(qd)


def _terms(N: int, theta: float):
    mech = a02_n_four_bar(N=N)
    model = mech.model
    q, qd = _parallelogram_state(N, theta)
    ct = model.constraint_terms(0.0, q, qd, mech.state.active)
    assert np.max(np.abs(ct.phi)) < 1e-12 and np.max(np.abs(ct.A @ qd)) < 1e-12
    M = model.mass_matrix(q)
    h = model.conservative_force(q) - model.coriolis_force(q, qd)  # h = f_g − C qd
    return np.ascontiguousarray(M), np.asarray(h, dtype=float), np.ascontiguousarray(ct.A), ct.gamma


def _mode(M, h, A, gam, rtol):
    """What the compiled kernel did: the LQ mode it recorded (0: SVD) and the rank."""

    n, m = M.shape[0], A.shape[0]
    work = scratch(n, m)
    out = np.empty(2 * n + 3)
    none = np.empty((0, 0))
    st = solve_work(M, h, h, False, A, gam, 1.0, False, rtol, 1e-13, 1e-12, False, out, none, none,
                    work, np.eye(m), False)  # fmt: skip
    assert st == OK
    return int(work[21][5]), int(out[2 * n])


def _agree(M, h, A, gam, rtol):
    with use_backend("numpy"):
        ref = solve_dynamics(M, h, A, gam, rtol=rtol)
    with use_backend("numba"):
        got = solve_dynamics(M, h, A, gam, rtol=rtol)
    assert int(got.rank) == int(ref.rank)
    scale = float(np.max(np.abs(ref.qdd))) + float(np.max(np.abs(h))) / float(np.min(np.diag(M)))
    assert np.max(np.abs(got.qdd - ref.qdd)) <= BACKEND_RTOL * scale
    fscale = float(np.max(np.abs(M)) * np.max(np.abs(ref.qdd)) + np.max(np.abs(h)))
    assert np.max(np.abs(got.f_c - ref.f_c)) <= BACKEND_RTOL * fscale
    assert np.max(np.abs(got.P - ref.P)) <= 1e-11
    assert float(got.mu) == pytest.approx(float(ref.mu), rel=1e-11)
    return int(got.rank)


@pytest.mark.parametrize("N", [12, 40])
@pytest.mark.parametrize(
    ("theta", "rtol", "mode", "deficit"),
    [
        (1.3, 1e-10, 2, 0),  # generic: certified over the profile
        (1.3, 1e-2, 2, 0),  # the projection's cutoff, still certified (σ_min/σ_max ≈ 0.016)
        (0.1, 1e-2, 0, None),  # cutoff with singular values below it: LAPACK SVD, truncated
        (3e-3, 1e-10, 2, 0),  # 3e-3 rad from horizontal: still certified at the default cutoff
        (0.0, 1e-10, 0, "N"),  # horizontal: N redundant rows (rank 5N + 2), LAPACK SVD
    ],
)
def test_large_chain_agrees_with_numpy(N, theta, rtol, mode, deficit):
    M, h, A, gam = _terms(N, theta)
    got_mode, rank = _mode(M, h, A, gam, rtol)
    assert got_mode == mode
    m = A.shape[0]
    if deficit == "N":
        assert rank == m - N
    elif deficit == 0:
        assert rank == m
    else:
        assert rank < m
    assert _agree(M, h, A, gam, rtol) == rank


@pytest.mark.parametrize("seed", range(3))
def test_large_chain_in_any_coordinate_order(seed):
    """Shuffled coordinates and rows (the row profile of the given order is then ~n wide): the
    same solution, still certified over a narrow profile."""
    rng = np.random.default_rng(seed)
    M, h, A, gam = _terms(40, 1.1)
    pc = rng.permutation(M.shape[0])
    pr = rng.permutation(A.shape[0])
    Mp, hp = np.ascontiguousarray(M[np.ix_(pc, pc)]), h[pc]
    Ap, gp = np.ascontiguousarray(A[np.ix_(pr, pc)]), gam[pr]
    assert _mode(Mp, hp, Ap, gp, 1e-2) == (2, A.shape[0])
    _agree(Mp, hp, Ap, gp, 1e-2)
    with use_backend("numba"):
        a = solve_dynamics(M, h, A, gam)
        b = solve_dynamics(Mp, hp, Ap, gp)
    assert np.max(np.abs(b.qdd - a.qdd[pc])) <= 1e-11 * np.max(np.abs(a.qdd))


def test_large_redundant_rows_take_the_svd():
    """A repeated row makes every row live but A rank deficient: no certificate, LAPACK SVD."""
    M, h, A, gam = _terms(12, 0.9)
    A2 = np.ascontiguousarray(np.vstack([A, -2.0 * A[5:6]]))
    g2 = np.concatenate([gam, -2.0 * gam[5:6]])
    mode, rank = _mode(M, h, A2, g2, 1e-10)
    assert mode == 0 and rank == A.shape[0]
    _agree(M, h, A2, g2, 1e-10)


@pytest.mark.parametrize(("theta", "rtol"), [(1.2, 1e-10), (0.3, 1e-2)])
def test_large_solve_again_and_near(theta, rtol):
    """``solve_again`` on the profile-certified LQ and on the LAPACK SVD, and ``solve_near`` on
    the former, equal a fresh factorization."""

    M, h, A, gam = _terms(40, theta)
    n, m = M.shape[0], A.shape[0]
    rng = np.random.default_rng(3)
    none = np.empty((0, 0))
    args = (1.0, False, rtol, 1e-13, 1e-12, False)
    work = scratch(n, m)
    assert solve_work(M, h, h, False, A, gam, *args, np.empty(2 * n + 3), none, none, work,
                      np.eye(m), False) == OK  # fmt: skip
    lq = int(work[21][5])
    h1, g1 = rng.standard_normal(n), A @ rng.standard_normal(n)
    again = np.empty(2 * n + 3)
    assert solve_again(M, h1, h1, False, g1, False, again, none, none, work) == OK
    ref = np.empty(2 * n + 3)
    assert solve_work(M, h1, h1, False, A, g1, *args, ref, none, none, scratch(n, m), np.eye(m),
                      False) == OK  # fmt: skip
    scale = float(np.max(np.abs(ref[:n])))
    assert np.max(np.abs(again[:n] - ref[:n])) <= 1e-11 * scale
    assert again[2 * n] == ref[2 * n]
    A2 = A + 1e-9 * rng.standard_normal(A.shape)
    near = np.empty(2 * n + 3)
    st = solve_near(M, h1, h1, False, A2, g1, 1e-13, near, work, False)
    if lq == 0:  # an SVD factorization: solve_near declines
        assert st == NO_FACTOR
        return
    assert st == OK
    fresh = np.empty(2 * n + 3)
    assert solve_work(M, h1, h1, False, A2, g1, *args, fresh, none, none, scratch(n, m), np.eye(m),
                      False) == OK  # fmt: skip
    assert np.max(np.abs(near[:n] - fresh[:n])) <= 1e-11 * float(np.max(np.abs(fresh[:n])))


def test_large_scratch_reused_across_changing_patterns():
    """One scratch, states whose A has different sparsity patterns (B = D A is written on A's
    pattern only and cleared on the last one): every call agrees with a fresh scratch and with
    NumPy, including after an uncertified (SVD) state and a state with an exact zero that
    another state's pattern has (sin 0 at the horizontal)."""

    N = 12
    states = [_terms(N, th) for th in (1.3, 0.0, 0.7, 0.1, 1.3)]
    rng = np.random.default_rng(5)
    M0, h0, A0, g0 = states[0]
    dense = A0.copy()  # a different pattern: extra nonzeros in every row
    dense[A0 == 0.0] = 1e-3 * rng.standard_normal(int(np.sum(A0 == 0.0))) * (
        rng.uniform(size=int(np.sum(A0 == 0.0))) < 0.05)  # fmt: skip
    states.insert(2, (M0, h0, dense, g0))
    n, m = M0.shape[0], A0.shape[0]
    assert m > 32  # the sparse path
    work = scratch(n, m)
    none = np.empty((0, 0))
    for M, h, A, g in states:
        got = np.empty(2 * n + 3)
        fresh = np.empty(2 * n + 3)
        for wk, out in ((work, got), (scratch(n, m), fresh)):
            st = solve_work(M, h, h, False, A, g, 1.0, False, 1e-10, 1e-13, 1e-12, False, out,
                            none, none, wk, np.eye(m), False)  # fmt: skip
            assert st == OK
        assert np.array_equal(got, fresh)
        _agree(M, h, A, g, 1e-10)


def test_large_nonfinite_and_huge_entries():
    """The sparse path learns A's finiteness from its row norms: a NaN or an infinity is
    reported (NumPy path: a typed error), a finite entry whose square overflows is not (the
    dense check decides; both backends then agree)."""

    M, h, A, g = _terms(12, 1.3)
    n, m = M.shape[0], A.shape[0]
    none = np.empty((0, 0))
    for bad in (np.nan, np.inf):
        Ab = A.copy()
        Ab[m // 2, np.flatnonzero(Ab[m // 2])[0]] = bad
        out = np.empty(2 * n + 3)
        st = solve_work(M, h, h, False, Ab, g, 1.0, False, 1e-10, 1e-13, 1e-12, False, out,
                        none, none, scratch(n, m), np.eye(m), False)  # fmt: skip
        assert st == NONFINITE
        with use_backend("numba"), pytest.raises(InputError, match="A"):
            solve_dynamics(M, h, Ab, g)
    Ah = A.copy()
    Ah[3] *= 1e160  # its squares overflow; the row is still finite
    out = np.empty(2 * n + 3)
    st = solve_work(M, h, h, False, Ah, g, 1.0, False, 1e-10, 1e-13, 1e-12, False, out,
                    none, none, scratch(n, m), np.eye(m), False)  # fmt: skip
    assert st == OK  # not NONFINITE; the NumPy path decides the same
    _agree(M, h, Ah, g, 1e-10)
    # the overflowing row's norm is computed scaled, so that row is kept (its infinite norm
    # made every row look negligible, itself included: rank 0, every constraint dropped); the
    # rows 1e160 times smaller are below rtol · max norm: vanished by the equilibration rule
    for backend in ("numpy", "numba"):
        with use_backend(backend):
            sol = solve_dynamics(M, h, Ah, g)
        assert sol.rank == 1
        assert abs(Ah[3] @ sol.qdd + g[3]) <= 1e-9 * np.linalg.norm(Ah[3]) * (1 + np.abs(sol.qdd).max())


# The two ``known`` tests call the kernels with that argument from Python, a specialization the
# default suite would compile only for them (43 s on a fresh clone, measured 2026-11-22): they run
# with the slow validation runs. The default suite exercises ``known`` through every compiled
# simulation (the loop passes it), whose results tests/sim compares with the general driver.
@pytest.mark.slow
@pytest.mark.parametrize("theta", [1.3, 0.3, 0.0])
def test_known_inputs_give_bitwise_the_checked_results(theta):
    """``known`` (a caller that validated a constant M and holds a superset of A's row pattern,
    like the simulation loop) skips checks and scans only: solve_work, solve_near and
    solve_again give bitwise the results of ``known = 0``, also when the given pattern has
    columns that are zero in A (the superset) and at a singular state (θ = 0: LAPACK's SVD)."""

    M, h, A, gam = _terms(12, theta)
    n, m = M.shape[0], A.shape[0]
    assert m > 32 and np.count_nonzero(M - np.diag(np.diag(M))) == 0
    rng = np.random.default_rng(7)
    superset = (A != 0.0) | (rng.uniform(size=A.shape) < 0.02)  # extra (zero) columns
    A2 = A + 1e-9 * rng.standard_normal(A.shape) * (A != 0.0)
    h1, g1 = rng.standard_normal(n), A @ rng.standard_normal(n)
    none = np.empty((0, 0))
    results = []
    for known in (0, KNOWN_M_VALID | KNOWN_M_DIAGONAL | KNOWN_PATTERN):
        work = scratch(n, m)
        if known:
            P = work[30]
            for i in range(m):
                cols = np.flatnonzero(superset[i])
                P[i, 0] = cols.size
                P[i, 1 : 1 + cols.size] = cols
        outs = [np.empty(2 * n + 3) for _ in range(3)]
        st = solve_work(M, h, h, False, A, gam, 1.0, False, 1e-10, 1e-13, 1e-12, False, outs[0],
                        none, none, work, np.eye(m), False, False, known)  # fmt: skip
        assert st == OK
        assert solve_again(M, h1, h1, False, g1, False, outs[1], none, none, work) == OK
        st_near = solve_near(M, h1, h1, False, A2, g1, 1e-13, outs[2], work, False, known)
        results.append((outs, st_near, int(work[21][5])))
    (ref, st_ref, lq_ref), (got, st_got, lq_got) = results
    assert lq_ref == lq_got and st_ref == st_got
    assert (lq_ref == 0) == (theta == 0.0)  # the horizontal state is not certified
    for a, b in zip(ref if st_ref == OK else ref[:2], got):  # (a declined solve_near: no result)
        assert np.array_equal(a, b)


@pytest.mark.slow
def test_known_diagonal_flag_is_what_the_kernel_uses():
    """With KNOWN_M_VALID and without KNOWN_M_DIAGONAL a diagonal M is treated as full (same
    solution to round-off); the flags only skip work, they never change the checks' outcome
    for valid inputs."""

    M, h, A, gam = _terms(12, 1.1)
    n, m = M.shape[0], A.shape[0]
    none = np.empty((0, 0))
    outs = []
    for known in (0, KNOWN_M_VALID):
        out = np.empty(2 * n + 3)
        st = solve_work(M, h, h, False, A, gam, 1.0, False, 1e-10, 1e-13, 1e-12, False, out,
                        none, none, scratch(n, m), np.eye(m), False, False, known)  # fmt: skip
        assert st == OK
        outs.append(out)
    assert np.allclose(outs[0], outs[1], rtol=1e-12, atol=1e-12 * float(np.max(np.abs(outs[0]))))
