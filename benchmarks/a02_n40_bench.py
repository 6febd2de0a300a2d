"""Issue 18, targets 2 and 3 on A02 N = 40 (20 s): CPU time, steps and errors of RK4 and the
adaptive methods against the exact 1-DOF reduction (energy: the exact motion conserves it).

    python benchmarks/a02_n40_bench.py [--T 20] [--runs rk4:4e-3,rk4:2e-3,dop853:1e-10,...]

Prints one line per run (CPU seconds of the simulate call, wall seconds, steps, rejected steps,
right-hand-side evaluations, max energy error, max B0 position error). Timings are noisy on a
shared machine: the load (os.getloadavg) is printed with them.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

from nonmin import library, simulate
from nonmin.library._iftomm import n_four_bar_reference
from nonmin.sim import DOP853, RK4, DormandPrince5


def _method(spec: str):  # type: ignore[no-untyped-def]
    kind, val = spec.split(":")
    v = float(val)
    if kind == "rk4":
        return RK4(v)
    if kind == "dop853":
        return DOP853(rtol=v, atol=1e-2 * v)
    if kind == "dopri5":
        return DormandPrince5(rtol=v, atol=1e-2 * v)
    raise SystemExit(f"unknown method {kind!r} (rk4, dop853, dopri5)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--N", type=int, default=40)
    ap.add_argument("--T", type=float, default=20.0)
    ap.add_argument("--runs", default="rk4:4e-3,rk4:2e-3,dop853:1e-8,dop853:1e-10,dop853:1e-12")
    a = ap.parse_args()
    mech = library.get("A02_n_four_bar", N=a.N)
    te = np.linspace(0.0, a.T, 201)
    ref = n_four_bar_reference(te, N=a.N, rtol=1e-13, atol=1e-13)
    print(f"A02 N = {a.N}, {a.T} s, load {os.getloadavg()[0]:.1f}")
    for spec in a.runs.split(","):
        c0, w0 = time.process_time(), time.perf_counter()
        tr = simulate(mech, (0.0, a.T), method=_method(spec), t_eval=te, progress=False)
        c1, w1 = time.process_time(), time.perf_counter()
        th = tr.q[:, 2]
        b0 = np.stack([tr.q[:, 0] + 0.5 * np.cos(th), tr.q[:, 1] + 0.5 * np.sin(th)], axis=1)
        print(f"{spec:>14}: cpu {c1 - c0:7.2f} s  wall {w1 - w0:7.2f} s  steps {tr.n_steps:6d}  "
              f"rejected {tr.n_rejected:4d}  rhs {tr.n_rhs:6d}  "
              f"energy {np.abs(tr.energy - tr.energy[0]).max():.2e} J  "
              f"B0 {np.abs(b0 - ref['B0.position']).max():.2e} m", flush=True)  # fmt: skip


if __name__ == "__main__":
    main()
