"""The built-in controllers compiled into the engine's loop (nonmin/control/_engine.py,
engine/src/sim_control.cpp) against the Python controllers in the general driver on the NumPy
reference kernels: the same u, q, qd, f_c to round-off; references as values (constant,
polynomial, spline) and as Python functions called back; force control; Switched; the
controller state; failures raised with the Python controller's types."""

from __future__ import annotations

import math
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from nonmin import library
from nonmin.control import ForceControl, Reference, Regulator, Switched, Tracker
from nonmin.core import use_backend
from nonmin.errors import InputError, SimulationError
from nonmin.model.planar import PlanarBuilder
from nonmin.sim import _engine, simulate

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "examples"))
from control_scenes import (
    arm2r_configuration,
    crank_four_bar,
    crank_four_bar_configuration,
    pendulum_configuration,
    wall_tip_path,
)

FIELDS = ("q", "qd", "qdd", "f_c", "u")


def _pair(model: Any, make: Any, **kw: Any) -> tuple[Any, Any]:
    a = simulate(model, controller=make(), engine="engine", progress=False, **kw)
    with use_backend("numpy"):  # the readable specification as the oracle
        b = simulate(model, controller=make(), engine="python", progress=False, **kw)
    return a, b


def _close(a: Any, b: Any, tol: float = 1e-9, tol_acc: float = 1e-7) -> None:
    assert a.metadata["engine"] == "engine" and b.metadata["engine"] == "python", a.metadata["engine"]
    assert a.success and b.success, (a.message, b.message)
    assert len(a) == len(b) and a.n_steps == b.n_steps
    np.testing.assert_allclose(a.t, b.t, rtol=0, atol=1e-12)
    for f in FIELDS:
        x, y = getattr(a, f), getattr(b, f)
        scale = max(1.0, float(np.max(np.abs(y))))
        err = float(np.max(np.abs(x - y))) / scale
        assert err < (tol_acc if f in ("qdd", "f_c", "u") else tol), (f, err)


def _compiled(ctrl: Any, model: Any, active: frozenset[str] | None = None) -> Any:
    prog = _engine.program_for(model)
    return _engine.compiled_controller(ctrl, model, prog, model.resolve_active(active))


# ----------------------------------------------------------------------------- references


def test_piecewise_polynomial_equals_the_reference_functions() -> None:
    """The engine's evaluation of constant, polynomial and spline references = their Python
    functions (inside, at the breakpoints, outside the spline's range: held)."""
    eng = _engine._engine()
    ts = np.array([0.0, 0.3, 0.7, 1.0])
    qs = np.array([[0.0, 1.0], [0.4, 0.2], [-0.3, 0.9], [0.1, 0.0]])
    refs = [Reference.constant([0.2, -1.0]), Reference.polynomial([[0.1, 2.0], [0.5, 0.0], [-1.0, 3.0], [0.25, 1.0]]),
            Reference.spline(ts, qs)]  # fmt: skip
    for ref in refs:
        assert ref.piecewise is not None
        x, c, hold = ref.piecewise
        pp = eng.SimPiecewisePolynomial(np.ascontiguousarray(x), np.ascontiguousarray(c), hold)
        for t in (-0.5, 0.0, 0.15, 0.3, 0.55, 0.7, 1.0, 1.7):
            want = np.concatenate(ref(t))
            got = np.asarray(pp(t))
            np.testing.assert_allclose(got, want, rtol=1e-13, atol=1e-13 * max(1.0, np.abs(want).max()))
    poly = refs[1]
    q, v, a = poly(2.0)
    np.testing.assert_allclose(q, [0.1 + 0.5 * 2 - 4.0 + 0.25 * 8, 2.0 + 12.0 + 8.0])
    np.testing.assert_allclose(v, [0.5 - 4.0 + 0.75 * 4, -0.0 + 12.0 + 12.0])
    np.testing.assert_allclose(a, [-2.0 + 1.5 * 2, 6.0 + 12.0])


