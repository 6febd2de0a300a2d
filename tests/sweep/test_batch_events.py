"""simulate_batch with automatic contact and compiled controllers inside the batched engine
loop (the event layer of engine/src/sim_events.cpp, the controllers of sim_control.cpp), and
with user events (made one by one by simulate): each run against simulate() of that run."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from nonmin import library
from nonmin.control import Regulator
from nonmin.sim import Event, Status, simulate, simulate_batch

T_EVAL = np.linspace(0.0, 0.6, 61)


@pytest.fixture(scope="module")
def arm() -> Any:
    return library.get("arm2r_wall")


def _rates(arm: Any, k: int, seed: int) -> np.ndarray:
    """k consistent initial velocities of the arm (link rates ω1 ∈ [1, 4], ω2 ∈ [−3, 1] rad/s:
    the tip moves towards the wall)."""
    rng = np.random.default_rng(seed)
    a1, a2 = arm.state.q[2], arm.state.q[5]
    e1, e2 = np.array([-np.sin(a1), np.cos(a1)]), np.array([-np.sin(a2), np.cos(a2)])
    V = np.zeros((k, arm.model.n))
    for i in range(k):
        w1, w2 = rng.uniform(1.0, 4.0), rng.uniform(-3.0, 1.0)
        V[i] = [*(0.5 * w1 * e1), w1, *(w1 * e1 + 0.5 * w2 * e2), w2]
    return V


def _same(bt: Any, i: int, ref: Any, tol: float) -> None:
    """Run i of the batch against simulate(): the samples on the grid, the events."""
    tr = bt[i]
    assert tr.status is Status.SUCCESS and ref.status is Status.SUCCESS
    assert [e.name for e in tr.events] == [e.name for e in ref.events]
    for ea, eb in zip(tr.events, ref.events, strict=True):
        assert abs(ea.t - eb.t) <= 1e-11, ea.name
        np.testing.assert_allclose(ea.qd_after, eb.qd_after, rtol=0, atol=tol)
        assert ea.active_after == eb.active_after
    # the reference's samples on the output grid (after an event: the sample after it)
    j = np.searchsorted(ref.t, T_EVAL, side="right") - 1
    assert np.all(ref.t[j] == T_EVAL)
    np.testing.assert_array_equal(tr.active_mask, ref.active_mask[j])
    for key in ("q", "qd", "energy", "work"):
        np.testing.assert_allclose(getattr(tr, key), getattr(ref, key)[j], rtol=0, atol=tol, err_msg=key)
    assert tr.n_steps == ref.n_steps


def test_contact_runs_go_through_the_engine_event_layer(arm: Any) -> None:
    k = 6
    V = _rates(arm, k, seed=3)
    bt = simulate_batch(arm, 0.6, arm.state.q, V, dt=1e-3, t_eval=T_EVAL, restitution=0.0, threads=2)
    assert bt.engine == ("batch",) * k
    assert bt.active_mask is not None and bt.active_mask.shape == (k, T_EVAL.size, 3)
    hits = 0
    for i in range(k):
        ref = simulate(arm, 0.6, arm.state.q, V[i], dt=1e-3, t_eval=T_EVAL, restitution=0.0, progress=False)
        assert ref.metadata["engine"] == "engine"
        _same(bt, i, ref, 1e-9)
        hits += any(e.name == "impact:wall" for e in ref.events)
    assert hits >= 3  # (the test covers impacts, and contact held or released)
    # one thread or two: the same numbers
    one = simulate_batch(arm, 0.6, arm.state.q, V, dt=1e-3, t_eval=T_EVAL, restitution=0.0, threads=1)
    np.testing.assert_array_equal(one.q, bt.q)
    assert [len(e) for e in one.events] == [len(e) for e in bt.events]


def test_regulated_runs_use_the_compiled_controller_bitwise() -> None:
    mech = library.get("five_bar")
    target = library.get("five_bar", end_effector=(0.2, 1.4)).state.q
    ctl = Regulator(mech.model, target=target, Kp=400.0, Kd=40.0, u_min=-3.0, u_max=3.0)
    rng = np.random.default_rng(5)
    k = 5
    V = np.tile(mech.state.qd, (k, 1)) + rng.normal(0.0, 0.5, (k, mech.model.n))
    t = np.linspace(0.0, 0.3, 31)
    bt = simulate_batch(mech, 0.3, mech.state.q, V, controller=ctl, dt=1e-3, t_eval=t, record=("q", "qd", "u"),
                        threads=2)  # fmt: skip
    assert bt.engine == ("batch",) * k
    for i in range(k):
        ref = simulate(mech, 0.3, mech.state.q, V[i], controller=ctl, dt=1e-3, t_eval=t, progress=False)
        assert ref.metadata["engine"] == "engine"
        for key in ("q", "qd", "u", "energy", "work"):
            np.testing.assert_array_equal(getattr(bt[i], key), getattr(ref, key), err_msg=key)
        # the controller's work is recorded by the batch too: the energy balance closes
        assert np.all(np.isfinite(bt.work[i])) and abs(bt.work[i, -1]) > 1e-3
        bal = bt.energy[i] - bt.energy[i, 0] - bt.work[i]
        assert float(np.max(np.abs(bal))) < 1e-6 * float(np.max(np.abs(bt.work[i])))
    assert float(np.max(np.abs(bt.u))) == 3.0  # (saturated somewhere: the clip is exercised)


def test_regulated_contact_runs_switch_controllers_with_the_active_set(arm: Any) -> None:
    # the target puts the tip 0.2 m behind the wall: the arm hits it and is held against it
    target = library.get("arm2r_wall", wall_x=2.5, joint_angles=(-0.3, 0.6)).state.q
    ctl = Regulator(arm.model, target=target, Kp=60.0, Kd=8.0)
    k = 4
    V = _rates(arm, k, seed=4) * 0.3
    bt = simulate_batch(arm, 0.6, arm.state.q, V, controller=ctl, dt=1e-3, t_eval=T_EVAL, restitution=0.2,
                        threads=2)  # fmt: skip
    assert bt.engine == ("batch",) * k
    for i in range(k):
        ref = simulate(arm, 0.6, arm.state.q, V[i], controller=ctl, dt=1e-3, t_eval=T_EVAL, restitution=0.2,
                       progress=False)  # fmt: skip
        assert ref.events and ref.events[0].name == "impact:wall"
        _same(bt, i, ref, 1e-8)
        assert abs(bt.work[i, -1]) > 1e-3  # (the regulator works: W is compared above)


def test_user_events_are_made_one_by_one_by_simulate(arm: Any) -> None:
    k = 3
    V = _rates(arm, k, seed=6)
    stop = Event(lambda t, q, qd, f_c: q[4] + 0.2, direction=+1, terminal=True, name="link2_up")
    bt = simulate_batch(arm, 0.6, arm.state.q, V, dt=1e-3, t_eval=T_EVAL, events=[stop], restitution=0.5)
    assert bt.engine == ("simulate",) * k
    for i in range(k):
        ref = simulate(arm, 0.6, arm.state.q, V[i], dt=1e-3, t_eval=T_EVAL, events=[stop], restitution=0.5,
                       progress=False)  # fmt: skip
        assert [e.name for e in bt.events[i]] == [e.name for e in ref.events]
        assert bt.status[i] == ref.status
        j = np.searchsorted(ref.t, T_EVAL, side="right") - 1
        ok = (j >= 0) & (ref.t[np.clip(j, 0, None)] == T_EVAL)
        np.testing.assert_array_equal(bt.q[i][ok], ref.q[j[ok]])
