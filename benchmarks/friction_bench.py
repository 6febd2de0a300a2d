"""The cost of exact Coulomb friction in the engine's loop, and its accuracy (issue #22).

Same runs, same integrator (RK4, dt = 1e-3, projection), timed side by side in one process:

* ``disk``: the planar disk launched at v0 = 3 m/s without spin (μ_f = 0.25), 2 s: slips, then
  rolls from t* = v0/(3 μ_f g). Against the same disk on a **frictionless** contact (the
  unilateral row only: it slides forever) — the frictionless run is the engine's contact loop
  without the friction solve, so the ratio is the price of the friction machinery (the extra
  back-substitution per slipping contact and evaluation, the split for N, the friction guards).
  Accuracy: |t* − v0/(3 μ_f g)| and |v − 2 v0/3| after rolling.
* ``puck``: the spatial puck sliding obliquely (μ_f = 0.4), 1 s: stops and sticks at v0/(μ_f g);
  against the frictionless puck.
* ``foot``: the demo (library ``foot_friction``, restitution 0.3, 1.5 s: 15 impacts and
  friction events) against the same foot with μ_f = 0 everywhere replaced by frictionless
  contacts is not the same motion; only its wall time per simulated second is reported.

Interleaved repeats, medians of wall and process CPU time; ratios of medians. The machine is
shared (8 agents, 2 cores): the load average is printed with the results.

    OPENBLAS_NUM_THREADS=1 python benchmarks/friction_bench.py [--repeat 7] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import time
from typing import Any

import numpy as np

import nonmin
from nonmin import library
from nonmin.model.planar import PlanarBuilder
from nonmin.model.spatial import SpatialBuilder

G = 9.81


def _disk(mu: float | None) -> Any:
    R = 0.2
    b = PlanarBuilder("disk")
    b.body("disk", mass=1.5, inertia=0.5 * 1.5 * R**2, points={"c": (0.0, 0.0)})
    if mu is None:
        b.point_on_line("floor", ("ground", (0.0, R)), "c", axis=(1.0, 0.0), unilateral=True, active=True)
    else:
        b.contact("floor", ("ground", (0.0, 0.0)), "c", axis=(1.0, 0.0), friction=mu, radius=R, active=True)
    return b.build()


def _puck(mu: float | None) -> Any:
    b = SpatialBuilder("puck")
    b.add_body("puck", mass=0.7, inertia=(0.01, 0.012, 0.02))
    if mu is None:
        b.add_point_on_plane("floor", "ground", "puck", point=(0, 0, 0), normal=(0, 0, 1))
    else:
        b.add_contact("floor", "ground", "puck", point=(0, 0, 0), normal=(0, 0, 1), friction=mu, active=True)
    return b.build()


def _cases() -> dict[str, tuple[Any, Any, float, Any, Any]]:
    d = np.array([math.cos(0.7), math.sin(0.7), 0.0])
    qd_p = np.zeros(7)
    qd_p[:3] = 2.5 * d
    foot = library.get("foot_friction")
    return {
        "disk": (_disk(0.25), _disk(None), 2.0, ([0.0, 0.2, 0.0], [3.0, 0.0, 0.0]), {}),
        "puck": (_puck(0.4), _puck(None), 1.0, ([0, 0, 0, 1, 0, 0, 0], qd_p), {}),
        "foot": (foot.model, None, foot.t_final, (foot.state.q, foot.state.qd), {"restitution": 0.3}),
    }


def _run(model: Any, T: float, state: Any, kw: dict[str, Any]) -> tuple[Any, float, float]:
    w0, c0 = time.perf_counter(), time.process_time()
    tr = nonmin.simulate(model, T, state[0], state[1], dt=1e-3, progress=False, **kw)
    return tr, time.perf_counter() - w0, time.process_time() - c0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=7)
    ap.add_argument("--json", default="")
    args = ap.parse_args()
    out: dict[str, Any] = {"load_average": os.getloadavg(), "cases": {}}
    for name, (fric, free, T, state, kw) in _cases().items():
        wall: dict[str, list[float]] = {"friction": [], "frictionless": []}
        cpu: dict[str, list[float]] = {"friction": [], "frictionless": []}
        tr = None
        for _ in range(args.repeat):  # interleaved
            tr, w, c = _run(fric, T, state, kw)
            wall["friction"].append(w)
            cpu["friction"].append(c)
            if free is not None:
                _, w, c = _run(free, T, state, kw)
                wall["frictionless"].append(w)
                cpu["frictionless"].append(c)
        assert tr is not None
        row: dict[str, Any] = {
            "T": T,
            "steps": int(tr.n_steps),
            "events": len(tr.events),
            "wall_friction_s": statistics.median(wall["friction"]),
            "cpu_friction_s": statistics.median(cpu["friction"]),
        }
        if free is not None:
            row["wall_frictionless_s"] = statistics.median(wall["frictionless"])
            row["cpu_frictionless_s"] = statistics.median(cpu["frictionless"])
            row["cpu_ratio"] = row["cpu_friction_s"] / row["cpu_frictionless_s"]
        if name == "disk":
            row["t_star_error_s"] = abs(tr.events[0].t - 3.0 / (3 * 0.25 * G))
            row["rolling_speed_error"] = float(abs(tr.qd[-1, 0] - 2.0))
        if name == "puck":
            row["stop_time_error_s"] = abs(tr.events[0].t - 2.5 / (0.4 * G))
        out["cases"][name] = row
        print(name, json.dumps(row))
    print("load average", out["load_average"])
    if args.json:
        with open(args.json, "w", encoding="utf-8") as fh:
            json.dump(out, fh, indent=2)


if __name__ == "__main__":
    main()
