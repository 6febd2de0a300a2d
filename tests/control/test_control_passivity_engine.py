"""The Tracker's passivity (Slotine–Li) law compiled into the engine (Law::passivity,
engine/src/sim_control.cpp) against the Python law (nonmin/control/_tracking.py, the
specification): per call (u, the Lyapunov value W, the projected target) to round-off, and over
whole runs (the same steps, trajectories within tight tolerances). Planar programs (constant M:
C = 0, Ȧ from the program's tangent along q̇), a rheonomic planar model (a driven distance), the
switched wall contact, and a robot (the tree program's Christoffel C and Ȧ). Programs without
C in the engine (spatial, SymPy, function models) are called back."""

from __future__ import annotations

import math
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from nonmin import library
from nonmin.control import Reference, Regulator, Tracker
from nonmin.core import use_backend
from nonmin.model.planar import PlanarBuilder
from nonmin.sim import _engine, simulate

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "examples"))
from control_scenes import (
    crank_four_bar,
    crank_four_bar_configuration,
)

FIELDS = ("q", "qd", "qdd", "f_c", "u")


def _compiled(ctrl: Any, model: Any, active: frozenset[str] | None = None) -> Any:
    prog = _engine.program_for(model)
    return _engine.compiled_controller(ctrl, model, prog, model.resolve_active(active))


def _mask(model: Any, active: frozenset[str]) -> list[int]:
    return [int(c.name in active) for c in model.constraints]


def _per_call(ctrl: Any, model: Any, states: list[tuple[float, np.ndarray, np.ndarray]],
              active: frozenset[str] | None = None, tol: float = 1e-10) -> None:  # fmt: skip
    """compiled.probe = the Python controller's info at each state: u, W, target."""
    act = model.resolve_active(active)
    c = _compiled(ctrl, model, act)
    assert type(c).__name__ == "SimControl"
    prog = _engine.program_for(model)
    for t, q, qd in states:
        got = c.probe(prog, t, q, qd, _mask(model, act))
        with use_backend("numpy"):
            want = ctrl.info(t, q, qd, active=act)
        scale_u = max(1.0, float(np.max(np.abs(want.u))))
        assert float(np.max(np.abs(np.asarray(got["u"]) - want.u))) <= tol * scale_u, (t, got["u"], want.u)
        assert abs(got["lyapunov"] - want.lyapunov) <= tol * max(1.0, abs(want.lyapunov)), (got, want.lyapunov)
        np.testing.assert_allclose(got["target"], want.target, rtol=0, atol=tol * max(1.0, np.abs(want.target).max()))
        assert math.isfinite(got["lyapunov"]) and got["lyapunov"] > 0.0


def _pair(model: Any, make: Any, **kw: Any) -> tuple[Any, Any]:
    a = simulate(model, controller=make(), engine="engine", progress=False, **kw)
    with use_backend("numpy"):
        b = simulate(model, controller=make(), engine="python", progress=False, **kw)
    return a, b


def _close(a: Any, b: Any, tol: float = 1e-9, tol_acc: float = 1e-7, same_steps: bool = True) -> None:
    assert a.metadata["engine"] == "engine" and b.metadata["engine"] == "python", a.metadata["engine"]
    assert a.success and b.success, (a.message, b.message)
    if same_steps:
        assert len(a) == len(b) and a.n_steps == b.n_steps, (a.n_steps, b.n_steps)
        np.testing.assert_allclose(a.t, b.t, rtol=0, atol=1e-12)
    for f in FIELDS:
        x, y = getattr(a, f), getattr(b, f)
        err = float(np.max(np.abs(x - y))) / max(1.0, float(np.max(np.abs(y))))
        assert err < (tol_acc if f in ("qdd", "f_c", "u") else tol), (f, err)


