"""The compiled engine of simulate(): same results as the general driver, eligibility, handover."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from nonmin import library
from nonmin.core import use_backend
from nonmin.errors import InputError
from nonmin.model.planar import PlanarBuilder, PlanarProgram
from nonmin.sim import Event, Reset, _fastpath, simulate

pytest.importorskip("numba")

FIELDS = ("q", "qd", "qdd", "f_c", "energy", "mu", "cond", "phi_norm", "velocity_residual_norm")


def _both(mech: object, **kw: object) -> tuple[object, object]:
    a = simulate(mech, engine="compiled", progress=False, **kw)  # type: ignore[arg-type]
    b = simulate(mech, engine="python", progress=False, **kw)  # type: ignore[arg-type]
    return a, b


@pytest.mark.parametrize(
    ("name", "kw"),
    [("crossed_four_bar", {}), ("A02_n_four_bar", {"N": 2}), ("slider_crank", {}), ("five_bar", {}),
     ("A01_pendulum", {})],
)  # fmt: skip
@pytest.mark.parametrize("sampled", [False, True])
def test_compiled_equals_general_driver(name: str, kw: dict[str, int], sampled: bool) -> None:
    mech = library.get(name, **kw)
    te = np.linspace(0.0, 0.3, 31) if sampled else None
    a, b = _both(mech, t_span=(0.0, 0.3), dt=2e-3, t_eval=te)
    assert a.metadata["engine"] == "compiled" and b.metadata["engine"] == "python"
    assert a.success and b.success
    assert len(a) == len(b) == (31 if sampled else 151)
    np.testing.assert_array_equal(a.t, b.t)
    np.testing.assert_array_equal(a.rank, b.rank)
    np.testing.assert_array_equal(a.active_mask, b.active_mask)
    assert a.n_steps == b.n_steps == 150
    scale = {f: max(1.0, float(np.max(np.abs(getattr(b, f))))) for f in FIELDS}
    for f in FIELDS:  # round-off apart (qdd near a change point is the most sensitive)
        err = float(np.max(np.abs(getattr(a, f) - getattr(b, f)))) / scale[f]
        assert err < (1e-7 if f in ("qdd", "f_c") else 1e-9), (f, err)
    assert float(np.max(a.phi_norm)) < 1e-13


def test_compiled_chunking_is_deterministic(monkeypatch: pytest.MonkeyPatch) -> None:
    """The warm-start state is carried between chunks: any split gives bitwise the same run."""
    mech = library.get("crossed_four_bar")
    a = simulate(mech, (0.0, 0.6), dt=1e-3, engine="compiled", progress=False)
    monkeypatch.setattr(_fastpath, "CHUNK_SECONDS", 1e-9)  # the smallest chunks (16 steps)
    b = simulate(mech, (0.0, 0.6), dt=1e-3, engine="compiled", progress=False)
    for f in ("q", "qd", "qdd", "f_c", "cond", "energy"):
        np.testing.assert_array_equal(getattr(a, f), getattr(b, f))


def test_compiled_keeps_the_crossed_four_bar_on_its_branch() -> None:
    """A stretch with change points (flat configurations) at a coarse step, against the exact
    branch solution the library ships."""
    mech = library.get("crossed_four_bar")
    te = np.linspace(0.0, 2.5, 251)
    tr = simulate(mech, (0.0, 2.5), dt=5e-3, t_eval=te, engine="compiled", progress=False)
    assert tr.metadata["engine"] == "compiled"
    assert float(np.max(tr.phi_norm)) < 1e-13
    assert float(np.max(np.abs(tr.energy - tr.energy[0]))) < 0.05
    ref = library.crossed_four_bar_reference(te)
    # the crank turns through θ = kπ (the flat, singular configurations) five times
    assert int(np.sum(np.diff(np.floor(ref["theta"] / np.pi)) != 0)) == 5
    assert float(np.max(np.abs(tr.q - ref["q"]))) < 0.05


def test_auto_engine_choice() -> None:
    """"auto" runs the engine wherever it covers the run; the numba loop only when asked."""
    mech = library.get("crossed_four_bar")
    assert simulate(mech, 0.01, progress=False).metadata["engine"] == "engine"
    assert simulate(mech, 0.01, engine="compiled", progress=False).metadata["engine"] == "compiled"
    assert simulate(mech, 0.01, method="dopri5", progress=False).metadata["engine"] == "engine"
    assert simulate(mech, 0.01, stabilization="baumgarte", progress=False).metadata["engine"] == "engine"
    with use_backend("numpy"):
        assert simulate(mech, 0.01, progress=False).metadata["engine"] == "python"
    big = library.get("A02_n_four_bar", N=40)
    assert simulate(big, 0.002, progress=False).metadata["engine"] == "engine"
    assert simulate(big, 0.002, engine="compiled", progress=False).metadata["engine"] == "compiled"
    # n = 75 and 73 degrees of freedom (> AUTO_NUMBA_MAX_N): the numba loop declines on 'auto'
    b = PlanarBuilder("loose")
    for i in range(25):
        b.body(f"bar{i}", mass=1.0, inertia=0.1)
    b.revolute("pin", ("ground", (0.0, 0.0)), ("bar0", (-0.5, 0.0)))
    loose = b.build()
    q0 = np.zeros(loose.n)
    q0[0] = 0.5
    assert simulate(loose, 0.002, q0, progress=False).metadata["engine"] == "engine"
    with pytest.raises(InputError, match="degrees of freedom"):
        simulate(loose, 0.002, q0, engine="compiled", progress=False)
    with use_backend("numba"):  # forced
        assert simulate(loose, 0.002, q0, engine="compiled", progress=False).metadata["engine"] == "compiled"
    wall = library.get("arm2r_wall")  # unilateral contact: the engine (events located in Python)
    assert simulate(wall, 0.01, progress=False).metadata["engine"] == "engine"
    assert simulate(wall, 0.01, contact=False, engine="compiled", progress=False).metadata["engine"] == "compiled"


def _spring_model() -> object:
    b = PlanarBuilder("sprung")
    b.body("bar", mass=1.0, inertia=0.1)
    b.revolute("pin", ("ground", (0.0, 0.0)), ("bar", (-0.5, 0.0)))
    b.rotational_spring("k", "ground", "bar", stiffness=3.0)
    return b.build()


@pytest.mark.parametrize(
    ("kw", "needle"),
    [({"method": "dopri5"}, "method must be 'rk4'"),
     ({"stabilization": "none"}, "stabilization must be the mass-metric"),
     ({"events": (Event(lambda t, q, qd, fc: t - 1.0, transition=Reset(lambda t, q, qd, a: (q, qd, a))),)},
      "events are given"),
     ({"controller": lambda t, q, qd, s, active=None: np.zeros(0)}, "a controller is given")],
)  # fmt: skip
def test_compiled_engine_names_what_prevents_it(kw: dict[str, object], needle: str) -> None:
    mech = library.get("crossed_four_bar")
    with pytest.raises(InputError, match=needle):
        simulate(mech, 0.01, engine="compiled", progress=False, **kw)  # type: ignore[arg-type]


def test_compiled_engine_refusals_for_model_backend_and_name() -> None:
    model = _spring_model()
    assert model.fast_program(model.default_active) is None  # type: ignore[attr-defined]
    with pytest.raises(InputError, match="no compiled program"):
        simulate(model, 0.01, np.array([0.5, 0.0, 0.0]), engine="compiled", progress=False)
    mech = library.get("crossed_four_bar")
    with use_backend("numpy"), pytest.raises(InputError, match="backend is 'numpy'"):
        simulate(mech, 0.01, engine="compiled", progress=False)
    with pytest.raises(InputError, match="engine must be one of"):
        simulate(mech, 0.01, engine="fast", progress=False)


def test_program_describes_the_model() -> None:
    mech = library.get("slider_crank")
    prog = mech.model.fast_program(mech.state.active)
    assert isinstance(prog, PlanarProgram)
    assert prog.n == mech.model.n and prog.m == mech.model.num_rows(mech.state.active)
    np.testing.assert_array_equal(prog.M, mech.model.mass_matrix(mech.state.q))
    np.testing.assert_array_equal(prog.f, mech.model.conservative_force(mech.state.q))


def test_max_steps_is_refused_before_the_run_by_both_engines() -> None:
    # a fixed-step run needing more than max_steps steps is refused up front (issue 19), the
    # same way by both engines, whatever throw (it was a partial run stopped at max_steps)
    mech = library.get("crossed_four_bar")
    for engine in ("compiled", "python"):
        for throw in (True, False):
            with pytest.raises(InputError, match="max_steps = 40"):
                simulate(mech, 1.0, dt=1e-3, max_steps=40, engine=engine, throw=throw, progress=False)
    a = simulate(mech, 0.04, dt=1e-3, max_steps=40, engine="compiled", progress=False)
    b = simulate(mech, 0.04, dt=1e-3, max_steps=40, engine="python", progress=False)
    assert a.success and a.n_steps == b.n_steps == 40 and len(a) == len(b) == 41
    np.testing.assert_allclose(a.q, b.q, atol=1e-12)


@pytest.mark.filterwarnings("ignore:overflow")
def test_kernel_failure_hands_over_and_raises_the_same_error() -> None:
    """A state whose first RK4 stage overflows: the compiled loop stops before the step, the
    general driver takes over and raises exactly what it raises on its own."""
    mech = library.get("crossed_four_bar")
    qd = mech.state.qd * 1e150
    errs = []
    for engine in ("compiled", "python"):
        with pytest.raises(Exception) as info:
            simulate(mech, 0.01, mech.state.q, qd, dt=1e-3, engine=engine, progress=False,
                     project_initial=False)  # fmt: skip
        errs.append(info.value)
    assert type(errs[0]) is type(errs[1]) and str(errs[0]) == str(errs[1])
    part = simulate(mech, 0.01, mech.state.q, qd, dt=1e-3, engine="compiled", throw=False,
                    project_initial=False, progress=False)  # fmt: skip
    assert not part.success and "compiled, then python" in part.metadata["engine"]


def _mix_model() -> tuple[Any, Any]:
    """A planar model with every primitive kind, and an assembled state."""
    from nonmin.model import assemble

    b = PlanarBuilder("mix")
    b.body("bar", mass=1.0, inertia=0.1)
    b.body("wheel", mass=0.7, inertia=0.05)
    b.body("slider", mass=0.4, inertia=0.02)
    b.point_mass("ball", mass=0.5)
    b.revolute("pin", ("ground", (0.0, 0.0)), ("bar", (-0.5, 0.0)))
    b.revolute("axle", ("ground", (1.0, 0.0)), ("wheel", (0.0, 0.0)))
    b.gear("g", "bar", "wheel", ratio=-2.0)
    b.prismatic("slide", ("ground", (0.0, -1.0)), ("slider", (0.0, 0.0)), axis=(1.0, 0.0))
    b.rod("r", ("bar", (0.5, 0.0)), ("ball", (0.0, 0.0)), length=0.8)
    b.rod("r2", ("slider", (0.0, 0.0)), ("ball", (0.0, 0.0)), length=1.5)
    model = b.build()
    names = list(model.coordinate_names)
    q0 = np.zeros(model.n)
    for key, val in {"bar.x": 0.5, "wheel.x": 1.0, "slider.x": 1.0, "slider.y": -1.0,
                     "ball.x": 1.2, "ball.y": -0.3}.items():  # fmt: skip
        q0[names.index(key)] = val
    return model, assemble(model, q0)


def test_compiled_covers_every_primitive_kind() -> None:
    """Point mass, gear and prismatic (angle rows), point-on-line, rods: both engines agree."""
    model, st = _mix_model()
    assert isinstance(model.fast_program(st.active), PlanarProgram)
    a = simulate(model, (0.0, 0.5), st, dt=1e-3, engine="compiled", progress=False)
    c = simulate(model, (0.0, 0.5), st, dt=1e-3, engine="python", progress=False)
    assert a.metadata["engine"] == "compiled"
    np.testing.assert_array_equal(a.rank, c.rank)
    assert float(np.max(np.abs(a.q - c.q))) < 1e-12
    assert float(np.max(np.abs(a.energy - c.energy))) < 1e-10
    assert float(np.max(a.phi_norm)) < 1e-13


def test_evaluation_at_the_same_q_recomputes_only_gamma() -> None:
    """The compiled loop's evaluation at the ``q`` of its previous one (after a velocity
    correction) computes only γ: A, φ and γ are bitwise those of a fresh evaluation."""
    from nonmin.sim import _fast_kernels as kern

    model, st = _mix_model()
    prog = model.fast_program(st.active)
    pr = (prog.M, prog.f, prog.A0, prog.I6, prog.SL, prog.prm, prog.rows, prog.var_idx,
          prog.counts, prog.angle_rows, prog.G, prog.angle_const)  # fmt: skip
    rng = np.random.default_rng(7)
    q = st.q + 0.05 * rng.standard_normal(prog.n)  # off the constraints: φ ≠ 0
    qd1, qd2 = rng.standard_normal(prog.n), rng.standard_normal(prog.n)

    def fresh(qd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        ws = kern.carry(prog.n, prog.m, prog.I6.shape[1], prog.var_idx.shape[0], prog.A0, prog.var_idx,
                          prog.M)[0]
        kern._evaluate(pr, q, qd, ws)
        return ws[3].copy(), ws[2].copy()

    ws = kern.carry(prog.n, prog.m, prog.I6.shape[1], prog.var_idx.shape[0], prog.A0, prog.var_idx,
                          prog.M)[0]
    kern._evaluate(pr, q, qd1, ws)
    kern._evaluate(pr, q.copy(), qd2, ws)  # same q: γ only
    A_ref, PG_ref = fresh(qd2)
    assert np.array_equal(ws[3], A_ref) and np.array_equal(ws[2], PG_ref)
    assert np.any(PG_ref[0] != 0.0) and not np.array_equal(PG_ref[1], fresh(qd1)[1])
    q2 = q + 1e-3
    kern._evaluate(pr, q2, qd2, ws)  # a new q: everything again
    ws2 = kern.carry(prog.n, prog.m, prog.I6.shape[1], prog.var_idx.shape[0], prog.A0, prog.var_idx,
                          prog.M)[0]
    kern._evaluate(pr, q2, qd2, ws2)
    assert np.array_equal(ws[3], ws2[3]) and np.array_equal(ws[2], ws2[2])
