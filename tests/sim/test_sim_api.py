"""simulate() boundary: Trajectory fields, save/load, CSV, throw=False, bad inputs, mechanisms."""

from __future__ import annotations

import json
from dataclasses import dataclass

import numpy as np
import pytest

import nonmin.sim as sim
from conftest import make_ball, make_pendulum
from nonmin.errors import (
    InputError,
    NotPositiveDefiniteError,
    ShapeError,
    SimulationError,
    UnknownNameError,
)
from nonmin.model import FunctionModel, State
from nonmin.sim import (
    RK4,
    Activate,
    Event,
    Status,
    Trajectory,
    load_trajectory,
    simulate,
)


def test_public_api_is_pinned() -> None:
    assert set(sim.__all__) == {
        "ADAPTIVE_RANK_RTOL", "DEFAULT_DT", "METHODS", "RK4", "RK8", "STABILIZATIONS", "Activate", "Baumgarte", "Deactivate",
        "DOP853", "DormandPrince5", "Event", "EventRecord", "ImplicitMidpoint", "Integrator",
        "NoStabilization", "Projection", "Reset", "Stabilization", "Status", "StepResult",
        "StepperState", "Trajectory", "load_trajectory", "simulate",
        "Solver", "EventSet", "Output", "check_model", "ModelReport", "CheckItem",
        "BatchTrajectory", "simulate_batch", "ContactState", "friction_state",
    }
    assert set(sim.METHODS) == {"rk4", "rk8", "dopri5", "dop853", "midpoint"}
    assert set(sim.STABILIZATIONS) == {"none", "baumgarte", "projection"}


def test_trajectory_fields_and_immutability() -> None:
    model = make_pendulum()
    tr = simulate(model, (0.0, 0.5), [1.0, 0.0], dt=0.01)
    N = len(tr)
    assert N == 51
    assert tr.q.shape == tr.qd.shape == tr.qdd.shape == tr.f_c.shape == (N, 2)
    assert tr.u.shape == (N, 0)
    assert tr.active_mask.shape == (N, 1) and tr.active_mask.all()
    assert tr.active[0] == frozenset({"rod"})
    for name in ("rank", "cond", "mu", "energy", "phi_norm", "velocity_residual_norm"):
        assert getattr(tr, name).shape == (N,)
    assert np.all(tr.rank == 1)
    assert np.all(tr.cond >= 1.0)
    assert tr.n_steps == 50 and tr.n_rhs >= 4 * 50 and tr.n_rejected == 0
    assert tr.status is Status.SUCCESS
    assert tr.metadata["model"]["name"] == "pendulum"
    # the constraint force of the rod is radial: f_c ∥ q
    cross = tr.f_c[:, 0] * tr.q[:, 1] - tr.f_c[:, 1] * tr.q[:, 0]
    assert np.max(np.abs(cross)) < 1e-9
    with pytest.raises(ValueError):
        tr.q[0, 0] = 3.0
    with pytest.raises(AttributeError):
        tr.status = Status.FAILED  # type: ignore[misc]


def test_save_load_round_trip(tmp_path) -> None:  # type: ignore[no-untyped-def]
    model = make_ball()
    tr = simulate(model, (0.0, 0.7), [0.0, 1.0], [0.2, 0.0], dt=1e-3, restitution=0.5)
    assert tr.events
    path = tmp_path / "ball.npz"
    tr.save(path)
    back = load_trajectory(path)
    assert Trajectory.load(path).n_steps == tr.n_steps
    for name in ("t", "q", "qd", "qdd", "f_c", "u", "active_mask", "rank", "cond", "mu", "energy",
                 "phi_norm", "velocity_residual_norm"):
        assert np.array_equal(getattr(back, name), getattr(tr, name)), name
    assert [e.to_dict() for e in back.events] == [e.to_dict() for e in tr.events]
    assert back.status is tr.status and back.message == tr.message
    assert back.constraint_names == tr.constraint_names
    assert back.coordinate_names == tr.coordinate_names
    assert back.metadata["nonmin_version"]
    assert back.metadata["options"]["restitution"] == 0.5
    assert back.metadata["model"]["constraints"][0]["kind"] == "unilateral"
    # self-describing: plain npz with a JSON entry, no pickles
    with np.load(path, allow_pickle=False) as raw:
        meta = json.loads(str(raw["__metadata__"]))
    assert meta["format"] == "nonmin.Trajectory"


def test_load_rejects_foreign_files(tmp_path) -> None:  # type: ignore[no-untyped-def]
    p = tmp_path / "x.npz"
    np.savez(p, a=np.zeros(3))
    with pytest.raises(InputError, match="metadata"):
        load_trajectory(p)
    with pytest.raises(InputError):
        load_trajectory(tmp_path / "missing.npz")


