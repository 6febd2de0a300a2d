"""The ``nonmin`` command line: parse → load → call the public API → write files.

Exit codes
----------
0  success
1  the work ran but failed: a simulation ended with status failed, ``check`` found a failing
   check, ``validate`` found a benchmark off target
2  usage error, malformed scenario file, unknown model or file, invalid input
3  a missing optional dependency (the message names the extra to install)
4  an unexpected internal error (a bug: please report it with the traceback)
130  interrupted (Ctrl-C); ``run`` first saves the samples computed so far

Trust: scenario files are data unless they name code (``[model] entry_point``, an event
``guard``): those run only with ``--allow-code``. Trajectory files are data: ``plot`` and
``animate`` never rebuild a model from their metadata; name the model with ``--model``.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
import traceback
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from ._files import write_text
from ._version import __version__
from .errors import InputError, MissingDependencyError, NonminError, OutputError, ScenarioError

EXIT_OK, EXIT_FAILED, EXIT_USAGE, EXIT_MISSING_DEP, EXIT_INTERNAL = 0, 1, 2, 3, 4
EXIT_INTERRUPTED = 130

DEMO_SCENARIOS = ("n_four_bar", "crossed_four_bar", "arm_wall", "foot_friction")


def _scenario_dir() -> Path:
    return Path(__file__).resolve().parent / "data" / "scenarios"


def _status_name(traj: Any) -> str:
    st = getattr(traj, "status", "")
    return str(getattr(st, "name", st)).lower()


def _summary_row(name: str, traj: Any, timings: dict[str, float], model: Any = None) -> dict[str, Any]:
    """One row of the run/demo summary.

    ``sim_s`` is the elapsed time of the simulation alone; ``render_s`` that of the plot, the
    animation and the files. ``energy_balance`` is the drift ``max |E − E₀ − W − W_fr + L_imp|``
    with W the work of controllers, actuators, dampers and drivers, W_fr the work of Coulomb
    friction and L_imp the energy lost at impacts (:func:`nonmin.viz.energy_balance`); ``work``,
    ``friction`` and ``impacts`` are their values at the end of the run.
    """
    import numpy as np

    from .viz import energy_balance

    phi = np.asarray(getattr(traj, "phi_norm", [np.nan]))
    vel = np.asarray(getattr(traj, "velocity_residual_norm", [np.nan]))
    rank = np.asarray(getattr(traj, "rank", [0]))
    bal = energy_balance(traj, model)
    return {
        "scenario": name,
        "status": _status_name(traj),
        "t_end": float(np.asarray(traj.t)[-1]),
        "energy_balance": float(np.max(np.abs(bal.balance))) if bal is not None else float("nan"),
        "work": float(bal.work[-1]) if bal is not None else float("nan"),
        "friction": float(bal.friction[-1]) if bal is not None else float("nan"),
        "impacts": float(bal.impacts[-1]) if bal is not None else float("nan"),
        "max_phi": float(np.max(phi)) if phi.size else float("nan"),
        "max_Aqd": float(np.max(vel)) if vel.size else float("nan"),
        "rank": f"{int(rank.min())}..{int(rank.max())}" if rank.size else "-",
        "events": len(getattr(traj, "events", ()) or ()),
        "sim_s": float(timings.get("simulate", float("nan"))),
        "render_s": float(sum(v for k, v in timings.items() if k != "simulate")),
    }


def _format_rows(rows: Sequence[dict[str, Any]]) -> str:
    w = max([len("scenario"), *(len(str(r["scenario"])) for r in rows)])
    head = (
        f"{'scenario':{w}s} {'status':16s} {'t_end[s]':>8s} {'drift[J]':>9s} {'W[J]':>9s} "
        f"{'W_fr[J]':>9s} {'L_imp[J]':>9s} {'|phi| max':>10s} "
        f"{'|Aqd| max':>10s} {'rank A':>7s} {'events':>6s} {'sim[s]':>7s} {'render[s]':>9s}"
    )
    lines = [head, "-" * len(head)]
    for r in rows:
        lines.append(
            f"{r['scenario']:{w}s} {r['status']:16s} {r['t_end']:8.3g} {r['energy_balance']:9.1e} "
            f"{r['work']:9.2e} {r['friction']:9.2e} {r['impacts']:9.2e} "
            f"{r['max_phi']:10.2e} {r['max_Aqd']:10.2e} {r['rank']:>7s} {r['events']:6d} "
            f"{r['sim_s']:7.2f} {r['render_s']:9.2f}"
        )
    lines.append(
        "sim[s] = seconds spent simulating; render[s] = seconds spent on the plot, animation and files; "
        "drift = max|E-E0-W-W_fr+L_imp| (W: work of forces and controllers, W_fr: of friction, "
        "L_imp: lost at impacts; W, W_fr, L_imp at the end)"
    )
    return "\n".join(lines)


# ---------------------------------------------------------------------------- verbs


def cmd_demo(args: argparse.Namespace) -> int:
    from .io import load_scenario, run_scenario, write_outputs

    out = Path(args.out)
    rows = []
    failed = False
    total0 = time.perf_counter()
    for name in args.only or DEMO_SCENARIOS:
        path = _scenario_dir() / f"{name}.toml"
        sc = load_scenario(path)
        print(f"[nonmin demo] {sc.name}: {sc.data.get('description', '')}", flush=True)
        print("    simulating ...", flush=True)
        res = run_scenario(sc, progress=args.progress, t_final=args.t_final, write=False)
        tm = res.timings
        print(f"    simulated {res.trajectory.t[-1] - res.trajectory.t[0]:.3g} s in "
              f"{tm.get('simulate', 0.0):.2f} s" if len(res.trajectory) else "    no samples", flush=True)
        if len(res.trajectory):
            print("    writing the trajectory, CSV, plot and animation ...", flush=True)
        res.files = write_outputs(res, sc.output_dir(out / name), progress=args.progress)
        if len(res.trajectory):
            rows.append(_summary_row(name, res.trajectory, tm, res.model))
        failed |= _status_name(res.trajectory) == "failed"
        for kind, f in res.files.items():
            print(f"    {kind:11s} {Path(f).resolve()}  ({tm.get(kind, 0.0):.2f} s)", flush=True)
        if _status_name(res.trajectory) == "interrupted":
            if rows:
                write_text(out / "summary.txt", _format_rows(rows) + "\n")
            print(f"nonmin: interrupted: {res.trajectory.message}", file=sys.stderr)
            return EXIT_INTERRUPTED
    print()
    print(_format_rows(rows))
    write_text(out / "summary.txt", _format_rows(rows) + "\n")
    total = time.perf_counter() - total0
    sim = sum(r["sim_s"] for r in rows)
    print(f"\nin all {total:.1f} s (simulation {sim:.1f} s, rendering and files {total - sim:.1f} s)")
    print(f"plots, animations and trajectories written to {out.resolve()}")
    return EXIT_FAILED if failed else EXIT_OK


def cmd_run(args: argparse.Namespace) -> int:
    from .io import load_scenario, run_scenario

    sc = load_scenario(args.scenario, allow_code=args.allow_code)
    res = run_scenario(sc, args.out, progress=args.progress, t_final=args.t_final,
                       checkpoint_every=args.checkpoint_every, resume=args.resume)
    traj = res.trajectory
    if len(traj):
        print(_format_rows([_summary_row(sc.name, traj, res.timings, res.model)]))
    for kind, f in res.files.items():
        print(f"{kind:11s} {Path(f).resolve()}")
    if _status_name(traj) == "interrupted":
        print(f"nonmin: interrupted: {traj.message}; {len(traj)} samples saved", file=sys.stderr)
        return EXIT_INTERRUPTED
    if _status_name(traj) == "failed":
        print(f"simulation failed: {traj.message}", file=sys.stderr)
        return EXIT_FAILED
    return EXIT_OK


def _load_model_arg(spec: str, allow_code: bool = False) -> tuple[Any, Any]:
    """MODEL argument: a library name or a scenario file."""
    p = Path(spec)
    if p.suffix == ".toml":
        from .io import load_scenario

        sc = load_scenario(p, allow_code=allow_code)
        model, default = sc.build_model()
        return model, sc.initial_state(model, default)
    from . import library

    mech = library.get(spec)
    return mech.model, mech.state


def cmd_check(args: argparse.Namespace) -> int:
    from .sim import check_model

    model, state = _load_model_arg(args.model, args.allow_code)
    report = check_model(model, state, duration=args.duration, samples=args.samples)
    print(report.format())
    return EXIT_OK if report.passed else EXIT_FAILED


def cmd_validate(args: argparse.Namespace) -> int:
    from . import validation

    records = validation.run_all(quick=not args.full)
    print(validation.format_table(records))
    if args.report:
        validation.write_report(records, args.report)
        print(f"report written to {args.report}")
    ok = all(getattr(r, "passed", True) for r in records)
    return EXIT_OK if ok else EXIT_FAILED


def _load_result(path: str) -> Any:
    from .sim import load_trajectory

    return load_trajectory(path)


def _model_for_result(traj: Any, spec: str | None, allow_code: bool, verb: str) -> Any:
    """The model named by the user (``--model``) for a saved trajectory, checked against it.

    A trajectory's metadata is provenance only: it is shown in the error message as a hint,
    never used to rebuild a model (a file from elsewhere must not make nonmin build, or run,
    what it names).
    """
    if spec is None:
        meta = getattr(traj, "metadata", {}) or {}
        src = meta.get("source") if isinstance(meta, dict) else None
        hint = ""
        if isinstance(src, dict) and isinstance(src.get("library"), str):
            hint = f" (its metadata says it came from library model {src['library']!r}"
            if src.get("params"):
                hint += f" with params {src['params']!r}"
            hint += ")"
        elif isinstance(src, dict) and isinstance(src.get("scenario"), str):
            hint = f" (its metadata says it came from scenario {src['scenario']!r})"
        raise InputError(
            f"{verb}: --model is required: name the library model or scenario file the "
            f"trajectory came from{hint}; nonmin does not rebuild models from a file's metadata"
        )
    model, _ = _load_model_arg(spec, allow_code)
    names = tuple(getattr(traj, "coordinate_names", ()))
    if tuple(model.coordinate_names) != names:
        raise InputError(
            f"{verb}: --model {spec!r} has coordinates {list(model.coordinate_names)[:8]}"
            f"{'...' if model.n > 8 else ''} ({model.n}); the trajectory has {len(names)}: "
            "not the model it came from"
        )
    return model


def cmd_plot(args: argparse.Namespace) -> int:
    from .viz import plot_trajectory, save_figure

    if (Path(args.result) / "zarr.json").is_file():  # a sweep store: a metric over its keys
        from .sweeps._cli import cmd_plot_sweep

        return cmd_plot_sweep(args)

    traj = _load_result(args.result)
    model = None if args.model is None else _model_for_result(traj, args.model, args.allow_code, "plot")
    out = Path(args.output or Path(args.result).with_suffix(".png"))
    save_figure(plot_trajectory(traj, model, title=traj.metadata.get("scenario_name")), out)
    print(out)
    return EXIT_OK


def _result_fps(traj: Any) -> float:
    """The frame rate a trajectory was animated with by ``run`` (its metadata), or the default."""
    from .viz import DEFAULT_FPS

    anim = (getattr(traj, "metadata", {}) or {}).get("animation")
    fps = anim.get("fps") if isinstance(anim, dict) else None
    return float(fps) if isinstance(fps, int | float) and 0 < fps <= 1000 else DEFAULT_FPS


def cmd_animate(args: argparse.Namespace) -> int:
    from .viz import animate

    traj = _load_result(args.result)
    model = _model_for_result(traj, args.model, args.allow_code, "animate")
    if len(traj) == 0:
        raise InputError(f"animate: {args.result!r} holds no samples")
    out_path = Path(args.output or Path(args.result).with_suffix(".gif"))
    fps = args.fps if args.fps is not None else _result_fps(traj)
    out = animate(traj, model, out_path, fps=fps, speed=args.speed,
                  title=traj.metadata.get("scenario_name"), progress=args.progress is not False)
    print(out)
    return EXIT_OK


def cmd_export(args: argparse.Namespace) -> int:
    from . import _export, io

    traj = _load_result(args.result)
    model = None if args.model is None else _model_for_result(traj, args.model, args.allow_code, "export")
    suffix = {"csv": ".csv", "parquet": ".parquet", "netcdf": ".nc"}[args.format]
    out = Path(args.output or Path(args.result).with_suffix(suffix))
    if args.format == "csv":
        io.to_csv(traj, out, model)
        print(out)
        print(_export.sidecar(out))
    elif args.format == "parquet":
        print(io.to_parquet(traj, out, model))
    else:
        print(io.to_netcdf(traj, out, model))
    return EXIT_OK


def cmd_view(args: argparse.Namespace) -> int:
    from .viz.view import view

    traj = _load_result(args.result)
    model = _model_for_result(traj, args.model, args.allow_code, "view")
    viewer = view(traj, model, port=args.port, speed=args.speed, open_browser=not args.no_browser)
    print(f"nonmin view: {viewer.url}  (Ctrl-C to stop)", flush=True)
    if args.seconds is not None:
        time.sleep(args.seconds)
        viewer.stop()
        return EXIT_OK
    try:
        while True:
            time.sleep(3600)
    finally:
        viewer.stop()


def _first_line(obj: Any) -> str:
    """The first paragraph of a docstring as plain text (reST roles and literals unwrapped)."""
    import re

    doc = (getattr(obj, "__doc__", None) or "").strip()
    text = " ".join(doc.split("\n\n", 1)[0].split())
    text = re.sub(r":[a-z]+:`~?(?:[\w.]+\.)?([^`]+)`", r"\1", text)  # :class:`~a.B` -> B
    return text.replace("``", "")


def cmd_list(args: argparse.Namespace) -> int:
    from . import control, library, sim

    def row(name: str, text: str) -> None:
        text = text if len(text) <= 96 else text[:93] + "..."
        print(f"  {name:28s} {text}")

    print("models (nonmin.library.get(NAME); scenario [model] library = NAME):")
    for name in library.names():
        row(name, _first_line(library._registry._REGISTRY[name]))
    print("integrators (simulate(method=NAME)):")
    for name in sorted(sim.METHODS):
        row(name, _first_line(sim.METHODS[name]))
    print("stabilizations (simulate(stabilization=NAME)):")
    for name in sorted(sim.STABILIZATIONS):
        row(name, _first_line(sim.STABILIZATIONS[name]))
    print("controllers (nonmin.control; scenario [controller] type = NAME):")
    for name in control.names():
        factory = control.get(name)
        cls = getattr(factory, "__annotations__", {}).get("return", "")
        row(name, f"{cls}: {_first_line(factory)}" if cls else _first_line(factory))
    row("(API only) Switched", _first_line(control.Switched))
    print("demo scenarios (nonmin demo --only NAME):")
    for name in DEMO_SCENARIOS:
        from .io import load_scenario

        sc = load_scenario(_scenario_dir() / f"{name}.toml")
        row(name, sc.name)
    return EXIT_OK


# ---------------------------------------------------------------------------- parser


def _number(low: float, high: float, *, low_open: bool = True, kind: type = float) -> Any:
    """An argparse type: a finite number in (low, high] (or [low, high])."""

    def parse(text: str) -> Any:
        try:
            v = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {'an integer' if kind is int else 'a number'}, got {text!r}") from None
        if not (math.isfinite(v) and (v > low if low_open else v >= low) and v <= high):
            raise argparse.ArgumentTypeError(
                f"expected a finite number in {'(' if low_open else '['}{low:g}, {high:g}], got {text!r}"
            )
        return v

    parse.__name__ = "integer" if kind is int else "number"
    return parse


_TIME = _number(0.0, 1e9)
_FPS = _number(0.0, 1000.0)
_SPEED = _number(0.0, 1e6)
_SAMPLES = _number(2, 1_000_000, low_open=False, kind=int)
_PORT = _number(0, 65535, low_open=False, kind=int)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="nonmin",
        description="Dynamics, simulation and control of constrained mechanical systems "
        "through singular, redundant and switching constraints.",
        epilog="exit codes: 0 ok, 1 run/check/validation failed, 2 usage or input error, "
        "3 missing optional dependency, 4 internal error",
    )
    p.add_argument("--version", action="version", version=f"nonmin {__version__}")
    sub = p.add_subparsers(dest="verb", required=True, metavar="VERB")

    def progress_flags(sp: argparse.ArgumentParser) -> None:
        g = sp.add_mutually_exclusive_group()
        g.add_argument(
            "--progress",
            dest="progress",
            action="store_true",
            default=None,
            help="always show progress",
        )
        g.add_argument(
            "--no-progress", dest="progress", action="store_false", help="never show progress"
        )

    def allow_code_flag(sp: argparse.ArgumentParser) -> None:
        sp.add_argument(
            "--allow-code",
            action="store_true",
            help="let the scenario import and run the code it names ([model] entry_point, event "
            "guards): scenario files with entry points are programs, use only trusted ones",
        )

    def model_flag(sp: argparse.ArgumentParser, required: bool, use: str = "") -> None:
        sp.add_argument(
            "--model",
            default=None,
            help="library model name or SCENARIO.toml the trajectory came from"
            + (f" ({use})" if use else "")
            + "; the file's metadata is never used to rebuild one",
        )
        allow_code_flag(sp)

    sp = sub.add_parser(
        "demo", help="run the built-in scenarios; write plots, animations and a summary"
    )
    sp.add_argument("--out", default="nonmin-demo", help="output folder (default ./nonmin-demo)")
    sp.add_argument("--only", nargs="+", choices=DEMO_SCENARIOS, help="run only these scenarios")
    sp.add_argument("--t-final", type=_TIME, default=None, help="shorten every scenario to this end time [s]")
    progress_flags(sp)
    sp.set_defaults(func=cmd_demo)

    sp = sub.add_parser("run", help="simulate a scenario file")
    sp.add_argument("scenario", help="SCENARIO.toml")
    sp.add_argument(
        "--out", default=None, help="output folder (default: [output] dir or SCENARIO-out)"
    )
    sp.add_argument("--t-final", type=_TIME, default=None, help="override the scenario's end time [s]")
    sp.add_argument(
        "--checkpoint-every", type=_TIME, default=None, metavar="SECONDS",
        help="write the samples so far to the trajectory file every SECONDS of simulated time",
    )
    sp.add_argument(
        "--resume", action="store_true",
        help="continue the (interrupted) run held by the output folder's trajectory file",
    )
    allow_code_flag(sp)
    progress_flags(sp)
    sp.set_defaults(func=cmd_run)

    sp = sub.add_parser("check", help="verify a model (library name or scenario file)")
    sp.add_argument("model", help="library model name (see `nonmin list`) or SCENARIO.toml")
    sp.add_argument(
        "--duration", type=_TIME, default=1.0, help="length of the diagnostic trajectory [s]"
    )
    sp.add_argument("--samples", type=_SAMPLES, default=200,
                    help="samples of the diagnostic trajectory where rank A, cond(M̄) and μ are reported")
    allow_code_flag(sp)
    sp.set_defaults(func=cmd_check)

    sp = sub.add_parser(
        "validate", help="run the external benchmark suite and print the comparison table"
    )
    sp.add_argument(
        "--full", action="store_true", help="full horizons (slow) instead of the quick versions"
    )
    sp.add_argument("--report", default=None, help="also write a Markdown report to this file")
    sp.set_defaults(func=cmd_validate)

    sp = sub.add_parser("plot", help="plot a saved trajectory, or a metric of a sweep over its keys")
    sp.add_argument("result", help="trajectory file (.npz) written by run/demo, or a sweep store (.zarr)")
    sp.add_argument("-o", "--output", default=None, help="image file (default RESULT.png)")
    sp.add_argument("--metric", default=None, help="sweep: per-run metric (default energy_drift)")
    sp.add_argument("--keys", default=None, help="sweep: one or two swept keys, comma-separated")
    model_flag(sp, required=False, use="draws the model-based panels")
    sp.set_defaults(func=cmd_plot)

    sp = sub.add_parser("animate", help="animate a saved trajectory (GIF or MP4)")
    sp.add_argument("result", help="trajectory file (.npz) written by run/demo")
    sp.add_argument("-o", "--output", default=None, help="FILE.gif or FILE.mp4 (default RESULT.gif)")
    sp.add_argument("--fps", type=_FPS, default=None,
                    help="frames per second (default: the run's, else 20: the same frames as `run`)")
    sp.add_argument("--speed", type=_SPEED, default=1.0, help="playback speed factor")
    model_flag(sp, required=True)
    progress_flags(sp)
    sp.set_defaults(func=cmd_animate)

    from .sweeps._cli import add_sweep_parser

    add_sweep_parser(sub, allow_code_flag, progress_flags)

    sp = sub.add_parser("export", help="export a saved trajectory to CSV, Parquet or NetCDF")
    sp.add_argument("result", help="trajectory file (.npz) written by run/demo")
    sp.add_argument("--format", choices=("csv", "parquet", "netcdf"), default="csv",
                    help="csv (plain header + RESULT.csv.json metadata), parquet or netcdf "
                    "(extra export); default csv")
    sp.add_argument("-o", "--output", default=None, help="output file (default RESULT.csv/.parquet/.nc)")
    model_flag(sp, required=False, use="gives the columns their units")
    sp.set_defaults(func=cmd_export)

    sp = sub.add_parser("view", help="open a saved trajectory in the interactive 3-D viewer (browser)")
    sp.add_argument("result", help="trajectory file (.npz) written by run/demo")
    sp.add_argument("--port", type=_PORT, default=8080,
                    help="port of the viewer's web server (default 8080; 0: any free port)")
    sp.add_argument("--speed", type=_SPEED, default=1.0, help="initial playback speed")
    sp.add_argument("--no-browser", action="store_true", help="do not open a browser window")
    sp.add_argument("--seconds", type=_TIME, default=None, help="stop after this many seconds")
    model_flag(sp, required=True)
    sp.set_defaults(func=cmd_view)

    sp = sub.add_parser("list", help="list models, integrators, stabilizations, controllers (with descriptions)")
    sp.set_defaults(func=cmd_list)
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``nonmin`` command; returns the exit code."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args))
    except MissingDependencyError as exc:
        print(f"nonmin: {exc}", file=sys.stderr)
        return EXIT_MISSING_DEP
    except OutputError as exc:
        print(f"nonmin: error: {exc}", file=sys.stderr)
        return EXIT_FAILED
    except (ScenarioError, InputError, FileNotFoundError) as exc:
        print(f"nonmin: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except NonminError as exc:
        print(f"nonmin: {type(exc).__name__}: {exc}", file=sys.stderr)
        return EXIT_FAILED
    except KeyboardInterrupt:
        print("nonmin: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except Exception:
        traceback.print_exc()
        print(
            "nonmin: internal error (a bug); please report it with the traceback above",
            file=sys.stderr,
        )
        return EXIT_INTERNAL


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
