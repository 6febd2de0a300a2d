"""Model + kernel over a batch of states (``Model.forward_dynamics``, engine ``forward_batch``).

Reference: each state evaluated by the model's own Python ``evaluate`` and solved by the NumPy
kernel (``nonmin.core`` with the ``numpy`` backend) — an independent path through the same
formulas. Every model source with a compiled program: planar, spatial (quaternions), SymPy,
robots (Pinocchio tree with loop closures).
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

import nonmin
from nonmin import library
from nonmin.core import solve_dynamics, use_backend
from nonmin.errors import NonFiniteError, ShapeError

RTOL = 1e-9


def _mechanisms():
    out = [
        ("crossed_four_bar", library.get("crossed_four_bar")),
        ("A02_N2", library.get("A02_n_four_bar", N=2)),
        ("slider_crank", library.get("slider_crank")),
        ("spinning_top", library.get("spinning_top")),
        ("A04_bricard", library.get("A04_bricard")),
    ]
    robots = pytest.importorskip("nonmin.model.robots")
    try:
        m, s = robots.two_arm_grasp()
        out.append(("two_arm_grasp", SimpleNamespace(model=m, state=s)))
        m, s = robots.fourbar("point")
        out.append(("fourbar_point", SimpleNamespace(model=m, state=s)))
    except nonmin.errors.MissingDependencyError:
        pass
    return out


MECHS = _mechanisms()


def _states(mech, N, seed=0):
    rng = np.random.default_rng(seed)
    q0, qd0 = np.asarray(mech.state.q), np.asarray(mech.state.qd)
    Q = q0 + 0.05 * rng.standard_normal((N, q0.size))
    V = qd0 + rng.standard_normal((N, q0.size))
    return Q, V


def _reference(model, t, q, qd, active, f=None):
    terms = model.evaluate(t, q, qd, active)
    g = terms.h + terms.f_passive + (0.0 if f is None else f)
    with use_backend("numpy"):
        return solve_dynamics(terms.M, g, terms.constraints.A, terms.constraints.gamma)


@pytest.mark.parametrize("name,mech", MECHS, ids=[n for n, _ in MECHS])
def test_batch_matches_the_python_path(name, mech):
    model = mech.model
    assert model.engine_program() is not None, f"{name}: no compiled program"
    Q, V = _states(mech, 40)
    act = mech.state.active
    res = model.forward_dynamics(Q, V, t=0.3, active=act)
    assert res.qdd.shape == Q.shape and res.f_c.shape == Q.shape and res.rank.shape == (40,)
    for i in range(0, 40, 7):
        ref = _reference(model, 0.3, Q[i], V[i], act)
        scale = 1.0 + np.max(np.abs(ref.qdd))
        assert np.max(np.abs(res.qdd[i] - ref.qdd)) <= RTOL * scale, name
        fscale = 1.0 + np.max(np.abs(ref.f_c))
        assert np.max(np.abs(res.f_c[i] - ref.f_c)) <= RTOL * fscale, name
        assert res.rank[i] == ref.rank


@pytest.mark.parametrize("name,mech", MECHS[:2] + MECHS[-1:], ids=[n for n, _ in MECHS[:2] + MECHS[-1:]])
def test_single_batch_and_threads_are_bitwise_equal(name, mech):
    model = mech.model
    Q, V = _states(mech, 300, seed=1)
    one = model.forward_dynamics(Q, V, threads=1)
    two = model.forward_dynamics(Q, V, threads=2)
    assert np.array_equal(one.qdd, two.qdd) and np.array_equal(one.f_c, two.f_c)
    single = model.forward_dynamics(Q[17], V[17])
    assert single.qdd.shape == (model.n,) and single.rank.shape == ()
    assert np.array_equal(single.qdd, one.qdd[17])
    grid = model.forward_dynamics(Q.reshape(3, 100, -1), V.reshape(3, 100, -1), threads=2)
    assert np.array_equal(grid.qdd.reshape(300, -1), one.qdd)


def test_applied_force_and_time_broadcast():
    mech = MECHS[0][1]
    model = mech.model
    Q, V = _states(mech, 5)
    f = np.linspace(-1.0, 1.0, model.n)
    res = model.forward_dynamics(Q, V, t=np.linspace(0, 1, 5), f=f)
    for i in range(5):
        ref = _reference(model, float(np.linspace(0, 1, 5)[i]), Q[i], V[i], mech.state.active, f)
        assert np.allclose(res.qdd[i], ref.qdd, rtol=1e-9, atol=1e-9)


def test_bad_inputs_are_typed_and_name_the_state():
    mech = MECHS[0][1]
    model = mech.model
    Q, V = _states(mech, 6)
    with pytest.raises(ShapeError, match="q must have shape"):
        model.forward_dynamics(Q[:, :-1], V[:, :-1])
    with pytest.raises(ShapeError, match="qd must have the shape"):
        model.forward_dynamics(Q, V[:3])
    with pytest.raises(ShapeError, match="t must be"):
        model.forward_dynamics(Q, V, t=np.zeros(4))
    with pytest.raises(ShapeError, match="f must have shape"):
        model.forward_dynamics(Q, V, f=np.zeros(3))
    V[4, 0] = np.nan
    with pytest.raises(NonFiniteError, match="state 4"):
        model.forward_dynamics(Q, V)


def test_threaded_chunks_write_every_state():
    """Threads take chunks of states from a shared counter and the outputs are not zero-filled
    beforehand: every state's q̈, f_c, rank and status are written, a failed state's q̈ and f_c
    read 0, and the results are those of one thread bit for bit."""
    from nonmin import _engine
    from nonmin._validation import SYMMETRY_RTOL
    from nonmin.core.linalg import DEFAULT_RTOL, SPD_RTOL

    mech = MECHS[1][1]
    model = mech.model
    Q, V = _states(mech, 3001, seed=2)
    bad = [5, 1234, 2999]
    V[bad, 1] = np.nan
    t = np.zeros(len(Q))
    mask = model.active_mask(mech.state.active)

    def run(threads):
        return _engine.forward_batch(model.engine_program(), t, Q, V, mask, None, DEFAULT_RTOL, SPD_RTOL,
                                     SYMMETRY_RTOL, 0.0, threads, True)

    qdd1, fc1, rank1, status1, nbad1 = run(1)
    for _ in range(3):  # fresh (uninitialized) output buffers each call
        qdd2, fc2, rank2, status2, nbad2 = run(2)
        assert nbad1 == nbad2 == len(bad)
        assert np.flatnonzero(status2).tolist() == bad and np.array_equal(status1, status2)
        assert np.array_equal(qdd1, qdd2) and np.array_equal(fc1, fc2) and np.array_equal(rank1, rank2)
        assert not np.any(qdd2[bad]) and not np.any(fc2[bad])
        ok = np.setdiff1d(np.arange(len(Q)), bad)
        assert np.all(np.isfinite(qdd2[ok])) and np.all(rank2[ok] == rank2[0])


@pytest.mark.parametrize("name,kw", [("A02_n_four_bar", {"N": 40}), ("spinning_top", {}), ("slider_crank", {})])
def test_forward_batch_keeps_its_scratch_bitwise(name, kw):
    """``Forward.batch`` keeps one scratch per worker thread from call to call (its ~10 MB at
    A02 N = 40 are not made again): a second and third call, on other thread counts and other
    states, give bit for bit what single calls and a fresh ``Forward`` give."""
    from nonmin import _engine

    mech = library.get(name, **kw)
    model = mech.model
    prog, mask = model.engine_program(), model.active_mask(mech.state.active)
    Q, V = _states(mech, 150, seed=3)
    t = np.linspace(0.0, 0.2, len(Q))
    fwd = _engine.Forward(prog, mask)
    first = fwd.batch(t, Q, V, 2)
    again = fwd.batch(t[::-1].copy(), Q[::-1].copy(), V[::-1].copy(), 1)
    assert np.array_equal(again[::-1], first)
    more = fwd.batch(t[:61], Q[:61], V[:61], 2)
    assert np.array_equal(more, first[:61])
    fresh = _engine.Forward(prog, mask).batch(t, Q, V, 1)
    assert np.array_equal(fresh, first)
    qdd = np.empty(model.n)
    for i in (0, 77, 149):
        fwd(float(t[i]), Q[i], V[i], qdd)
        assert np.array_equal(qdd, first[i])


def test_forward_dynamics_keeps_scratch_across_models_bitwise():
    """``Model.forward_dynamics`` keeps the per-thread scratch of its last programs (engine
    ``forward_batch``): calls alternating between more models and active sets than it keeps
    give bit for bit the first call's results (each computed with a fresh scratch)."""
    cases = []
    for name, kw in (("A02_n_four_bar", {"N": 40}), ("A02_n_four_bar", {"N": 2}), ("slider_crank", {}),
                     ("crossed_four_bar", {})):  # fmt: skip
        mech = library.get(name, **kw)
        Q, V = _states(mech, 70, seed=4)
        cases.append((mech.model, Q, V, mech.state.active))
    first = [m.forward_dynamics(Q, V, active=act, threads=2) for m, Q, V, act in cases]
    for _ in range(2):
        for (m, Q, V, act), ref in zip(cases, first):
            for threads in (1, 2):
                res = m.forward_dynamics(Q, V, active=act, threads=threads)
                assert np.array_equal(res.qdd, ref.qdd) and np.array_equal(res.f_c, ref.f_c)
                assert np.array_equal(res.rank, ref.rank)
            one = m.forward_dynamics(Q[11], V[11], active=act)
            assert np.array_equal(one.qdd, ref.qdd[11])