def _states(model: Any, q0: np.ndarray, ts: np.ndarray, rng: np.random.Generator) -> list[Any]:
    """Admissible states near q0 (on the manifold, q̇ in N(A)) at the times ts."""
    from nonmin.model import assemble

    out = []
    for t in ts:
        st = assemble(model, q0 + 0.02 * rng.normal(size=model.n), rng.normal(size=model.n), t=float(t))
        out.append((float(t), np.asarray(st.q), np.asarray(st.qd)))
    return out


# ----------------------------------------------------------------------------- five-bar (tutorial 03)


def _five_bar_tracker() -> tuple[Any, Tracker, np.ndarray]:
    ts = np.linspace(0.0, 2.0, 41)
    circle = [(0.4 + 0.15 * np.sin(np.pi * t), 1.5 - 0.15 + 0.15 * np.cos(np.pi * t)) for t in ts]
    ref = Reference.spline(ts, [library.five_bar(end_effector=p).state.q for p in circle])
    model = library.five_bar().model
    q0 = library.five_bar(end_effector=(0.35, 1.45)).state.q
    return model, Tracker(model, ref, Kp=100.0, Kd=20.0, lambda_=10.0), q0


def test_five_bar_passivity_per_call() -> None:
    model, trk, q0 = _five_bar_tracker()
    rng = np.random.default_rng(3)
    _per_call(trk, model, _states(model, q0, np.array([0.0, 0.013, 0.5, 1.25, 1.999, 2.5]), rng))


def test_five_bar_passivity_run_equals_python() -> None:
    """Tutorial 03 section 4 (DOPRI5 rtol 1e-7): the same accepted steps, the same trajectory."""

    def make() -> Tracker:
        return _five_bar_tracker()[1]

    model, _, q0 = _five_bar_tracker()
    # 0.3 s: 77 accepted steps, the start's transient (max |u| 131 N·m at the start) and the
    # circle after it (0.6 s before: 128 steps; the general driver's run was the test's cost)
    ts = np.linspace(0.0, 0.3, 13)
    a, b = _pair(model, make, t_span=(0.0, 0.3), q0=q0, method="dopri5", rtol=1e-7, atol=1e-9, t_eval=ts)
    assert a.n_steps > 60
    # DOPRI5's step sizes follow an error estimate at round-off distance of the two laws: the
    # same number of steps, the samples to well within the method's tolerance
    _close(a, b, tol=1e-6, tol_acc=1e-5)
    assert float(np.max(np.abs(a.u))) > 1.0
    # RK4 (fixed steps): the whole run to round-off (75 steps; 150 before)
    a, b = _pair(model, make, t_span=(0.0, 0.15), q0=q0, dt=2e-3)
    _close(a, b)


def test_crank_four_bar_passivity_run() -> None:
    """RK4 on the crank four-bar with actuator limits: u, q, qd to round-off (the controller
    state: test_control_engine.py's test_tracker_state_is_the_python_record)."""
    model = crank_four_bar()
    ts = np.linspace(0.0, 0.6, 13)
    qs = np.array([crank_four_bar_configuration(model, 1.0 + 0.8 * math.sin(2.0 * t)) for t in ts])
    ref = Reference.spline(ts, qs)

    def make() -> Tracker:
        return Tracker(model, ref, Kp=400.0, Kd=40.0, lambda_=10.0, u_min=-30.0, u_max=30.0)

    q0 = crank_four_bar_configuration(model, 0.6)
    _per_call(make(), model, _states(model, q0, np.array([0.0, 0.1, 0.35]), np.random.default_rng(1)))
    a, b = _pair(model, make, t_span=(0.0, 0.2), q0=q0, dt=2e-3)
    _close(a, b)