def test_time_signal_is_the_model_time_functions() -> None:
    """A reference's engine signal is made of the engine's TimeFunctions (the drivers' values):
    SimTimeSignal over model time functions (a spline, an expression's tape) = their Python
    evaluation, and = SimPiecewisePolynomial (PPoly's layout) bit for bit."""
    from nonmin.model import Expression, PiecewisePolynomial, Spline

    eng = _engine._engine()
    ts = np.array([0.0, 0.3, 0.7, 1.0])
    f0 = Spline(ts, np.array([0.0, 0.4, -0.3, 0.1]))
    f1 = Expression("sin(2*t) + t**3")
    sig = eng.SimTimeSignal([f0.engine(), f1.engine()])
    assert sig.dim == 2
    for t in (-0.5, 0.0, 0.15, 0.3, 0.55, 1.0, 1.7):
        got = np.asarray(sig(t)).reshape(3, 2)
        for j, f in enumerate((f0, f1)):
            np.testing.assert_allclose(got[:, j], f(t), rtol=1e-13, atol=1e-13)
    ref = Reference.spline(ts, np.array([[0.0, 1.0], [0.4, 0.2], [-0.3, 0.9], [0.1, 0.0]]))
    x, c, hold = ref.piecewise
    pp = eng.SimPiecewisePolynomial(np.ascontiguousarray(x), np.ascontiguousarray(c), hold)
    assert type(pp).__name__ == "SimTimeSignal"
    comps = [
        PiecewisePolynomial(np.asarray(x), np.ascontiguousarray(c[::-1, :, j].T), hold=False).engine()
        for j in range(2)
    ]
    held = eng.SimTimeSignal(comps, hold, float(x[0]), float(x[-1]))
    for t in (-0.5, 0.0, 0.15, 0.3, 0.55, 0.7, 1.0, 1.7):
        assert np.asarray(pp(t)).tolist() == np.asarray(held(t)).tolist()
        np.testing.assert_allclose(np.asarray(pp(t)), np.concatenate(ref(t)), rtol=1e-13, atol=1e-13)
    with pytest.raises(InputError, match="hold window"):
        eng.SimTimeSignal(comps, True, 1.0, 1.0)


# ----------------------------------------------------------------------------- regulator


@pytest.mark.parametrize("opts", [{}, {"metric": "mass"}, {"target_policy": "reject"}, {"u_max": 2.0}])
def test_regulator_engine_equals_python(opts: dict[str, Any]) -> None:
    model = crank_four_bar()
    target = crank_four_bar_configuration(model, 1.4)
    if "target_policy" not in opts:
        target = target + 0.05  # off the manifold: projected (Euclidean or mass metric)
    lim = opts.pop("u_max", None)

    def make() -> Regulator:
        return Regulator(model, target=target, Kp=200.0, Kd=30.0, u_max=lim, u_min=None if lim is None else -lim,
                         **opts)  # fmt: skip

    assert type(_compiled(make(), model)).__name__ == "SimControl"
    # 75 steps (150 before; the general driver's run is the test's cost)
    a, b = _pair(model, make, t_span=(0.0, 0.15), q0=crank_four_bar_configuration(model, 0.6), dt=2e-3)
    assert a.n_steps == 75
    _close(a, b)


# ----------------------------------------------------------------------------- tracker


def _crank_refs(model: Any) -> dict[str, Reference]:
    def crank(t: float) -> float:
        return 1.0 + 0.8 * math.sin(2.0 * t)

    ts = np.linspace(0.0, 0.6, 13)
    qs = np.array([crank_four_bar_configuration(model, crank(t)) for t in ts])
    q_lin = crank_four_bar_configuration(model, 1.0)
    return {
        "spline": Reference.spline(ts, qs),  # between the samples off the manifold: projected
        "polynomial": Reference.polynomial([q_lin, 0.3 * np.ones(model.n), -0.2 * np.ones(model.n)]),
        "function": Reference.from_functions(lambda t: crank_four_bar_configuration(model, crank(t))),
        "constant": Reference.constant(q_lin),
    }


@pytest.mark.parametrize("kind", ["spline", "polynomial", "function", "constant"])
def test_computed_torque_tracker_engine_equals_python(kind: str) -> None:
    model = crank_four_bar()
    ref = _crank_refs(model)[kind]

    def make() -> Tracker:
        return Tracker(model, ref, Kp=400.0, Kd=40.0, method="computed_torque")

    c = _compiled(make(), model)
    assert type(c).__name__ == "SimControl"
    # 75 steps (150 before; the general driver's run is the test's cost)
    a, b = _pair(model, make, t_span=(0.0, 0.15), q0=crank_four_bar_configuration(model, 0.6), dt=2e-3)
    assert a.n_steps == 75
    _close(a, b)
    assert float(np.max(np.abs(a.u))) > 1.0


