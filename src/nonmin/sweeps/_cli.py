"""The ``nonmin sweep`` command and ``nonmin plot`` of a sweep store (called from nonmin.cli)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

__all__ = ["add_sweep_parser", "cmd_plot_sweep", "cmd_sweep"]


def add_sweep_parser(sub: Any, allow_code_flag: Any, progress_flags: Any) -> None:
    sp = sub.add_parser(
        "sweep",
        help="run a scenario over grids / random samples / lists of values (extra 'sweep')",
        description="Each --vary KEY=START:STOP:COUNT is a grid axis (crossed with the others), "
        "KEY=LOW:HIGH a uniform random axis (needs --samples), KEY=V1,V2,... a list. Keys are "
        "dotted scenario paths: model.params.omega0, simulate.dt, initial.qd[2]. Finished blocks "
        "of runs are committed to the Zarr store as they finish; the same command again resumes.",
    )
    sp.add_argument("scenario", help="SCENARIO.toml")
    sp.add_argument("--vary", action="append", default=[], metavar="KEY=SPEC", help="an axis (repeatable)")
    sp.add_argument("--samples", type=int, default=None, help="random draws of the LOW:HIGH axes")
    sp.add_argument("--seed", type=int, default=None, help="seed of the random draws")
    sp.add_argument("--out", default=None, help="Zarr store (default: ./SCENARIO-sweep.zarr)")
    sp.add_argument("--scheduler", default=None, metavar="tcp://HOST:PORT", help="run the blocks on this Dask scheduler")
    sp.add_argument("--workers", type=int, default=None, help="local threads (default: the cores)")
    sp.add_argument("--chunk", type=int, default=64, help="runs per block (task, engine call, commit)")
    allow_code_flag(sp)
    progress_flags(sp)
    sp.set_defaults(func=cmd_sweep)


def cmd_sweep(args: argparse.Namespace) -> int:
    from ._run import sweep

    out = Path(args.out) if args.out else Path.cwd() / f"{Path(args.scenario).stem}-sweep.zarr"
    try:
        res = sweep(args.scenario, args.vary, samples=args.samples, seed=args.seed, store=out,
                    scheduler=args.scheduler, workers=args.workers, chunk=args.chunk, progress=args.progress,
                    allow_code=args.allow_code)  # fmt: skip
    except KeyboardInterrupt:  # Ctrl-C: say what the store keeps and how to go on (exit 130)
        print(f"nonmin sweep: {_committed(out)}; the same command resumes", file=sys.stderr)
        raise
    print(f"{res.store}: {res.runs} runs ({res.computed} computed now, {res.skipped} from the store), "
          f"{res.failed} failed")  # fmt: skip
    return 0


def _committed(store: Path) -> str:
    """What an interrupted sweep's store holds, in words: the runs of the blocks with a commit
    record (a block's status is written before its record, so an interrupt between the two
    leaves statuses of runs that are not committed and that the rerun computes again)."""
    import zarr

    from ._store import commit_records

    try:
        group: Any = zarr.open_group(str(store), mode="r")
        runs = int(group["status"].shape[0])
        records = commit_records(group)
    except Exception:  # nothing committed yet (no store), or a store being written
        return f"{store}: no run committed yet"
    done = sum(int(r["runs"][1]) - int(r["runs"][0]) for r in records if "runs" in r)
    return f"{store}: {done} of {runs} runs committed"


def cmd_plot_sweep(args: argparse.Namespace) -> int:
    from ..viz import save_figure
    from ._plot import plot_sweep

    keys = args.keys.split(",") if getattr(args, "keys", None) else None
    fig = plot_sweep(args.result, getattr(args, "metric", None) or "energy_drift", keys)
    out = Path(args.output or Path(args.result).with_suffix(".png"))
    save_figure(fig, out)
    print(out)
    return 0