def test_controller_of_another_model_instance() -> None:
    """Tutorial 03 builds the tracker on one five-bar instance and simulates another (equal)
    one: compiled on the controller's own program (own_terms), the same run as the Python
    controller. A nominal model driving a perturbed plant (the crank four-bar under another
    gravity, same layout) likewise; a model of another layout is called back."""
    model, trk, _ = _five_bar_tracker()
    off = library.five_bar(end_effector=(0.35, 1.45))
    assert off.model is not model
    c = _engine.compiled_controller(trk, off.model, _engine.program_for(off.model), off.model.resolve_active(None))
    assert type(c).__name__ == "SimControl"

    def make() -> Tracker:
        return _five_bar_tracker()[1]

    a, b = _pair(off, make, t_span=(0.0, 0.15), dt=2e-3)  # 75 steps (150 before)
    _close(a, b)
    plant, nominal = crank_four_bar(g=12.0), crank_four_bar()
    ts = np.linspace(0.0, 0.6, 13)
    ref = Reference.spline(ts, np.array([crank_four_bar_configuration(nominal, 1.0 + 0.8 * math.sin(2.0 * t))
                                         for t in ts]))  # fmt: skip

    def make2() -> Tracker:
        return Tracker(nominal, ref, Kp=400.0, Kd=40.0, lambda_=10.0)

    assert type(_compiled(make2(), plant)).__name__ == "SimControl"
    a, b = _pair(plant, make2, t_span=(0.0, 0.2), q0=crank_four_bar_configuration(plant, 0.6), dt=2e-3)
    _close(a, b)
    a0 = simulate(nominal, controller=make2(), engine="engine", progress=False, t_span=(0.0, 0.2),
                  q0=crank_four_bar_configuration(plant, 0.6), dt=2e-3)  # fmt: skip
    assert float(np.max(np.abs(a0.q - a.q))) > 1e-6  # (the plant's own dynamics)
    assert _compiled(make2(), _arm3_driven()) is None


# ----------------------------------------------------------------------------- rheonomic, switching


def _arm3_driven() -> Any:
    """A 3R arm whose tip's distance to the ground point (2.2, 0) is driven (rheonomic, A depends
    on q: Ȧ ≠ 0), three joint torques, 2 DOF left; gravity on."""
    b = PlanarBuilder("arm3_driven", gravity=(0.0, -9.81))
    for i in (1, 2, 3):
        b.body(f"l{i}", mass=1.0, inertia=1.0 / 12.0)
    b.revolute("j1", ("ground", (0.0, 0.0)), ("l1", (-0.5, 0.0)))
    b.revolute("j2", ("l1", (0.5, 0.0)), ("l2", (-0.5, 0.0)))
    b.revolute("j3", ("l2", (0.5, 0.0)), ("l3", (-0.5, 0.0)))
    b.point("T", "l3", (0.5, 0.0))
    b.ground_point("G", (2.2, 0.0))
    b.drive_distance("drive", "G", "T", [0.6, 0.3])  # |T − G| = 0.6 + 0.3 t
    for j in ("j1", "j2", "j3"):
        b.actuator(j, j)
    return b.build()


def _arm3_q(a1: float, a2: float, a3: float) -> np.ndarray:
    q, p, ang = [], np.zeros(2), 0.0
    for a in (a1, a2, a3):
        ang = a
        c = p + 0.5 * np.array([math.cos(ang), math.sin(ang)])
        q += [c[0], c[1], ang]
        p = p + np.array([math.cos(ang), math.sin(ang)])
    return np.array(q)


def test_rheonomic_planar_passivity_per_call_and_run() -> None:
    from nonmin.model import assemble

    model = _arm3_driven()
    q0 = assemble(model, _arm3_q(0.6, -0.5, -0.9), np.zeros(model.n), t=0.0).q
    ref = Reference.polynomial([_arm3_q(0.5, -0.4, -0.8), 0.2 * np.ones(model.n)])

    def make() -> Tracker:
        return Tracker(model, ref, Kp=50.0, Kd=10.0, lambda_=5.0)

    _per_call(make(), model, _states(model, q0, np.array([0.0, 0.05, 0.2]), np.random.default_rng(7)))
    a, b = _pair(model, make, t_span=(0.0, 0.15), q0=q0, dt=2e-3)  # 75 steps (150 before)
    _close(a, b)
    assert float(np.max(np.abs(a.u))) > 1.0


