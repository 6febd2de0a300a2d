"""Per-run work of simulate_batch against simulate one by one, for instruction counts.

Run under ``valgrind --tool=callgrind`` with 1 and with 3 runs; the difference of the process
totals over 2 is the per-run count (imports and model loading cancel), reproducible on a loaded
machine where wall times are not::

    python benchmarks/batch_instructions.py --prepare            # model + 8 states (seed 2026)
    valgrind --tool=callgrind python benchmarks/batch_instructions.py batch 1   # and 3
    valgrind --tool=callgrind python benchmarks/batch_instructions.py one 1     # and 3

The crossed four-bar over 2 s, RK4 dt = 1e-3, samples every 10 ms (sweep_bench.py's runs).

The batch evaluates W = 4 runs in lock-step lanes (AVX2; engine/src/lanes.hpp): a group needs
4 runs, so its per-run count is (8 runs − 4 runs) / 4; ``NONMIN_LANES=0`` gives the scalar batch
on the same runs, and ``one 4`` / ``one 8`` the same runs one by one::

    NONMIN_LANES=1 valgrind --tool=callgrind python benchmarks/batch_instructions.py batch 4   # and 8
"""

from __future__ import annotations

import argparse
import pickle
import tempfile
from pathlib import Path

import numpy as np

CACHE = Path(tempfile.gettempdir()) / "nonmin_batch_instructions.pkl"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("mode", nargs="?", choices=("batch", "one"))
    ap.add_argument("k", nargs="?", type=int, default=1)
    ap.add_argument("--prepare", action="store_true", help="build the model once (it is slow under valgrind)")
    args = ap.parse_args()
    if args.prepare or not CACHE.exists():
        from nonmin import library
        from nonmin.library._planar import _cfb_coordinates

        rng = np.random.default_rng(2026)
        th = rng.uniform(0.0, 2 * np.pi, 8)
        om = rng.uniform(5.0, 9.0, 8) * rng.choice([-1.0, 1.0], 8)
        Q, V = _cfb_coordinates(th, om)
        CACHE.write_bytes(pickle.dumps((library.get("crossed_four_bar").model, Q, V)))
    if args.mode is None:
        return 0
    from nonmin.sim import simulate, simulate_batch

    m, Q, V = pickle.loads(CACHE.read_bytes())
    t = np.linspace(0.0, 2.0, 201)
    if args.mode == "batch":
        bt = simulate_batch(m, 2.0, Q[: args.k], V[: args.k], dt=1e-3, t_eval=t, threads=1)
        print(bt.n_steps.tolist(), bt.n_rhs.tolist())
    else:
        for i in range(args.k):
            tr = simulate(m, 2.0, Q[i], V[i], dt=1e-3, t_eval=t, progress=False)
            print(tr.n_steps, tr.n_rhs)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
