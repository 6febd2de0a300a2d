"""Turn a :class:`Scenario` into API calls: simulate it and write its outputs."""

from __future__ import annotations

import dataclasses
import inspect
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .._files import confined
from ..errors import InputError, NonminError, ScenarioError, UnknownNameError
from ._scenario import Scenario, resolve_entry_point

__all__ = ["ScenarioResult", "build_controller", "build_events", "run_scenario", "simulate_kwargs"]


#: ``simulate`` keywords that ``[simulate.options]`` may not set, with where they come from
#: instead: the runner passes them itself (a second value was a TypeError), or they name files
#: to write or read, which a data file may do only inside its output folder (``[output]``).
_RUNNER_OWNED = {
    "active": "key 'initial.active'",
    "controller": "the [controller] table",
    "events": "[[events]] tables",
    "throw": "nothing: nonmin run keeps a failed run's samples and status (throw=False)",
    "progress": "nonmin run --progress / --no-progress",
    "checkpoint": "nonmin run --checkpoint-every SECONDS (it writes the output folder's trajectory file)",
    "checkpoint_every": "nonmin run --checkpoint-every SECONDS",
    "resume": "nonmin run --resume (it continues the output folder's trajectory file)",
}


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
    for key in extra:
        if key in _RUNNER_OWNED:
            raise ScenarioError(
                f"{sc.path}: key 'simulate.options.{key}': not settable from a scenario file; "
                f"use {_RUNNER_OWNED[key]}"
            )
    if "t_eval" in extra and "output_dt" in sim:
        raise ScenarioError(
            f"{sc.path}: key 'simulate.options.t_eval': the output times are given twice, also "
            "by 'simulate.output_dt'; keep one"
        )
    kw.update(extra)
    from ..sim import simulate
    from ..sim._options import SHORTHANDS

    params = inspect.signature(simulate).parameters
    known = {k for k, v in params.items() if v.kind == v.KEYWORD_ONLY} | set(SHORTHANDS)
    for key in kw:
        if key not in known:
            raise ScenarioError(
                f"{sc.path}: key 'simulate.options.{key}': not a keyword of nonmin.sim.simulate; "
                f"expected one of {sorted(known)}"
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
    missing = [
        p.name for p in sig.parameters.values()
        if p.kind == p.KEYWORD_ONLY and p.default is p.empty and p.name not in kwargs
    ]  # fmt: skip
    if missing:
        raise ScenarioError(
            f"{sc.path}: missing key " + ", ".join(f"'controller.{k}'" for k in missing)
            + f" for controller {name!r}"
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
            guard = resolve_entry_point(
                ev["guard"], sc.path, key + ".guard", allow_code=sc.allow_code
            )
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
    #: Wall-clock seconds of each stage: ``"simulate"`` (the call to simulate), and one entry
    #: per file written (``"trajectory"``, ``"csv"``, ``"plot"``, ``"animation"``).
    timings: dict[str, float] = field(default_factory=dict)


#: Largest number of output samples a scenario may ask for through ``output_dt`` (each sample
#: holds several vectors of n numbers: 10 million samples of a 10-coordinate model are ~5 GB).
MAX_OUTPUT_SAMPLES = 10_000_000


def _end_time(sc: Scenario, t0: float, horizon: float | None, t_final: float | None) -> float:
    sim = sc.section("simulate")
    if t_final is not None:
        key, value = "t_final (argument)", t_final
    elif "t_final" in sim:
        key, value = "simulate.t_final", sim["t_final"]
    elif horizon is not None:
        key, value = "the model's horizon", horizon
    else:
        key, value = "simulate.t_final (default t0 + 1)", t0 + 1.0
    try:
        t1 = float(value)
    except (TypeError, ValueError):
        raise ScenarioError(f"{sc.path}: key {key!r}: expected a number, got {value!r}") from None
    if not (math.isfinite(t1) and t1 > t0):
        raise ScenarioError(
            f"{sc.path}: key {key!r}: expected a finite end time after the start time "
            f"t0 = {t0:g}, got {value!r}"
        )
    return t1


def _output_times(sc: Scenario, t0: float, t1: float) -> Any:
    sim = sc.section("simulate")
    if "output_dt" not in sim:
        return None
    dt_out = float(sim["output_dt"])
    count = (t1 - t0) / dt_out
    if not count < MAX_OUTPUT_SAMPLES:
        raise ScenarioError(
            f"{sc.path}: key 'simulate.output_dt': {dt_out:g} s over [{t0:g}, {t1:g}] asks for "
            f"{count:.3g} samples, more than {MAX_OUTPUT_SAMPLES}; take a larger output_dt"
        )
    t_eval = np.arange(t0, t1 + 0.5 * dt_out, dt_out)
    t_eval[-1] = min(t_eval[-1], t1)
    return t_eval


def run_scenario(
    sc: Scenario,
    out_dir: str | Path | None = None,
    *,
    progress: bool | None = None,
    write: bool = True,
    t_final: float | None = None,
    checkpoint_every: float | None = None,
    resume: bool = False,
) -> ScenarioResult:
    """Build the model, state, controller and events of a scenario, simulate, write outputs.

    Code named by the scenario (``entry_point``, ``guard``) runs only if it was loaded with
    ``allow_code=True``. A simulation stopped by ``KeyboardInterrupt`` returns (and writes) the
    samples computed so far with status ``interrupted``.

    ``checkpoint_every`` (simulated seconds) makes the run write its samples so far to the
    trajectory file of the output folder as it goes (durably, status ``interrupted`` until it
    ends); ``resume=True`` continues the run that file holds (see :func:`nonmin.sim.simulate`).
    """
    from ..sim import simulate

    if t_final is not None:
        try:
            tf = float(t_final)
        except (TypeError, ValueError):
            raise InputError(f"t_final must be a number, got {t_final!r}") from None
        if not (math.isfinite(tf) and tf > 0):
            raise InputError(f"t_final must be a positive finite time [s], got {t_final!r}")
    out = sc.output_dir(out_dir) if write else None  # refuse a bad [output] before the run
    if write:
        _output_names(sc, out)  # type: ignore[arg-type]
    model, default_state, horizon = sc.build_source()
    state = sc.initial_state(model, default_state)
    kw = simulate_kwargs(sc)
    t_end = _end_time(sc, state.t, horizon, t_final)
    t_eval = _output_times(sc, state.t, t_end)
    if t_eval is not None:
        kw["t_eval"] = t_eval
    controller = build_controller(sc, model)
    events = build_events(sc, model)
    if (checkpoint_every is not None or resume) and not write:
        raise InputError("checkpoint_every and resume need write=True (they use the output folder)")
    if out is not None:
        target = _output_names(sc, out)["trajectory"]
        if checkpoint_every is not None:
            kw["checkpoint"], kw["checkpoint_every"] = target, checkpoint_every
        if resume:
            if target is None or not target.is_file():
                raise InputError(f"resume: there is no trajectory file {str(target)!r} to resume")
            kw["resume"] = target
    import time

    start = time.perf_counter()
    try:
        traj = simulate(
            model,
            (state.t, t_end),
            state.q,
            state.qd,
            active=state.active,
            controller=controller,
            events=events,
            throw=False,
            progress=progress,
            **kw,
        )
    except InputError as exc:
        raise ScenarioError(f"{sc.path}: table [simulate]: {exc}") from None
    result = ScenarioResult(scenario=sc, model=model, trajectory=traj,
                            timings={"simulate": time.perf_counter() - start})
    if write:
        assert out is not None
        result.files = write_outputs(result, out, progress=progress)
    return result


def _output_names(sc: Scenario, out: Path) -> dict[str, Path | None]:
    """The files of the [output] table, each confined to the output folder ``out``."""
    opts = sc.section("output")
    names: dict[str, Path | None] = {
        "trajectory": confined(out, opts.get("trajectory", "trajectory.npz"), file=sc.path,
                               key="output.trajectory", suffixes=(".npz",)),
        "csv": out / "trajectory.csv" if opts.get("csv", True) else None,
        "plot": out / "trajectory.png" if opts.get("plots", True) else None,
    }
    anim = opts.get("animation", "animation.gif")
    names["animation"] = (
        confined(out, "animation.gif" if anim is True else anim, file=sc.path,
                 key="output.animation", suffixes=(".gif", ".mp4"))
        if anim else None
    )
    return names


def write_outputs(result: ScenarioResult, out: Path, *, progress: bool | None = None) -> dict[str, Path]:
    """Write trajectory file, CSV, plots and animation as the [output] table asks.

    The wall time of each file goes to ``result.timings``; ``progress`` (not False) lets the
    animation report on stderr when it takes more than 2 s.

    Every file is written durably (temporary + fsync + rename: the previous file survives any
    failure); names from the scenario are confined to ``out``. The trajectory file is written
    first, so an interrupted or failed run keeps its samples even if a later output fails.
    """
    import time

    from ..sim import Trajectory
    from ..viz import DEFAULT_FPS

    sc, model, traj = result.scenario, result.model, result.trajectory
    opts = sc.section("output")
    names = _output_names(sc, out)
    files: dict[str, Path] = {}
    source: dict[str, Any] = {"scenario": str(sc.path.resolve())}
    lib = sc.section("model").get("library")
    if lib:
        source.update(library=lib, params=dict(sc.section("model").get("params", {})))
    fps = float(opts.get("fps", DEFAULT_FPS))
    if isinstance(traj, Trajectory):
        traj = dataclasses.replace(traj, metadata={**traj.metadata, "source": source,
                                                   "scenario_name": sc.name, "animation": {"fps": fps}})
        result.trajectory = traj
    clock = time.perf_counter
    target = names["trajectory"]
    assert target is not None
    t0 = clock()
    traj.save(target)
    files["trajectory"] = target
    result.timings["trajectory"] = clock() - t0
    if names["csv"] is not None:
        t0 = clock()
        from .._export import to_csv

        to_csv(traj, names["csv"], model)
        files["csv"] = names["csv"]
        result.timings["csv"] = clock() - t0
    if len(traj) == 0:
        return files
    if names["plot"] is not None:
        from ..viz import plot_trajectory, save_figure

        t0 = clock()
        files["plot"] = save_figure(plot_trajectory(traj, model, title=sc.name), names["plot"])
        result.timings["plot"] = clock() - t0
    anim = names["animation"]
    if anim is not None and model.geometry(traj.q[0]) is not None:
        from ..viz import animate

        t0 = clock()
        files["animation"] = animate(traj, model, anim, fps=fps, title=sc.name,
                                     progress=progress is not False)
        result.timings["animation"] = clock() - t0
    return files