# ----------------------------------------------------------------------------- robots (TreeProgram)


def test_robot_passivity_per_call_and_run() -> None:
    pytest.importorskip("pinocchio")
    import warnings

    from nonmin.errors import JointLimitWarning
    from nonmin.model.robots._examples import serial_arm

    warnings.simplefilter("ignore", JointLimitWarning)
    model, state = serial_arm()
    q0 = np.asarray(state.q)
    d = np.array([0.1, 0.05, -0.1, -0.05])  # (away from the joint stops)
    ref = Reference.polynomial([q0 + d, d])

    def make() -> Tracker:
        return Tracker(model, ref, Kp=30.0, Kd=5.0, lambda_=5.0)

    rng = np.random.default_rng(11)
    states = [(float(t), q0 + 0.05 * rng.normal(size=model.n), rng.normal(size=model.n)) for t in (0.0, 0.1, 0.3)]
    from nonmin.model import assemble

    states = [(t, np.asarray(s.q), np.asarray(s.qd)) for t, q, qd in states
              for s in [assemble(model, q, qd, t=t)]]  # fmt: skip
    _per_call(make(), model, states)
    a, b = _pair(model, make, t_span=(0.0, 0.2), q0=q0, dt=2e-3)
    _close(a, b)
    assert [e.name for e in a.events] == [e.name for e in b.events]


def test_called_back_without_coriolis_in_the_engine() -> None:
    """A function model (C from the user's function): the passivity law stays in Python."""
    from nonmin.model import FunctionModel

    fm = FunctionModel(name="xy", coordinate_names=("x", "y"), mass=lambda q: np.diag([2.0 + math.cos(q[1]), 1.0]),
                       coriolis=lambda q, qd: np.array([[-0.5 * math.sin(q[1]) * qd[1], -0.5 * math.sin(q[1]) * qd[0]],
                                                        [0.5 * math.sin(q[1]) * qd[0], 0.0]]),
                       conservative=lambda q: np.zeros(2), potential=lambda q: 0.0, actuator_names=("fx", "fy"),
                       input_matrix_fn=lambda q: np.eye(2))  # fmt: skip
    trk = Tracker(fm, np.zeros(2))
    prog = _engine.program_for(fm)
    assert prog is None or _compiled(trk, fm) is None


# ----------------------------------------------------------------------------- regulator σ > 0


@pytest.mark.filterwarnings("ignore:Regulator\\(sigma")
def test_regulator_sigma_compiled_equals_python() -> None:
    """Regulator(sigma > 0): the spring e + σ‖e‖η (η = q̇/‖q̇‖, or Pξ₀/‖Pξ₀‖ at rest) compiled;
    per call (at rest too) and over a run from rest, as the Python law."""
    model = crank_four_bar()
    target = crank_four_bar_configuration(model, 1.4)
    q0 = crank_four_bar_configuration(model, 0.6)

    def make() -> Regulator:
        return Regulator(model, target=target, Kp=200.0, Kd=30.0, sigma=0.5)

    states = _states(model, q0, np.array([0.0, 0.1]), np.random.default_rng(2))
    states.append((0.0, q0, np.zeros(model.n)))
    c = _compiled(make(), model)
    assert type(c).__name__ == "SimControl"
    prog = _engine.program_for(model)
    act = model.resolve_active(None)
    for t, q, qd in states:
        got = np.asarray(c.probe(prog, t, q, qd, _mask(model, act))["u"])
        with use_backend("numpy"):
            want = make().info(t, q, qd, active=act).u
        assert float(np.max(np.abs(got - want))) <= 1e-10 * max(1.0, float(np.max(np.abs(want))))
    a, b = _pair(model, make, t_span=(0.0, 0.3), q0=q0, dt=2e-3)
    _close(a, b)
    assert float(np.max(np.abs(a.u))) > 1.0
