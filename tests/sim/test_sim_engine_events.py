"""The engine's event layer (engine/src/sim_events.cpp): contact guards located by Brent's
method on the method's own partial steps and transitions (simultaneous impacts, releases,
Zeno truncation) applied in C++, against the general driver on the NumPy kernels."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from test_sim_simultaneous import _ball_on_floor_into_ramp, _bar_on_three_points

from conftest import make_ball
from nonmin import library
from nonmin.core import polyhedral_projection, use_backend
from nonmin.sim import _simulate, simulate


def _pair(model: Any, monkeypatch: pytest.MonkeyPatch, **kw: Any) -> tuple[Any, Any]:
    """The engine run (its transitions must not go through the Python driver's) and the
    general driver's on the NumPy kernels."""
    with monkeypatch.context() as mp:
        def no(*a: Any, **k: Any) -> Any:
            raise AssertionError("the Python driver applied a contact transition on the engine path")

        mp.setattr(_simulate, "_set_impact", no)
        mp.setattr(_simulate, "_apply", no)
        a = simulate(model, engine="engine", progress=False, **kw)
    with use_backend("numpy"):
        b = simulate(model, engine="python", progress=False, **kw)
    return a, b


def _same_events(a: Any, b: Any, t_tol: float, x_tol: float) -> None:
    assert [e.name for e in a.events] == [e.name for e in b.events]
    for ea, eb in zip(a.events, b.events):
        assert abs(ea.t - eb.t) < t_tol, (ea.name, ea.t - eb.t)
        assert ea.active_before == eb.active_before and ea.active_after == eb.active_after
        assert ea.transition == eb.transition
        for f in ("q_before", "qd_before", "q_after", "qd_after"):
            x, y = getattr(ea, f), getattr(eb, f)
            assert np.max(np.abs(x - y)) <= x_tol * max(1.0, float(np.max(np.abs(y)))), (ea.name, f)


def _same_samples(a: Any, b: Any, tol: float) -> None:
    assert len(a) == len(b) and a.n_steps == b.n_steps
    np.testing.assert_array_equal(a.active_mask, b.active_mask)
    np.testing.assert_allclose(a.t, b.t, rtol=0, atol=1e-11)
    for f in ("q", "qd", "energy"):
        x, y = getattr(a, f), getattr(b, f)
        assert float(np.max(np.abs(x - y))) <= tol * max(1.0, float(np.max(np.abs(y)))), f


@pytest.mark.parametrize("kw", [
    {"dt": 1e-3},
    {"dt": 1e-3, "t_eval": np.linspace(0.0, 1.2, 61)},
    {"method": "midpoint", "dt": 2e-3},
    {"method": "dopri5", "rtol": 1e-10, "atol": 1e-12},
])  # fmt: skip
def test_bouncing_ball_on_the_engine_equals_the_general_driver(kw: dict[str, Any], monkeypatch: pytest.MonkeyPatch) -> None:
    a, b = _pair(make_ball(), monkeypatch, t_span=(0.0, 1.2), q0=[0.0, 1.0], qd0=[0.3, 0.0], restitution=0.7, **kw)
    assert len(a.events) >= 2
    _same_events(a, b, 1e-11, 1e-9)
    if "dopri5" not in kw:  # (DOPRI5's step sizes follow a projected error at round-off)
        _same_samples(a, b, 1e-9)


def test_arm_on_a_wall_with_a_controller_impact_and_release(monkeypatch: pytest.MonkeyPatch) -> None:
    mech = library.get("arm2r_wall")
    u_amp = np.array([10.0, -6.0])

    def ctrl(t: float, q: Any, qd: Any, state: Any = None, *, active: Any = None) -> Any:
        return u_amp * np.cos(2.0 * t)

    a, b = _pair(mech, monkeypatch, t_span=(0.0, 0.45), dt=1e-3, controller=ctrl,
                 t_eval=np.linspace(0.0, 0.45, 46))  # fmt: skip
    assert [e.name for e in a.events] == ["impact:wall", "release:wall"]
    _same_events(a, b, 1e-11, 1e-9)
    _same_samples(a, b, 1e-8)


@pytest.mark.parametrize("maker", [_bar_on_three_points, _ball_on_floor_into_ramp])
def test_simultaneous_impacts_on_the_engine(maker: Any, monkeypatch: pytest.MonkeyPatch) -> None:
    model = maker()
    if model.n == 3:
        kw: dict[str, Any] = dict(t_span=(0.0, 0.8), q0=[0.0, 0.5, 0.0], restitution=0.5)
    else:
        # 0.3 m from the ramp (1 m before: 700 more steps of rolling on the floor, 2.5 s of the
        # general driver's CPU): the ramp at 0.3 s, the floor and the ramp together at 0.504 s
        kw = dict(t_span=(0.0, 0.6), q0=[0.3, 0.0], qd0=[-1.0, 0.0], active={"floor"}, restitution=1.0)
    a, b = _pair(model, monkeypatch, dt=1e-3, **kw)
    assert len(a.events) >= 2
    if model.n != 3:
        assert [e.name for e in a.events] == ["impact:ramp", "impact:floor+ramp"]
    _same_events(a, b, 1e-11, 1e-9)
    _same_samples(a, b, 1e-9)


def test_robot_joint_limit_and_floor_on_the_engine(monkeypatch: pytest.MonkeyPatch) -> None:
    """The 4-dof arm lifted off its floor contact falls onto it (a compiled TreeProgram)."""
    from nonmin.model.robots import serial_arm

    model, state = serial_arm()
    q0 = np.array(state.q, dtype=float)
    q0[1] -= 0.05  # lift the end effector
    # to 0.35 s (0.6 s before: no event after 0.288 s): four impacts on the floor, the release
    # from it at 0.231 s and the wrist's upper stop at 0.288 s
    a, b = _pair(model, monkeypatch, t_span=(0.0, 0.35), q0=q0, dt=1e-3, restitution=0.3)
    assert a.events and a.events[0].name == "impact:ee_contact"
    assert [e.name for e in a.events][-2:] == ["release:ee_contact", "impact:wrist.upper"]
    _same_events(a, b, 1e-11, 1e-8)
    _same_samples(a, b, 1e-8)



def test_a_run_with_contact_guards_starts_in_the_engine(monkeypatch: pytest.MonkeyPatch) -> None:
    """A run with unilateral constraints alone starts in the engine (no Python projection, point
    or guard values): SimLoop.arm_guards gives the contact guards the values the Python start
    computes at its first point (_guard_values: the closed contact's normal force, the open
    joint stops' gaps), and the run equals the general driver's."""
    from types import SimpleNamespace

    from nonmin.model.robots import serial_arm
    from nonmin.sim import _engine
    from nonmin.sim._integrators import RK4
    from nonmin.sim._stabilization import Projection

    model, state = serial_arm()
    act = frozenset({"ee_contact"})
    q0, qd0 = np.array(state.q, dtype=float), np.full(model.n, 0.1)
    uni = tuple(c.name for c in model.constraints if c.kind == "unilateral")
    system = _simulate._System(model, None, Projection(), None, model.n, model.k, act, None, unilateral=uni)
    watches = _simulate._watches((), act, uni)
    idx, guards = _simulate._engine_guards(system, watches, [0.0] * len(watches))
    opts = _engine.options(RK4(), Projection(), dt=1e-3, t1=0.0, h0=1e-3, rank_rtol=None,
                           drift_factor=_simulate.DRIFT_RANK_FACTOR, project_initial=True, max_steps=10)  # fmt: skip
    er = _engine.run(_engine.program_for(model), opts=opts, active_mask=_simulate.model_mask(model, act),
                     t_out=None, sink=lambda blk: None, progress=SimpleNamespace(update=lambda t: None),
                     start=(0.0, q0, qd0), guards=guards, contact=([0.0] * len(model.constraints), 1e-6))  # fmt: skip
    assert er.started and er.steps == 0
    q, qd = Projection().project(model, 0.0, q0, qd0, act, None)
    ref = _simulate._guard_values(system, watches, system.point(0.0, q, qd))
    assert [watches[i].kind for i in idx].count("release") == 1 and len(idx) == len(uni)
    np.testing.assert_allclose(er.guards, [ref[i] for i in idx], rtol=1e-9, atol=1e-12)
    assert abs(er.guards[[watches[i].kind for i in idx].index("release")]) > 1e-3  # a real force

    def no(*a: Any, **k: Any) -> Any:
        raise AssertionError("the Python driver started a run the engine can start")

    with monkeypatch.context() as mp:
        mp.setattr(_simulate, "_guard_values", no)
        a = simulate(model, (0.0, 0.2), q0, qd0, active=act, dt=1e-3, engine="engine", progress=False)
    with use_backend("numpy"):
        b = simulate(model, (0.0, 0.2), q0, qd0, active=act, dt=1e-3, engine="python", progress=False)
    assert a.metadata["engine"] == "engine"
    _same_events(a, b, 1e-11, 1e-8)
    _same_samples(a, b, 1e-8)

def test_engine_kernel_equals_the_numpy_specification() -> None:
    rng = np.random.default_rng(7)
    for _ in range(20):
        n = 5
        B = rng.standard_normal((n, n))
        M = B @ B.T + n * np.eye(n)
        Ae, Ai = rng.standard_normal((1, n)), rng.standard_normal((4, n))
        Ai[3] = Ai[0] + Ai[1]  # redundant
        x0, re, ri = rng.standard_normal(n), rng.standard_normal(1), rng.standard_normal(4)
        ri[3] = ri[0] + ri[1]
        a = polyhedral_projection(M, x0, Ae, re, Ai, ri)
        with use_backend("numpy"):
            b = polyhedral_projection(M, x0, Ae, re, Ai, ri)
        assert np.max(np.abs(a.x - b.x)) < 1e-13 * (1 + np.max(np.abs(b.x)))
        np.testing.assert_array_equal(a.at_bound, b.at_bound)