def test_to_csv_and_outputs(tmp_path) -> None:  # type: ignore[no-untyped-def]
    model = make_pendulum().replace(outputs_fn=lambda t, q, qd: {"r": np.array([np.hypot(*q)])})
    tr = simulate(model, (0.0, 0.1), [1.0, 0.0], dt=0.01)
    p = tmp_path / "pend.csv"
    tr.to_csv(p)
    data = np.loadtxt(p, delimiter=",", skiprows=1)
    assert data.shape == (len(tr), 1 + 4 * 2 + 6 + 3 + 1)  # (+ friction_work, impact_loss, work)
    assert np.array_equal(data[:, 0], tr.t)
    header = p.read_text().splitlines()[0].split(",")
    assert header[0] == "t" and "q_x" in header and "active_rod" in header
    out = tr.outputs(model)
    assert out["r"].shape == (len(tr), 1)
    assert np.allclose(out["r"], 1.0, atol=1e-12)


def test_t_eval_samples_exactly_there() -> None:
    t_eval = np.array([0.0, 0.0123, 0.5, 0.777])
    tr = simulate(make_pendulum(), (0.0, 0.8), [1.0, 0.0], dt=0.01, t_eval=t_eval)
    assert np.array_equal(tr.t, t_eval)
    full = simulate(make_pendulum(), (0.0, 0.8), [1.0, 0.0], dt=0.0123 / 2)
    # a partial RK4 step from the step start is an RK4 solution too: agrees to the global error
    i = int(np.argmin(np.abs(full.t - 0.0123)))
    assert np.allclose(tr.q[1], full.q[i], atol=1e-8)


def _collapsing_mass_model() -> FunctionModel:
    """A free particle whose inertia vanishes at x = 0.5: M̄ stops being positive definite."""
    return FunctionModel(
        name="collapse",
        coordinate_names=("x",),
        mass=lambda q: np.array([[max(0.5 - q[0], 0.0)]]),
        coriolis=lambda q, qd: np.zeros((1, 1)),
        conservative=lambda q: [0.0],
        potential=lambda q: 0.0,
    )


def test_throw_false_returns_the_partial_trajectory() -> None:
    model = _collapsing_mass_model()
    with pytest.raises(NotPositiveDefiniteError):
        simulate(model, (0.0, 1.0), [0.0], [1.0], dt=0.01, stabilization="none")
    tr = simulate(model, (0.0, 1.0), [0.0], [1.0], dt=0.01, stabilization="none", throw=False)
    assert tr.status is Status.FAILED
    assert not tr.success
    assert "NotPositiveDefiniteError" in tr.message
    assert 0.4 < tr.t[-1] < 0.5
    assert len(tr) > 10


def test_max_steps_and_step_underflow_fail_cleanly() -> None:
    # a fixed-step run that needs more than max_steps is refused before it starts
    with pytest.raises(InputError, match="max_steps"):
        simulate(make_pendulum(), (0.0, 1.0), [1.0, 0.0], dt=0.01, max_steps=5)
    with pytest.raises(InputError, match="max_steps"):
        simulate(make_pendulum(), (0.0, 1.0), [1.0, 0.0], dt=0.01, max_steps=5, throw=False)
    # an adaptive one stops when it reaches max_steps (its step count is not known up front)
    with pytest.raises(SimulationError, match="max_steps"):
        simulate(make_pendulum(), (0.0, 1.0), [1.0, 0.0], method="dopri5", max_steps=5)
    tr = simulate(make_pendulum(), (0.0, 1.0), [1.0, 0.0], method="dopri5", max_steps=5, throw=False)
    assert tr.status is Status.FAILED and len(tr) == 6


@dataclass(frozen=True)
class _Mech:
    model: FunctionModel
    state: State


def test_mechanism_supplies_the_initial_state() -> None:
    model = make_pendulum()
    mech = _Mech(model, model.state([0.0, -1.0], [1.0, 0.0]))
    tr = simulate(mech, (0.0, 0.1), dt=0.01)
    assert np.array_equal(tr.q[0], [0.0, -1.0]) and np.array_equal(tr.qd[0], [1.0, 0.0])
    tr2 = simulate(mech, (0.0, 0.1), [1.0, 0.0], dt=0.01)  # explicit q0 wins
    assert np.array_equal(tr2.q[0], [1.0, 0.0])


