"""The C++ engine on large sparse constraint matrices (more than 32 rows) and on the certified
LQ's decisions (engine/src/core_lq.cpp).

The states of tests/core/test_fast_large.py (the A02 N four-bar in the parallelogram mode:
6N + 3 coordinates, 6N + 2 pin rows, one degree of freedom, singular when horizontal), in the
builder's order and shuffled, at the default cutoff and at the projection's 1e-2: the engine
certifies full rank over L's row profile where the numba kernel did, takes the SVD where that
fails, and agrees with the NumPy backend. Small systems: the certified LQ with the dense L⁻¹
decides regular states (also with vanished rows, which it drops), the SVD the others.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from core_testlib import random_A, random_spd

from nonmin import _engine as E
from nonmin.core import solve_dynamics, use_backend
from nonmin.library import a02_n_four_bar

SVD, LQ_INVERSE, LQ_PROFILE = 0, 1, 2
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


def _agree(M, h, A, gam, rtol, backend="engine"):
    """The engine's solve_dynamics against the NumPy backend; returns the rank."""
    with use_backend("numpy"):
        ref = solve_dynamics(M, h, A, gam, rtol=rtol)
    with use_backend(backend):
        got = solve_dynamics(M, h, A, gam, rtol=rtol)
    assert int(got.rank) == int(ref.rank)
    scale = float(np.max(np.abs(ref.qdd))) + float(np.max(np.abs(h))) / float(np.min(np.diag(M)))
    assert np.max(np.abs(got.qdd - ref.qdd)) <= BACKEND_RTOL * scale
    fscale = float(np.max(np.abs(M)) * np.max(np.abs(ref.qdd)) + np.max(np.abs(h)))
    assert np.max(np.abs(got.f_c - ref.f_c)) <= BACKEND_RTOL * fscale
    assert np.max(np.abs(got.P - ref.P)) <= 1e-11
    assert float(got.mu) == pytest.approx(float(ref.mu), rel=1e-11)
    return int(got.rank)


def _info(M, h, A, gam, rtol):
    return E.core_solve_info(M, h, A, gam, rtol)


@pytest.mark.parametrize("N", [12, 40])
@pytest.mark.parametrize(
    ("theta", "rtol", "method", "deficit"),
    [
        (1.3, 1e-10, LQ_PROFILE, 0),
        (1.3, 1e-2, LQ_PROFILE, 0),
        (0.1, 1e-2, SVD, None),
        (3e-3, 1e-10, LQ_PROFILE, 0),
        (0.0, 1e-10, LQ_PROFILE, "N"),  # horizontal: N rows redundant, skipped
    ],
)
def test_large_chain_agrees_with_numpy(N, theta, rtol, method, deficit):
    M, h, A, gam = _terms(N, theta)
    info = _info(M, h, A, gam, rtol)
    assert info["status"] == 0 and info["method"] == method
    assert info["null_space_form"]  # one degree of freedom
    m = A.shape[0]
    rank = info["rank"]
    if deficit == "N":
        assert rank == m - N
    elif deficit == 0:
        assert rank == m
    else:
        assert rank < m
    assert _agree(M, h, A, gam, rtol) == rank


@pytest.mark.parametrize("seed", range(3))
def test_large_chain_in_any_coordinate_order(seed):
    rng = np.random.default_rng(seed)
    M, h, A, gam = _terms(40, 1.1)
    pc = rng.permutation(M.shape[0])
    pr = rng.permutation(A.shape[0])
    Mp, hp = np.ascontiguousarray(M[np.ix_(pc, pc)]), h[pc]
    Ap, gp = np.ascontiguousarray(A[np.ix_(pr, pc)]), gam[pr]
    info = _info(Mp, hp, Ap, gp, 1e-2)
    assert info["method"] == LQ_PROFILE and info["rank"] == A.shape[0]
    _agree(Mp, hp, Ap, gp, 1e-2)
    with use_backend("engine"):
        a = solve_dynamics(M, h, A, gam)
        b = solve_dynamics(Mp, hp, Ap, gp)
    assert np.max(np.abs(b.qdd - a.qdd[pc])) <= 1e-11 * np.max(np.abs(a.qdd))


