"""Turn a :class:`Scenario` into API calls: simulate it and write its outputs."""

from __future__ import annotations

import dataclasses
import inspect
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import NonminError, ScenarioError, UnknownNameError
from ._scenario import Scenario, resolve_entry_point

__all__ = ["ScenarioResult", "build_controller", "build_events", "run_scenario", "simulate_kwargs"]


def simulate_kwargs(sc: Scenario) -> dict[str, Any]:
    """Keywords for :func:`nonmin.sim.simulate` from the [simulate] table (validated)."""
    sim = sc.section("simulate")
    kw: dict[str, Any] = {}
    for key in ("method", "dt", "rtol", "atol", "stabilization", "contact", "restitution"):
        if key in sim:
            kw[key] = sim[key]
    extra = dict(sim.get("options", {}))
    overlap = set(extra) & set(kw)
    if overlap:
        raise ScenarioError(
            f"{sc.path}: keys {sorted(overlap)} given both in [simulate] and [simulate.options]"
        )
    kw.update(extra)
    from ..sim import simulate

    params = inspect.signature(simulate).parameters
    for key in kw:
        if key not in params:
            raise ScenarioError(
                f"{sc.path}: key 'simulate.options.{key}': not a keyword of nonmin.sim.simulate; "
                f"expected one of {sorted(k for k, v in params.items() if v.kind == v.KEYWORD_ONLY)}"
            )
    return kw


def build_controller(sc: Scenario, model: Any) -> Any:
    """The controller of the [controller] table, or None."""
    ctl = sc.section("controller")
    if not ctl:
        return None
    from .. import control

    name = ctl.pop("type")
    try:
        factory = control.get(name)
    except UnknownNameError as exc:
        raise ScenarioError(f"{sc.path}: key 'controller.type': {exc}") from None
    kwargs = {}
    for key, val in ctl.items():
        kwargs[key] = np.asarray(val, dtype=float) if isinstance(val, list) else val
    sig = inspect.signature(factory)
    accepts_var = any(p.kind == p.VAR_KEYWORD for p in sig.parameters.values())
    if not accepts_var:
        for key in kwargs:
            if key not in sig.parameters:
                raise ScenarioError(
                    f"{sc.path}: unknown key 'controller.{key}' for controller {name!r}; expected "
                    f"one of {sorted(p for p in sig.parameters if p != 'model')}"
                )
    try:
        return factory(model, **kwargs)
    except NonminError as exc:
        raise ScenarioError(f"{sc.path}: table [controller]: {exc}") from None
    except TypeError as exc:
        raise ScenarioError(f"{sc.path}: table [controller]: {exc}") from None


def build_events(sc: Scenario, model: Any) -> tuple[Any, ...]:
    """Events of the [[events]] tables."""
    from ..sim import Activate, Deactivate, Event

    out = []
    for i, ev in enumerate(sc.data.get("events", [])):
        key = f"events[{i}]"
        if ("at_time" in ev) == ("guard" in ev):
            raise ScenarioError(
                f"{sc.path}: table {key}: expected exactly one of 'at_time' or 'guard'"
            )
        if "at_time" in ev:
            t_at = float(ev["at_time"])

            def guard(t: float, q: Any, qd: Any, f_c: Any, _t: float = t_at) -> float:
                return t - _t

            direction = 1
        else:
            guard = resolve_entry_point(ev["guard"], sc.path, key + ".guard")
            direction = int(ev.get("direction", 0))
        kind = ev.get("transition", "none")
        names = ev.get("constraints", [])
        if kind != "none" and not names:
            raise ScenarioError(
                f"{sc.path}: key {key}.constraints: a '{kind}' transition needs constraint names"
            )
        try:
            model.resolve_active(names)
        except UnknownNameError as exc:
            raise ScenarioError(f"{sc.path}: key {key}.constraints: {exc}") from None
        transition: Any = None
        if kind == "activate":
            transition = Activate(names, restitution=float(ev.get("restitution", 0.0)))
        elif kind == "deactivate":
            transition = Deactivate(names)
        out.append(
            Event(
                guard,
                direction=direction,
                transition=transition,
                terminal=bool(ev.get("terminal", False)),
                name=ev["name"],
            )
        )
    return tuple(out)


@dataclass
class ScenarioResult:
    """What :func:`run_scenario` produced."""

    scenario: Scenario
    model: Any
    trajectory: Any
    files: dict[str, Path] = field(default_factory=dict)


def run_scenario(
    sc: Scenario,
    out_dir: str | Path | None = None,
    *,
    progress: bool | None = None,
    write: bool = True,
    t_final: float | None = None,
) -> ScenarioResult:
    """Build the model, state, controller and events of a scenario, simulate, write outputs."""
    from ..sim import simulate

    model, default_state, horizon = sc.build_source()
    state = sc.initial_state(model, default_state)
    kw = simulate_kwargs(sc)
    sim = sc.section("simulate")
    t_override = t_final
    if "t_final" in sim:
        t_final = float(sim["t_final"])
    elif horizon is not None:
        t_final = horizon
    else:
        t_final = state.t + 1.0
    if t_override is not None:
        t_final = float(t_override)
    if "output_dt" in sim:
        kw["t_eval"] = np.arange(
            state.t, t_final + 0.5 * float(sim["output_dt"]), float(sim["output_dt"])
        )
        kw["t_eval"][-1] = min(kw["t_eval"][-1], t_final)
    controller = build_controller(sc, model)
    events = build_events(sc, model)
    traj = simulate(
        model,
        (state.t, t_final),
        state.q,
        state.qd,
        active=state.active,
        controller=controller,
        events=events,
        throw=False,
        progress=progress,
        **kw,
    )
    result = ScenarioResult(scenario=sc, model=model, trajectory=traj)
    if write:
        result.files = write_outputs(result, sc.output_dir(out_dir))
    return result


def write_outputs(result: ScenarioResult, out: Path) -> dict[str, Path]:
    """Write trajectory file, CSV, plots and animation as the [output] table asks."""
    from ..sim import Trajectory

    sc, model, traj = result.scenario, result.model, result.trajectory
    opts = sc.section("output")
    out.mkdir(parents=True, exist_ok=True)
    files: dict[str, Path] = {}
    traj_name = opts.get("trajectory", "trajectory.npz")
    source: dict[str, Any] = {"scenario": str(sc.path.resolve())}
    lib = sc.section("model").get("library")
    if lib:
        source.update(library=lib, params=dict(sc.section("model").get("params", {})))
    if isinstance(traj, Trajectory):
        traj = dataclasses.replace(traj, metadata={**traj.metadata, "source": source, "scenario_name": sc.name})
        result.trajectory = traj
    files["trajectory"] = Path(traj.save(out / traj_name) or (out / traj_name))
    if opts.get("csv", True):
        files["csv"] = Path(traj.to_csv(out / "trajectory.csv") or (out / "trajectory.csv"))
    if opts.get("plots", True):
        from ..viz import plot_trajectory, save_figure

        files["plot"] = save_figure(
            plot_trajectory(traj, model, title=sc.name), out / "trajectory.png"
        )
    anim = opts.get("animation", "animation.gif")
    if anim and model.geometry(traj.q[0]) is not None:
        from ..viz import animate

        name = "animation.gif" if anim is True else str(anim)
        files["animation"] = animate(
            traj, model, out / name, fps=float(opts.get("fps", 20)), title=sc.name
        )
    return files
