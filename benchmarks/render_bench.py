"""Rendering cost of the demo's scenes (issue 23: GIF/MP4 encoding of the demo scenes ≤ 10 s).

Each demo scenario is simulated once (not timed), then its animation is written as a GIF
(and as an MP4 when ffmpeg is available to matplotlib); wall and CPU seconds per scene and in
all are printed. Speed claims about rendering come from here, not from timed tests.

Usage::

    python benchmarks/render_bench.py [--repeat 3]
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time
from pathlib import Path

from nonmin.cli import DEMO_SCENARIOS
from nonmin.io import load_scenario
from nonmin.io._run import run_scenario
from nonmin.viz import animate

SCENARIOS = Path(__file__).resolve().parents[1] / "src" / "nonmin" / "data" / "scenarios"


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args(argv)
    print(f"load average before {os.getloadavg()}")
    totals: dict[str, list[float]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name in DEMO_SCENARIOS:
            res = run_scenario(load_scenario(SCENARIOS / f"{name}.toml"), write=False)
            for ext in ("gif", "mp4"):
                walls = []
                for k in range(args.repeat):
                    w0, c0 = time.perf_counter(), time.process_time()
                    try:
                        animate(res.trajectory, res.model, Path(tmp) / f"{name}{k}.{ext}", progress=False)
                    except Exception as exc:  # no ffmpeg: report and go on
                        print(f"{name} {ext}: {type(exc).__name__}: {exc}")
                        break
                    walls.append(time.perf_counter() - w0)
                    cpu = time.process_time() - c0
                if walls:
                    med = statistics.median(walls)
                    totals.setdefault(ext, []).append(med)
                    print(f"{name:18s} {ext}: median wall {med:.2f} s (last CPU {cpu:.2f} s)")
    for ext, v in totals.items():
        print(f"all scenes, {ext}: {sum(v):.2f} s wall (sum of medians)")
    print(f"load average after {os.getloadavg()}")


if __name__ == "__main__":
    main()
