"""Issue 18, targets 2 and 3 on A02 N = 40 (20 s): CPU time, steps and errors of RK4 and the
adaptive methods against the exact 1-DOF reduction (energy: the exact motion conserves it).

    python benchmarks/a02_n40_bench.py [--T 20] [--runs rk4:4e-3,rk4:2e-3,dop853:1e-10,...] [--energy]
    python benchmarks/a02_n40_bench.py --a01 [--runs dop853:1e-10,dopri5:1e-10] [--energy]

``--energy``: ``Projection(energy=True)`` (the velocity also projected onto the initial energy
level). ``--a01``: the IFToMM A01 pendulum over ``--T`` (default then 2000 s) instead, samples
every 0.1 s, energy error only.

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
from nonmin.sim import DOP853, RK4, DormandPrince5, Projection


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
    ap.add_argument("--T", type=float, default=None)
    ap.add_argument("--runs", default="rk4:4e-3,rk4:2e-3,dop853:1e-8,dop853:1e-10,dop853:1e-12")
    ap.add_argument("--energy", action="store_true", help="Projection(energy=True)")
    ap.add_argument("--a01", action="store_true", help="A01 pendulum (default 2000 s)")
    a = ap.parse_args()
    kw = {"stabilization": Projection(energy=True)} if a.energy else {}
    if a.a01:
        T = 2000.0 if a.T is None else a.T
        pend = library.get("A01_pendulum")
        te = np.linspace(0.0, T, round(T * 10) + 1)
        print(f"A01, {T} s, energy={a.energy}, load {os.getloadavg()[0]:.1f}")
        for spec in a.runs.split(","):
            c0, w0 = time.process_time(), time.perf_counter()
            tr = simulate(pend, (0.0, T), method=_method(spec), t_eval=te, progress=False, **kw)
            c1, w1 = time.process_time(), time.perf_counter()
            print(f"{spec:>14}: cpu {c1 - c0:7.2f} s  wall {w1 - w0:7.2f} s  steps {tr.n_steps:6d}  "
                  f"rejected {tr.n_rejected:5d}  {tr.status.name}  "
                  f"energy {np.abs(tr.energy - tr.energy[0]).max():.2e} J", flush=True)  # fmt: skip
        return
    a.T = 20.0 if a.T is None else a.T
    mech = library.get("A02_n_four_bar", N=a.N)
    te = np.linspace(0.0, a.T, 201)
    ref = n_four_bar_reference(te, N=a.N, rtol=1e-13, atol=1e-13)
    print(f"A02 N = {a.N}, {a.T} s, energy={a.energy}, load {os.getloadavg()[0]:.1f}")
    for spec in a.runs.split(","):
        c0, w0 = time.process_time(), time.perf_counter()
        tr = simulate(mech, (0.0, a.T), method=_method(spec), t_eval=te, progress=False, **kw)
        c1, w1 = time.process_time(), time.perf_counter()
        th = tr.q[:, 2]
        b0 = np.stack([tr.q[:, 0] + 0.5 * np.cos(th), tr.q[:, 1] + 0.5 * np.sin(th)], axis=1)
        print(f"{spec:>14}: cpu {c1 - c0:7.2f} s  wall {w1 - w0:7.2f} s  steps {tr.n_steps:6d}  "
              f"rejected {tr.n_rejected:4d}  rhs {tr.n_rhs:6d}  "
              f"energy {np.abs(tr.energy - tr.energy[0]).max():.2e} J  "
              f"B0 {np.abs(b0 - ref['B0.position']).max():.2e} m", flush=True)  # fmt: skip


if __name__ == "__main__":
    main()
