"""nonmin's two simulation drivers side by side: the general (Python) driver and the C++ engine.

Runs fixed-step RK4 with the mass-metric projection on the crossed four-bar and A02 (N = 2)
with both ``engine="python"`` and ``engine="engine"`` in one process, samples every 0.01 s,
and prints the median wall time per simulated second and the ratio::

    OPENBLAS_NUM_THREADS=1 python benchmarks/engine_bench.py [--dt 1e-3] [--horizon 3] [--repeat 3]

With ``--first-use`` it instead measures what a fresh process pays once (issue 17, target 1):
``import nonmin.sim``, the first engine run of the crossed four-bar (1 s, RK4 dt = 1e-3) and
then a first general-driver run (nothing compiles at run time).
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def _mechanism(name: str):  # type: ignore[no-untyped-def]
    from nonmin import library

    return library.get("A02_n_four_bar", N=2) if name == "A02_N2" else library.get(name)


def engines(dt: float, horizon: float, repeat: int) -> None:
    from nonmin.sim import simulate

    print(f"RK4 dt = {dt:g}, projection, samples every 0.01 s, {horizon:g} s, median of {repeat}")
    for name in ("crossed_four_bar", "A02_N2"):
        mech = _mechanism(name)
        med = {}
        for eng in ("python", "engine"):
            kw = {"method": "rk4", "dt": dt, "progress": False, "engine": eng,
                  "t_eval": np.linspace(0.0, horizon, round(horizon / 0.01) + 1)}
            simulate(mech, (0.0, min(horizon, 0.1)), **{**kw, "t_eval": None})  # compile/warm
            walls = []
            for _ in range(repeat):
                t0 = time.perf_counter()
                simulate(mech, (0.0, horizon), **kw)
                walls.append((time.perf_counter() - t0) / horizon)
            med[eng] = float(np.median(walls))
        print(f"{name:17s} general {med['python']:.4f} s/s   engine {med['engine']:.4f} s/s"
              f"   ratio {med['python'] / med['engine']:.1f}")


def first_use() -> None:
    c0, t0 = time.process_time(), time.perf_counter()
    import nonmin  # noqa: F401

    c1, t1 = time.process_time(), time.perf_counter()
    from nonmin.sim import simulate

    mech = _mechanism("crossed_four_bar")
    c2, t2 = time.process_time(), time.perf_counter()
    simulate(mech, 1.0, dt=1e-3, progress=False)
    c3, t3 = time.process_time(), time.perf_counter()
    simulate(mech, 0.1, dt=1e-3, engine="python", progress=False)
    c4, t4 = time.process_time(), time.perf_counter()
    print(f"wall (CPU) s: import nonmin {t1 - t0:.2f} ({c1 - c0:.2f}), library model {t2 - t1:.2f} "
          f"({c2 - c1:.2f}), first simulate (1 s, RK4 dt 1e-3, engine) {t3 - t2:.2f} ({c3 - c2:.2f}), "
          f"first general-driver run (0.1 s) {t4 - t3:.2f} ({c4 - c3:.2f})")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dt", type=float, default=1e-3)
    ap.add_argument("--horizon", type=float, default=3.0)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--first-use", action="store_true", help="time the first runs instead")
    args = ap.parse_args()
    if args.first_use:
        first_use()
    else:
        engines(args.dt, args.horizon, args.repeat)


if __name__ == "__main__":
    main()