def test_controller_protocol_is_used() -> None:
    from nonmin.control import Controller

    class Count(Controller):
        def initial_state(self) -> int:
            return 0

        def __call__(self, t, q, qd, state=None, *, active=None):  # type: ignore[no-untyped-def]
            return np.zeros(0)

        def update(self, t, q, qd, state, *, active=None):  # type: ignore[no-untyped-def]
            return state + 1

    calls: list[int] = []

    class Spy(Count):
        def __call__(self, t, q, qd, state=None, *, active=None):  # type: ignore[no-untyped-def]
            calls.append(state)
            return np.zeros(0)

    simulate(make_pendulum(), (0.0, 0.05), [1.0, 0.0], dt=0.01, controller=Spy())
    assert calls[0] == 0 and max(calls) == 4  # state advanced once per accepted step


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        ({"q0": [1.0, 0.0, 0.0]}, ShapeError, r"q0 must have shape \(2,\)"),
        ({"qd0": [[0.0, 0.0]]}, ShapeError, "qd0"),
        ({"q0": [np.nan, 0.0]}, InputError, "finite"),
        ({"t_span": (1.0, 0.5)}, InputError, "increasing"),
        ({"t_span": (0.0, 1.0, 2.0)}, ShapeError, "t_span"),
        ({"active": ["nope"]}, UnknownNameError, "nope"),
        ({"method": "euler"}, UnknownNameError, "dopri5"),
        ({"stabilization": "magic"}, UnknownNameError, "projection"),
        ({"dt": -1.0}, InputError, "dt"),
        ({"restitution": 2.0}, InputError, "restitution"),
        ({"bogus": 1}, InputError, "bogus"),
        ({"events": [Event(lambda t, q, qd, f: q[0], transition=Activate("wall"))]}, UnknownNameError, "wall"),
        ({"events": ["not an event"]}, InputError, "Event"),
        ({"t_eval": [0.5, 0.1]}, InputError, "t_eval"),
        ({"method": 3}, InputError, "Integrator"),
    ],
)
def test_bad_inputs_raise_typed_errors(kwargs: dict, error: type, match: str) -> None:
    args = {"t_span": (0.0, 1.0), "q0": [1.0, 0.0]}
    args.update(kwargs)
    t_span, q0 = args.pop("t_span"), args.pop("q0")
    with pytest.raises(error, match=match):
        simulate(make_pendulum(), t_span, q0, **args)


def test_integrator_objects_are_accepted() -> None:
    tr = simulate(make_pendulum(), (0.0, 0.1), [1.0, 0.0], method=RK4(dt=0.02))
    assert tr.n_steps == 5


def test_plot_delegates_to_viz() -> None:
    pytest.importorskip("matplotlib")
    import matplotlib

    matplotlib.use("Agg")
    tr = simulate(make_ball(), (0.0, 0.6), [0.0, 1.0], dt=0.01, restitution=0.5)
    fig = tr.plot(title="ball")
    assert fig.__class__.__name__ == "Figure"
    import matplotlib.pyplot as plt

    plt.close(fig)


def test_progress_output_only_when_asked(capsys) -> None:  # type: ignore[no-untyped-def]
    simulate(make_pendulum(), (0.0, 0.05), [1.0, 0.0], dt=0.01, progress=False)
    assert capsys.readouterr().err == ""
    simulate(make_pendulum(), (0.0, 0.05), [1.0, 0.0], dt=0.01)  # auto: stderr is not a TTY here
    assert capsys.readouterr().err == ""
    simulate(make_pendulum(), (0.0, 0.05), [1.0, 0.0], dt=0.01, progress=True)
    assert capsys.readouterr().err != ""


@pytest.mark.parametrize(
    ("kw", "err", "words"),
    [
        ({"q0": "complex"}, "InputError", ["q0", "complex"]),
        ({"q0": "bool"}, "InputError", ["q0", "booleans"]),
        ({"qd0": "text"}, "ShapeError", ["qd0", "9 numbers"]),
        ({"q0": "batch"}, "ShapeError", ["q0", "(2, 9)", "simulate_batch"]),
    ],
)
def test_simulate_refuses_non_real_initial_states(kw, err, words):  # type: ignore[no-untyped-def]
    """q0/qd0 given as complex, booleans or text ran silently (NumPy's casts); (k, n) hints the batch."""
    import warnings

    import nonmin
    from nonmin import errors

    mech = nonmin.library.get("crossed_four_bar")
    q, qd = mech.state.q, mech.state.qd
    make = {"complex": q + 1e-3j, "bool": q.astype(bool), "text": [str(v) for v in qd], "batch": np.stack([q, q])}
    args = {"q0": q, "qd0": qd}
    for k, v in kw.items():
        args[k] = make[v]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(getattr(errors, err)) as info:
            nonmin.simulate(mech.model, 0.01, args["q0"], args["qd0"], dt=1e-3)
    for w in words:
        assert w in str(info.value), str(info.value)


def test_a_controller_with_the_wrong_signature_is_told_the_call() -> None:
    """``controller=lambda t, q, qd: tau`` (Pinocchio/MuJoCo habit) said only "unexpected keyword
    argument 'active'"; the error now states how simulate calls a controller."""
    import nonmin

    mech = nonmin.library.get("five_bar")
    k = len(mech.model.actuator_names)
    with pytest.raises(SimulationError) as info:
        nonmin.simulate(mech, 0.01, dt=1e-3, controller=lambda t, q, qd: np.zeros(k))
    msg = str(info.value)
    assert "controller(t, q, qd, state, *, active)" in msg and "active" in msg
    # a controller that takes the call but fails inside keeps the plain message
    with pytest.raises(SimulationError, match=r"controller raised TypeError: inside \(at t = 0\)"):
        nonmin.simulate(mech, 0.01, dt=1e-3, controller=lambda t, q, qd, s, active: (_ for _ in ()).throw(TypeError("inside")))
    traj = nonmin.simulate(mech, 0.01, dt=1e-3, controller=lambda t, q, qd, state=None, **kw: np.zeros(k))
    assert traj.success
