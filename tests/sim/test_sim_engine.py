"""The engine's loop (simulate(engine="engine")) against the general driver on the NumPy
reference kernels: same steps, same samples, same diagnostics to round-off; coverage, handover
of failures, callbacks (Python models, controllers) and chunking."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from conftest import crossed_initial_state, make_crossed_four_bar, make_pendulum
from nonmin import library
from nonmin.control import Regulator
from nonmin.core import use_backend
from nonmin.errors import InputError, NotPositiveDefiniteError, SimulationError
from nonmin.model import FunctionModel
from nonmin.sim import RK4, Event, Projection, Reset, _engine, simulate


class _MyRK4(RK4):
    """A user's integrator: the general driver runs it."""


FIELDS = ("q", "qd", "qdd", "f_c", "energy", "mu", "cond", "phi_norm", "velocity_residual_norm")


def _pair(mech: Any, **kw: Any) -> tuple[Any, Any]:
    a = simulate(mech, engine="engine", progress=False, **kw)
    with use_backend("numpy"):  # the readable specification as the oracle
        b = simulate(mech, engine="python", progress=False, **kw)
    return a, b


def _close(a: Any, b: Any, tol: float = 1e-9, tol_acc: float = 1e-7, steps: bool = True) -> None:
    assert a.metadata["engine"] == "engine" and b.metadata["engine"] == "python"
    assert a.success and b.success, (a.message, b.message)
    assert len(a) == len(b)
    if steps:
        assert a.n_steps == b.n_steps
        np.testing.assert_array_equal(a.rank, b.rank)
    np.testing.assert_allclose(a.t, b.t, rtol=0, atol=1e-12 if steps else tol)
    np.testing.assert_array_equal(a.active_mask, b.active_mask)
    for f in (*FIELDS, "work"):  # (work: both drivers' quadrature with the method's own weights)
        x, y = getattr(a, f), getattr(b, f)
        scale = max(1.0, float(np.max(np.abs(y))))
        err = float(np.max(np.abs(x - y))) / scale
        assert err < (tol_acc if f in ("qdd", "f_c") else tol), (f, err)


MECHS = [("crossed_four_bar", {}), ("A02_n_four_bar", {"N": 2}), ("slider_crank", {}), ("five_bar", {}),
         ("A01_pendulum", {})]  # fmt: skip


