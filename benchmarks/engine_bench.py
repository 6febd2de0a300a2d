"""nonmin's two simulation engines side by side: the general (Python) driver and the compiled loop.

Runs fixed-step RK4 with the mass-metric projection on the crossed four-bar and A02 (N = 2)
with both ``engine="python"`` and ``engine="compiled"`` in one process, samples every 0.01 s,
and prints the median wall time per simulated second and the ratio::

    OPENBLAS_NUM_THREADS=1 python benchmarks/engine_bench.py [--dt 1e-3] [--horizon 3] [--repeat 3]

With ``--first-use`` it instead measures what a fresh machine pays once: import, first general
driver run and first compiled run, each including numba's compilation; run it with an empty
``NUMBA_CACHE_DIR`` (e.g. ``NUMBA_CACHE_DIR=$(mktemp -d)``) for the cold figures.
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
        for eng in ("python", "compiled"):
            kw = {"method": "rk4", "dt": dt, "progress": False, "engine": eng,
                  "t_eval": np.linspace(0.0, horizon, round(horizon / 0.01) + 1)}
            simulate(mech, (0.0, min(horizon, 0.1)), **{**kw, "t_eval": None})  # compile/warm
            walls = []
            for _ in range(repeat):
                t0 = time.perf_counter()
                simulate(mech, (0.0, horizon), **kw)
                walls.append((time.perf_counter() - t0) / horizon)
            med[eng] = float(np.median(walls))
        print(f"{name:17s} general {med['python']:.4f} s/s   compiled {med['compiled']:.4f} s/s"
              f"   ratio {med['python'] / med['compiled']:.1f}")


def first_use() -> None:
    t0 = time.perf_counter()
    from nonmin.sim import simulate

    mech = _mechanism("crossed_four_bar")
    t1 = time.perf_counter()
    simulate(mech, 0.1, dt=1e-3, engine="python", progress=False)
    t2 = time.perf_counter()
    simulate(mech, 0.1, dt=1e-3, engine="compiled", progress=False)
    t3 = time.perf_counter()
    print(f"import {t1 - t0:.1f} s, first general-driver run {t2 - t1:.1f} s, "
          f"first compiled run {t3 - t2:.1f} s")


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