def test_large_random_sparse_range_form():
    """Many rows and many degrees of freedom (n − m > m): the range form after the profile
    certificate; and a redundant copy of a row: skipped, still certified (rank m)."""
    rng = np.random.default_rng(4)
    n, m = 120, 40
    A = rng.standard_normal((m, n)) * (rng.uniform(size=(m, n)) < 0.05)
    A[np.arange(m), 2 * np.arange(m)] += 1.0
    M = np.diag(rng.uniform(1.0, 2.0, n))
    h, gam = rng.standard_normal(n), rng.standard_normal(m)
    info = _info(M, h, A, gam, 1e-10)
    assert info["method"] == LQ_PROFILE and not info["null_space_form"]
    _agree(M, h, A, gam, 1e-10)
    A2 = np.vstack([A, 2.0 * A[3]])
    g2 = np.append(gam, 2.0 * gam[3])
    info = _info(M, h, A2, g2, 1e-10)
    assert info["method"] == LQ_PROFILE and info["rank"] == m
    _agree(M, h, A2, g2, 1e-10)


@pytest.mark.parametrize("seed", range(6))
def test_small_systems_certified_or_svd(seed):
    rng = np.random.default_rng(seed)
    n = 4 + seed
    M = random_spd(rng, n)
    h = rng.standard_normal(n)
    A, _ = random_A(rng, "full", n, n - 1)
    info = _info(M, h, A, A @ h, 1e-10)
    assert info["method"] == LQ_INVERSE and info["rank"] == A.shape[0]
    assert info["null_space_form"] == (n - A.shape[0] <= A.shape[0])
    Az = np.vstack([A[:2], np.zeros((1, n)), A[2:]])  # a vanished row: dropped, still certified
    info = _info(M, h, Az, Az @ h, 1e-10)
    assert info["method"] == LQ_INVERSE and info["rank"] == A.shape[0]
    _agree(M, h, Az, Az @ h, 1e-10)
    noise = rng.standard_normal(n)
    Ad = np.vstack([A, A[0] + 1e-11 * np.linalg.norm(A[0]) / np.linalg.norm(noise) * noise])
    info = _info(M, h, Ad, Ad @ h, 1e-10)  # nearly redundant (above round-off): the SVD
    assert info["method"] == SVD and info["rank"] == A.shape[0]
    Ar = np.vstack([A, -2.0 * A[0]])  # exactly redundant: skipped, certified
    info = _info(M, h, Ar, Ar @ h, 1e-10)
    assert info["method"] == LQ_INVERSE and info["rank"] == A.shape[0]
    _agree(M, h, Ar, Ar @ h, 1e-10)


def test_large_nonfinite_and_huge_entries():
    """A NaN or an infinity in a large A: the typed error (the engine reports it, NumPy raises);
    a finite row whose squares overflow keeps a finite norm (row_norm scaled, as NumPy's
    row_norms): that row is kept and the rows 1e160 times smaller vanish (rank 1)."""
    from nonmin.errors import InputError

    M, h, A, g = _terms(12, 1.3)
    m = A.shape[0]
    for bad in (np.nan, np.inf):
        Ab = A.copy()
        Ab[m // 2, np.flatnonzero(Ab[m // 2])[0]] = bad
        assert _info(M, h, Ab, g, 1e-10)["status"] == 1  # not_finite
        with use_backend("engine"), pytest.raises(InputError, match="A"):
            solve_dynamics(M, h, Ab, g)
    Ah = A.copy()
    Ah[3] *= 1e160
    assert _info(M, h, Ah, g, 1e-10)["rank"] == 1
    assert _agree(M, h, Ah, g, 1e-10) == 1