@pytest.mark.parametrize(("name", "kw"), MECHS)
@pytest.mark.parametrize("sampled", [False, True])
def test_rk4_projection_equals_general_driver(name: str, kw: dict[str, int], sampled: bool) -> None:
    mech = library.get(name, **kw)
    # 150 steps through the crossed four-bar's change point (0.204 s) and on A02; 75 on the
    # smooth mechanisms (150 before: the general driver's runs are the test's cost)
    steps = 150 if name in ("crossed_four_bar", "A02_n_four_bar") else 75
    t1 = 0.3 if steps == 150 else 0.15
    te = np.linspace(0.0, t1, steps // 5 + 1) if sampled else None
    a, b = _pair(mech, t_span=(0.0, t1), dt=2e-3, t_eval=te)
    assert len(a) == (steps // 5 + 1 if sampled else steps + 1) and a.n_steps == steps
    _close(a, b)
    assert float(np.max(a.phi_norm)) < 1e-13


@pytest.mark.parametrize("name", ["slider_crank", "five_bar", "A01_pendulum"])
@pytest.mark.parametrize(
    "kw",
    [{"method": "midpoint", "dt": 2e-3}, {"method": "midpoint", "dt": 2e-3, "t_eval": np.linspace(0, 0.15, 16)},
     {"stabilization": "baumgarte", "dt": 2e-3}, {"stabilization": "none", "dt": 2e-3},
     {"stabilization": Projection(metric="euclidean"), "dt": 2e-3, "t_eval": np.linspace(0, 0.15, 9)}],
)  # fmt: skip
def test_methods_and_stabilizations_equal_general_driver(name: str, kw: dict[str, Any]) -> None:
    # 75 steps (0.3 s before): the 15 cases' general-driver runs were the module's largest cost
    a, b = _pair(library.get(name), t_span=(0.0, 0.15), **kw)
    assert a.n_steps == 75
    _close(a, b)


def test_midpoint_through_a_singular_configuration_with_rank_rtol() -> None:
    a, b = _pair(library.get("A02_n_four_bar", N=2), t_span=(0.0, 0.3), method="midpoint", dt=2e-3,
                 rank_rtol=1e-5)  # fmt: skip
    _close(a, b)


@pytest.mark.parametrize("name", ["slider_crank", "five_bar", "A01_pendulum", "crossed_four_bar"])
@pytest.mark.parametrize("sampled", [False, True])
def test_dopri5_equals_general_driver(name: str, sampled: bool) -> None:
    """DOPRI5's error is measured on projected solutions, a difference of two projections at
    their round-off floor: the step sizes of two implementations of the same arithmetic differ
    at that level (the general driver on its numba and NumPy kernels differs as much), so the
    comparison is to the method's tolerance, not to round-off."""
    mech = library.get(name)
    te = np.linspace(0.0, 0.3, 31) if sampled else None
    a, b = _pair(mech, t_span=(0.0, 0.3), method="dopri5", t_eval=te)
    assert abs(a.n_steps - b.n_steps) <= 1
    if sampled:
        _close(a, b, tol=1e-5, tol_acc=1e-4, steps=False)
    else:  # the step sequences drift apart (t by up to ~1e-5 s here): both are the motion
        assert abs(len(a) - len(b)) <= 1 and a.t[-1] == b.t[-1] == 0.3
    for tr in (a, b):
        ref = simulate(mech, (0.0, 0.3), method="rk4", dt=1e-4, t_eval=tr.t, engine="engine", progress=False)
        assert float(np.max(np.abs(tr.q - ref.q))) < 1e-6


def test_python_model_runs_through_the_callback() -> None:
    """A FunctionModel has no compiled program: the engine evaluates it through PyProgram."""
    model = make_crossed_four_bar()
    assert type(_engine.program_for(model)).__name__ == "PyProgram"
    q0, qd0 = crossed_initial_state()
    a, b = _pair(model, t_span=(0.0, 0.5), q0=q0, qd0=qd0, dt=2e-3)
    _close(a, b)
    pend = make_pendulum()
    a, b = _pair(pend, t_span=(0.0, 0.5), q0=[1.0, 0.0], method="dopri5", t_eval=np.linspace(0, 0.5, 11))
    _close(a, b, tol=1e-7, tol_acc=1e-6, steps=False)


def test_python_controller_through_the_callback() -> None:
    mech = library.get("five_bar")
    gain = np.array([3.0, -2.0])

    def ctrl(t: float, q: Any, qd: Any, state: Any = None, *, active: Any = None) -> Any:
        return gain * np.cos(5.0 * t) - 0.5 * qd[[0, 6]]

    a, b = _pair(mech, t_span=(0.0, 0.3), dt=2e-3, controller=ctrl)
    _close(a, b)
    assert float(np.max(np.abs(a.u))) > 1.0  # the controller acted, and u is recorded


@pytest.mark.parametrize("kw", [{"dt": 2e-3}, {"dt": 2e-3, "u_max": 3.0}, {"method": "dopri5"}])
def test_regulator_compiled_equals_the_python_regulator(kw: dict[str, Any]) -> None:
    """The Regulator runs compiled in the loop (no Python per evaluation): the same u (with
    saturation) as the Python controller in the general driver."""
    kw = dict(kw)
    lim = kw.pop("u_max", None)
    mech = library.get("five_bar")
    target = library.get("five_bar", end_effector=(0.2, 1.4)).state.q

    def reg() -> Regulator:
        return Regulator(mech.model, target=target, Kp=400.0, Kd=40.0, u_max=lim,
                         u_min=None if lim is None else -lim)  # fmt: skip

    prog = _engine.program_for(mech.model)
    assert type(_engine.compiled_controller(reg(), mech.model, prog, mech.state.active)).__name__ == "SimControl"
    # 0.25 s (125 RK4 steps; 0.5 s before): the general driver's run is the test's cost
    a = simulate(mech, (0.0, 0.25), controller=reg(), engine="engine", progress=False, **kw)
    with use_backend("numpy"):
        b = simulate(mech, (0.0, 0.25), controller=reg(), engine="python", progress=False, **kw)
    if "dt" in kw:
        _close(a, b)
        np.testing.assert_allclose(a.u, b.u, rtol=0, atol=1e-12 * float(np.max(np.abs(b.u))))
    else:
        _close(a, b, tol=1e-7, tol_acc=1e-6, steps=False)
    if lim is not None:
        assert float(np.max(np.abs(a.u))) == lim  # saturated


def test_compiled_regulator_state_is_the_python_record() -> None:
    """merge_state over the compiled steps = ControlState.record over the same steps."""
    mech = library.get("five_bar")
    target = library.get("five_bar", end_effector=(0.2, 1.4)).state.q
    ctl = Regulator(mech.model, target=target, Kp=400.0, Kd=40.0, u_min=-2.0, u_max=2.0)
    prog = _engine.program_for(mech.model)
    creg = _engine.compiled_controller(ctl, mech.model, prog, mech.state.active)
    eng = _engine._engine()
    opts = _engine.options(RK4(), Projection(), dt=2e-3, t1=0.1, h0=0.0, rank_rtol=None, drift_factor=1.0,
                           project_initial=True, max_steps=1000)  # fmt: skip
    loop = eng.SimLoop(prog, mech.model.active_mask(mech.state.active), opts, np.zeros(0), True, None, None,
                       None, [], creg)  # fmt: skip
    assert loop.start(0.0, mech.state.q, mech.state.qd) == eng.SIM_DONE
    assert loop.run(100) == eng.SIM_DONE
    rec = loop.take()
    got = _engine.merge_state(ctl, ctl.initial_state(), creg)
    want = ctl.initial_state()
    for t, q, qd in zip(rec["t"][1:], rec["q"][1:], rec["qd"][1:], strict=True):
        want = ctl.update(t, q, qd, want, active=mech.state.active)
    assert got.steps == want.steps == 50
    assert got.saturated_steps == want.saturated_steps and got.saturated == want.saturated
    assert got.infeasible_steps == want.infeasible_steps
    assert abs(got.min_sigma_pb - want.min_sigma_pb) <= 1e-12 * want.min_sigma_pb
    np.testing.assert_allclose(got.max_abs_u, want.max_abs_u, rtol=1e-12)


def test_chunking_is_deterministic(monkeypatch: pytest.MonkeyPatch) -> None:
    mech = library.get("crossed_four_bar")
    a = simulate(mech, (0.0, 0.4), dt=1e-3, engine="engine", progress=False)
    monkeypatch.setattr(_engine, "CHUNK_SECONDS", 1e-9)  # the smallest chunks (16 steps)
    b = simulate(mech, (0.0, 0.4), dt=1e-3, engine="engine", progress=False)
    for f in ("t", "q", "qd", "qdd", "f_c", "cond", "energy"):
        np.testing.assert_array_equal(getattr(a, f), getattr(b, f))


def test_max_steps_hands_over_and_raises_as_the_general_driver() -> None:
    mech = library.get("crossed_four_bar")
    kw: dict[str, Any] = {"method": "dopri5", "max_steps": 7, "engine": "engine", "progress": False}
    with pytest.raises(SimulationError, match="max_steps = 7 reached"):
        simulate(mech, (0.0, 1.0), **kw)
    tr = simulate(mech, (0.0, 1.0), throw=False, **kw)
    assert not tr.success and tr.n_steps == 7 and len(tr) == 8
    assert tr.metadata["engine"].startswith("engine, then python from t = ")


def test_kernel_failure_raises_the_typed_error() -> None:
    """A coordinate without inertia that no constraint fixes: M̄ is singular at the start."""
    model = FunctionModel(
        name="massless", coordinate_names=("x", "y"), mass=lambda q: np.diag([1.0, 0.0]),
        coriolis=lambda q, qd: np.zeros((2, 2)), conservative=lambda q: [0.0, -1.0],
        potential=lambda q: q[1],
    )  # fmt: skip
    with pytest.raises(NotPositiveDefiniteError):
        simulate(model, 0.1, [0.0, 0.0], engine="engine", progress=False)


def test_callback_exception_propagates() -> None:
    class Boom(RuntimeError):
        pass

    def mass(q: Any) -> Any:
        if q[1] < -0.1:
            raise Boom("model failed")
        return np.eye(2)

    model = FunctionModel(
        name="boom", coordinate_names=("x", "y"), mass=mass, coriolis=lambda q, qd: np.zeros((2, 2)),
        conservative=lambda q: [0.0, -9.81], potential=lambda q: 9.81 * q[1],
    )  # fmt: skip
    # a user function's exception becomes a SimulationError naming it and the time (issue 19);
    # the original exception stays reachable through the cause chain
    with pytest.raises(SimulationError, match=r"mass raised Boom.*|t = .*mass raised Boom") as info:
        simulate(model, 1.0, [0.0, 0.0], engine="engine", progress=False)
    assert "t = " in str(info.value)
    cause: BaseException | None = info.value
    while cause is not None and not isinstance(cause, Boom):
        cause = cause.__cause__
    assert isinstance(cause, Boom)
    tr = simulate(model, 1.0, [0.0, 0.0], engine="engine", progress=False, throw=False)
    assert not tr.success and "Boom" in tr.message


def _bottom(t: float, q: Any, qd: Any, f_c: Any) -> float:
    return float(q[0])


@pytest.mark.parametrize("kw", [{"dt": 1e-3}, {"method": "dopri5", "rtol": 1e-10, "atol": 1e-12}])
def test_events_located_by_the_general_driver_between_engine_steps(kw: dict[str, Any]) -> None:
    """The engine watches the guards at every step end; the step where one crosses is taken by
    the general driver (location, transition), then the engine goes on."""
    tick = Event(lambda t, q, qd, fc: t - 0.25, direction=1, name="tick")
    bottom = Event(_bottom, direction=0, name="bottom")
    reset = Event(lambda t, q, qd, fc: t - 0.6, direction=1, name="kick",
                  transition=Reset(lambda t, q, qd, act: (q, 1.1 * qd, act)))  # fmt: skip
    # to 0.7 s: 0.1 s past the kick (0.9 s before; the next event, a bottom crossing, is after
    # 1.5 s; the bottom is crossed at 0.592 s)
    a, b = _pair(make_pendulum(), t_span=(0.0, 0.7), q0=[1.0, 0.0], events=[tick, bottom, reset], **kw)
    assert [e.name for e in a.events] == [e.name for e in b.events] == ["tick", "bottom", "kick"]
    np.testing.assert_allclose([e.t for e in a.events], [e.t for e in b.events], atol=1e-12)
    if "dt" in kw:
        _close(a, b)
    else:  # (DOPRI5's step sizes differ at the projected error's round-off: see above)
        _close(a, b, tol=1e-6, tol_acc=1e-5, steps=False)


def test_unilateral_contact_impact_and_release_on_the_engine() -> None:
    mech = library.get("arm2r_wall")
    u_amp = np.array([10.0, -6.0])

    def ctrl(t: float, q: Any, qd: Any, state: Any = None, *, active: Any = None) -> Any:
        return u_amp * np.cos(2.0 * t)

    a, b = _pair(mech, t_span=(0.0, 0.45), dt=1e-3, controller=ctrl)
    assert [e.name for e in a.events] == [e.name for e in b.events] == ["impact:wall", "release:wall"]
    np.testing.assert_allclose([e.t for e in a.events], [e.t for e in b.events], atol=1e-11)
    _close(a, b, tol=1e-8, tol_acc=1e-6)


def test_engine_coverage_and_auto_choice() -> None:
    mech = library.get("crossed_four_bar")
    ev = Event(lambda t, q, qd, fc: t - 0.005, name="tick")
    assert simulate(mech, 0.01, events=[ev], progress=False).metadata["engine"] == "engine"
    with pytest.raises(InputError, match="engine='engine' cannot run this simulation: method"):
        simulate(mech, 0.01, method=_MyRK4(dt=1e-3), engine="engine", progress=False)
    assert simulate(mech, 0.01, method="dopri5", progress=False).metadata["engine"] == "engine"
    assert simulate(mech, 0.01, stabilization="baumgarte", progress=False).metadata["engine"] == "engine"
    with use_backend("numpy"):  # the NumPy reference kernels asked for: the general driver
        assert simulate(mech, 0.01, method="dopri5", progress=False).metadata["engine"] == "python"
