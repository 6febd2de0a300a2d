"""Batched model + kernel against MuJoCo's C batch, interleaved (issue 17, target 5).

The batched part of ``model_bench.py --engine`` (``Forward.batch`` on 10⁴ states of the
mechanism's own RK4 trajectory against ``mujoco.rollout.rollout(..., nstep=1)`` on 10⁴ states of
MuJoCo's trajectory, 1 and 2 threads each), with the four timings interleaved in each of 9
rounds and medians per state: on a shared machine a load change then hits both peers alike.
Prints one line per mechanism (µs per state and the ratios engine / MuJoCo).

    OPENBLAS_NUM_THREADS=1 python benchmarks/batch_interleaved.py
    OPENBLAS_NUM_THREADS=1 python benchmarks/batch_interleaved.py --cases A02_N40 --rounds 5

Each engine timing is preceded by a warm-up call on both thread counts (``Forward.batch``
makes its per-thread scratch on the first call and keeps it, as MuJoCo keeps its ``MjData``).
"""

from __future__ import annotations

import os
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import model_bench
import mujoco
from mujoco import rollout

from nonmin import _engine, library

N = 10_000
ROUNDS = 9
ALL_CASES = {
    "crossed_four_bar": ("crossed_four_bar", "crossed_four_bar", {}, "crossed_four_bar"),
    "A02_N2": ("A02 N=2", "A02_n_four_bar", {"N": 2}, "A02_N2"),
    "A02_N40": ("A02 N=40", "A02_n_four_bar", {"N": 40}, "A02_N40"),
    "A02_N80": ("A02 N=80", "A02_n_four_bar", {"N": 80}, "A02_N80"),
}
CASES = tuple(ALL_CASES[k] for k in ("crossed_four_bar", "A02_N2"))


def main() -> None:
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", default=",".join(("crossed_four_bar", "A02_N2")),
                    help=f"comma-separated, of {', '.join(ALL_CASES)}")  # fmt: skip
    ap.add_argument("--rounds", type=int, default=ROUNDS)
    args = ap.parse_args()
    for label, name, kw, bar in (ALL_CASES[k] for k in args.cases.split(",")):
        mech = library.get(name, **kw)
        m, s = mech.model, mech.state
        fwd = _engine.Forward(m.engine_program(), m.active_mask(s.active))
        tt, Q, QD = model_bench._trajectory_states(mech, N)
        mj, dat = model_bench._mujoco(bar)
        x0 = model_bench.mujoco_trajectory_states(mj, dat, N)
        datas = {t: [mujoco.MjData(mj) for _ in range(t)] for t in (1, 2)}
        for t in (1, 2):
            rollout.rollout(mj, datas[t], x0[:10], nstep=1)  # warm-up (pool, allocation)
            fwd.batch(tt[:128], Q[:128], QD[:128], t)  # warm-up (the kept per-thread scratch)
        res: dict[str, list[float]] = {k: [] for k in ("e1", "e2", "m1", "m2")}
        for _ in range(args.rounds):
            for t in (1, 2):
                t0 = time.perf_counter()
                fwd.batch(tt, Q, QD, t)
                res[f"e{t}"].append(time.perf_counter() - t0)
                t0 = time.perf_counter()
                rollout.rollout(mj, datas[t], x0, nstep=1)
                res[f"m{t}"].append(time.perf_counter() - t0)
        med = {k: 1e6 * statistics.median(v) / N for k, v in res.items()}
        print(f"{label}: engine 1 thread {med['e1']:.3f}, 2 threads {med['e2']:.3f} µs/state | "
              f"rollout 1 thread {med['m1']:.3f}, 2 threads {med['m2']:.3f} | engine / rollout "
              f"1 thread {med['e1'] / med['m1']:.2f}, 2 threads {med['e2'] / med['m2']:.2f} "
              f"(load {os.getloadavg()[0]:.1f})", flush=True)  # fmt: skip


if __name__ == "__main__":
    main()