def test_passivity_tracker_is_compiled_and_equals_python() -> None:
    """(More in test_control_passivity_engine.py: per call, rheonomic, switched, robots.)"""
    model = crank_four_bar()
    ref = _crank_refs(model)["spline"]

    def make() -> Tracker:
        return Tracker(model, ref, Kp=400.0, Kd=40.0, lambda_=10.0)

    # planar program: C = 0 (constant M), Ȧ from the program's tangent
    assert type(_compiled(make(), model)).__name__ == "SimControl"
    a, b = _pair(model, make, t_span=(0.0, 0.2), q0=crank_four_bar_configuration(model, 0.6), dt=2e-3)
    _close(a, b)


@pytest.mark.parametrize("method", ["computed_torque", "passivity"])
def test_tracker_state_is_the_python_record(method: str) -> None:
    """merge_state over the compiled steps = ControlState.record over the same steps, for both
    compiled tracking laws (the crank four-bar with actuator limits)."""
    model = crank_four_bar()
    ctl = Tracker(model, _crank_refs(model)["spline"], Kp=400.0, Kd=40.0, lambda_=10.0, method=method,
                  u_min=-30.0, u_max=30.0)  # fmt: skip
    tr = simulate(model, (0.0, 0.2), crank_four_bar_configuration(model, 0.6), dt=2e-3, controller=ctl,
                  engine="engine", progress=False)  # fmt: skip
    creg = _compiled(ctl, model)
    eng = _engine._engine()
    from nonmin.sim import RK4, Projection

    opts = _engine.options(RK4(), Projection(), dt=2e-3, t1=0.2, h0=0.0, rank_rtol=None, drift_factor=1.0,
                           project_initial=True, max_steps=1000)  # fmt: skip
    act = model.resolve_active(None)
    loop = eng.SimLoop(_engine.program_for(model), model.active_mask(act), opts, np.zeros(0), True, None, None,
                       None, [], creg)  # fmt: skip
    assert loop.start(0.0, tr.q[0], tr.qd[0]) == eng.SIM_DONE
    assert loop.run(1000) == eng.SIM_DONE
    rec = loop.take()
    got = _engine.merge_state(ctl, ctl.initial_state(), creg)
    want = ctl.initial_state()
    with use_backend("numpy"):
        for t, q, qd in zip(rec["t"][1:], rec["q"][1:], rec["qd"][1:], strict=True):
            want = ctl.update(t, q, qd, want, active=act)
    assert got.steps == want.steps == 100
    assert got.saturated_steps == want.saturated_steps and sum(got.saturated_steps) > 0
    assert got.infeasible_steps == want.infeasible_steps == 0
    assert abs(got.min_sigma_pb - want.min_sigma_pb) <= 1e-12 * want.min_sigma_pb
    np.testing.assert_allclose(got.max_abs_u, want.max_abs_u, rtol=1e-9)
    if method == "passivity":
        assert math.isfinite(creg.lyapunov)


# ----------------------------------------------------------------------------- force control


def _pendulum_xy() -> Any:
    b = PlanarBuilder("pendulum_xy", gravity=(0.0, -9.81))
    b.point_mass("bob", mass=1.0, points=["P"])
    b.ground_point("O", (0.0, 0.0))
    b.rod("rod", "O", "P", length=1.0)
    b.force("fx", "P", direction=(1.0, 0.0))
    b.force("fy", "P", direction=(0.0, 1.0))
    return b.build()


@pytest.mark.parametrize("target", [-2.0, "callable"])
@pytest.mark.parametrize("motion", ["regulator", "computed_torque"])
def test_force_control_engine_equals_python(target: Any, motion: str) -> None:
    model = _pendulum_xy()
    force = (lambda t: -2.0 - math.sin(3.0 * t)) if target == "callable" else target

    def make() -> ForceControl:
        if motion == "regulator":
            m = Regulator(model, target=pendulum_configuration(0.5), Kp=5.0, Kd=1.0)
        else:
            ref = Reference.polynomial([pendulum_configuration(-1.0), [0.5, 0.5]])
            m = Tracker(model, ref, Kp=50.0, Kd=10.0, method="computed_torque")
        return ForceControl(m, {"rod": force})

    assert type(_compiled(make(), model)).__name__ == "SimControl"
    # 75 steps (150 before; the general driver's run with the Python ForceControl is the cost)
    a, b = _pair(model, make, t_span=(0.0, 0.15), q0=pendulum_configuration(-1.2), dt=2e-3)
    assert a.n_steps == 75
    _close(a, b)
    ctl = make()
    lam = [ctl.measured_force(t, q, fc)["rod"][0] for t, q, fc in zip(a.t, a.q, a.f_c)]
    want = [force(t) if callable(force) else force for t in a.t]
    np.testing.assert_allclose(lam, want, atol=1e-9)


