"""Measured potential of lock-step SIMD lanes (issue 20, target 1): builds ``lq_lanes.cpp``
with g++ (-O3 -mavx2 -ffp-contract=off) and runs it on the crossed four-bar's constraint
matrices A (8 × 9) at 4096 states of sweep_bench.py's random runs (2 s, RK4 dt = 1e-3,
samples every 10 ms): the equilibrated Householder LQ and L y = D b, one run at a time against
four runs in one AVX2 register, bitwise checked. See ``benchmarks/SWEEP.md``.

    OPENBLAS_NUM_THREADS=1 python benchmarks/lanes/lanes.py
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))


def main() -> int:
    import sweep_bench as sb

    from nonmin import _engine, library

    th, om = sb.states(24, 2026)
    _, bt = sb.nonmin_batch(th, om, None)
    model = library.get("crossed_four_bar").model
    prog = model.engine_program()
    mask = model.active_mask(None)
    terms, ws = prog.make_terms(), prog.make_workspace()
    Q = np.asarray(bt.q).reshape(-1, model.n)[:4096]
    V = np.asarray(bt.qd).reshape(-1, model.n)[:4096]
    mats = []
    for q, qd in zip(Q, V):
        prog.evaluate_into(terms, ws, 0.0, q, qd, mask, _engine.NEED_A)
        mats.append(np.array(terms.A))
    A = np.ascontiguousarray(np.stack(mats))
    K, m, n = A.shape
    with tempfile.TemporaryDirectory() as tmp:
        exe, data = Path(tmp) / "lq_lanes", Path(tmp) / "A.bin"
        A.tofile(data)
        subprocess.run(["g++", "-O3", "-mavx2", "-ffp-contract=off", "-o", str(exe), str(HERE / "lq_lanes.cpp")],
                       check=True)  # fmt: skip
        r = subprocess.run([str(exe), str(data), str(K), str(m), str(n)], capture_output=True, text=True)
    print(r.stdout.strip(), f"(load {os.getloadavg()[0]:.1f})")
    return r.returncode


if __name__ == "__main__":
    raise SystemExit(main())
