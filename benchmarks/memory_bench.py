"""Peak resident memory of a simulation (issue 17, target 6: a 20 s A02 N = 40 run ≤ 150 MB).

Each setting runs in a fresh process (``ru_maxrss`` is a high-water mark): ``import nonmin`` and
the library model first (the baseline), then ``simulate`` of A02 N = 40 (243 coordinates, 242
rows) for 20 s with RK4 on the engine, samples every 0.01 s (2001 samples) or every step. Prints
the peak RSS after the import and after the run, in MB (MiB):

    python benchmarks/memory_bench.py [--every-step]
"""

from __future__ import annotations

import argparse
import subprocess
import sys

SCRIPT = """
import resource, sys
import numpy as np
import nonmin
from nonmin import library
mech = library.get("A02_n_four_bar", N=40)
r0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
dt, every = float(sys.argv[1]), sys.argv[2] == "every"
kw = {} if every else {"t_eval": np.linspace(0.0, 20.0, 2001)}
tr = nonmin.simulate(mech, (0.0, 20.0), dt=dt, progress=False, **kw)
r1 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
print(f"{r0 / 1024:.1f} {r1 / 1024:.1f} {tr.n_steps} {len(tr.t)} {tr.metadata['engine']}")
"""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--every-step", action="store_true", help="also record every step (dt 1e-3)")
    a = ap.parse_args()
    settings = [(1e-3, "sampled"), (1e-2, "sampled")] + ([(1e-3, "every")] if a.every_step else [])
    print("| RK4 dt | samples | peak RSS after import (MB) | peak RSS after the run (MB) | steps | engine |")
    print("|---|---|---:|---:|---:|---|")
    for dt, mode in settings:
        out = subprocess.run([sys.executable, "-c", SCRIPT, str(dt), mode], capture_output=True,
                             text=True, check=True).stdout.split()  # fmt: skip
        r0, r1, steps, _, eng = out[0], out[1], out[2], out[3], " ".join(out[4:])
        what = "every 0.01 s" if mode == "sampled" else "every step"
        print(f"| {dt:g} | {what} | {r0} | {r1} | {steps} | {eng} |", flush=True)


if __name__ == "__main__":
    main()