def test_force_control_feasible_takes_the_certified_lq(monkeypatch: pytest.MonkeyPatch) -> None:
    """A feasible commanded force: step 3 solves [ZB; EB] u = [Z f_∥; …] by its certified LQ
    (no SVD per call; the same singular values as [PB; EB]) and the run still equals the Python
    controller's SVD minimum-norm solution to round-off."""
    from nonmin.control import _engine as ceng

    made: list[Any] = []
    real = ceng.compile_controller

    def spy(*args: Any, **kw: Any) -> Any:  # the real compiler; keeps what it made
        out = real(*args, **kw)
        made.append(out)
        return out

    monkeypatch.setattr(ceng, "compile_controller", spy)
    model = _pendulum_xy()

    def make() -> ForceControl:
        return ForceControl(Regulator(model, target=pendulum_configuration(0.5), Kp=5.0, Kd=1.0), {"rod": -2.0})

    a, b = _pair(model, make, t_span=(0.0, 0.15), q0=pendulum_configuration(-1.2), dt=2e-3)  # 75 steps (150 before)
    assert a.n_steps == 75
    _close(a, b)
    stats = made[-1].stats
    assert stats["fast_actuations"] > 0 and stats["svd_actuations"] == 0, stats


@pytest.mark.parametrize("method", ["computed_torque", "passivity"])
def test_force_control_through_contact_and_switched(method: str) -> None:
    """arm2r_wall: a tracker (computed torque, or passivity: Law::passivity) reaches the wall,
    then commands 5 N on it; the engine runs each active set with the compiled controller
    (events by the general driver)."""
    mech = library.get("arm2r_wall")
    m = mech.model

    def path(t: float) -> np.ndarray:
        return wall_tip_path(t, t_reach=0.6, t_settle=0.3, t_slide=1.0)

    ts = np.linspace(0.0, 1.2, 61)
    ref = Reference.spline(ts, np.array([arm2r_configuration(path(t)) for t in ts]))

    def make() -> Any:
        trk = Tracker(m, ref, Kp=400.0, Kd=40.0, lambda_=10.0, method=method)
        return Switched(m, {frozenset({"shoulder", "elbow"}): trk}, default=ForceControl(trk, {"wall": 5.0}))

    free = _compiled(make(), m, frozenset({"shoulder", "elbow"}))
    touch = _compiled(make(), m, frozenset({"shoulder", "elbow", "wall"}))
    assert type(free).__name__ == type(touch).__name__ == "SimControl"
    assert free.switched[1] == 0 and touch.switched[1] == 1
    a = simulate(mech, (0.0, 0.7), method="rk4", dt=4e-3, controller=make(), engine="engine", progress=False)
    with use_backend("numpy"):
        b = simulate(mech, (0.0, 0.7), method="rk4", dt=4e-3, controller=make(), engine="python", progress=False)
    assert a.success and b.success
    assert [e.name for e in a.events] == [e.name for e in b.events] and len(a.events) == 1
    assert abs(a.events[0].t - b.events[0].t) < 1e-9
    assert len(a) == len(b)
    np.testing.assert_allclose(a.q, b.q, rtol=0, atol=1e-7)
    np.testing.assert_allclose(a.u, b.u, rtol=0, atol=1e-5 * float(np.max(np.abs(b.u))))


# ----------------------------------------------------------------------------- failures


def test_failures_raise_the_python_controllers_errors() -> None:
    """A compiled controller that fails hands over: the Python controller raises its own error."""
    model = crank_four_bar()
    q0 = crank_four_bar_configuration(model, 0.6)
    off = Reference.constant(crank_four_bar_configuration(model, 1.0) + 0.1)
    for eng in ("engine", "python"):
        with pytest.raises(SimulationError, match=r"AssemblyError: reference q\*\(t\) is off the constraint manifold"):
            simulate(model, (0.0, 0.1), q0, dt=2e-3, engine=eng, progress=False,
                     controller=Tracker(model, off, method="computed_torque", target_policy="reject"))  # fmt: skip

    def bad(t: float) -> np.ndarray:
        if t > 0.05:
            raise ValueError("no reference after 0.05 s")
        return crank_four_bar_configuration(model, 0.6)

    for eng in ("engine", "python"):
        with pytest.raises(SimulationError, match=r"no reference after 0\.05 s"):
            simulate(model, (0.0, 0.1), q0, dt=2e-3, engine=eng, progress=False,
                     controller=Tracker(model, Reference.from_functions(bad), method="computed_torque"))  # fmt: skip
