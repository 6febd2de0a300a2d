"""A03 Andrews at the coarse end of its work–precision diagram (issue 18, target 4, gap a).

MuJoCo's Euler at dt 2e-4 (1.7 rad stiff, 4.2 rad default off the Test Set's reference at 0.03 s)
against nonmin's coarsest runs: RK4 at dt 1e-3 … 3e-3 (also without the singular-passage
placement, ``RK4(dt, passages=False)``: Andrews' mechanism passes no singular configuration) and
DOPRI5/DOP853 at rtol 1e-2, with the
samples every 1e-3 s (``t_eval``) or at the step ends (``t_eval=None``), and two samples only.
Process CPU time per 0.03-s run, medians over 5 interleaved rounds (30 calls per nonmin round,
MuJoCo's own timed runs of ``andrews_peers.run_mujoco``), in one process::

    OPENBLAS_NUM_THREADS=1 python benchmarks/a03_coarse_end.py
"""

from __future__ import annotations

import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import andrews_peers as ap

from nonmin import library, simulate
from nonmin.sim import RK4
from nonmin.validation._references import load_a03_reference

ap.CLOCK[0] = time.process_time
T = 0.03


def main() -> None:
    mech = library.get("A03_andrews")
    _, ref = load_a03_reference()
    te = np.round(np.arange(0.0, T + 1e-12, 1e-3), 10)

    def nm(cfg: dict, teval: object):
        return lambda: simulate(mech, (0, T), t_eval=teval, progress=False, throw=False, **cfg)

    cases = [
        ("rk4 dt 1e-3, t_eval 1e-3", nm({"method": "rk4", "dt": 1e-3}, te)),
        ("rk4 dt 1e-3, step ends", nm({"method": "rk4", "dt": 1e-3}, None)),
        ("rk4 dt 1.5e-3, t_eval 1e-3", nm({"method": "rk4", "dt": 1.5e-3}, te)),
        ("rk4 dt 1.5e-3, step ends", nm({"method": "rk4", "dt": 1.5e-3}, None)),
        ("rk4 dt 2e-3, step ends", nm({"method": "rk4", "dt": 2e-3}, None)),
        ("rk4 dt 3e-3, step ends", nm({"method": "rk4", "dt": 3e-3}, None)),
        ("rk4 dt 1e-3, t_eval (0, T)", nm({"method": "rk4", "dt": 1e-3}, [0.0, T])),
        ("rk4 dt 2e-3, t_eval (0, T)", nm({"method": "rk4", "dt": 2e-3}, [0.0, T])),
        ("rk4(passages=False) dt 2e-3, step ends", nm({"method": RK4(dt=2e-3, passages=False)}, None)),
        ("rk4(passages=False) dt 1.5e-3, step ends", nm({"method": RK4(dt=1.5e-3, passages=False)}, None)),
        ("rk4(passages=False) dt 1.5e-3, t_eval 1e-3", nm({"method": RK4(dt=1.5e-3, passages=False)}, te)),
        ("rk4(passages=False) dt 1e-3, t_eval 1e-3", nm({"method": RK4(dt=1e-3, passages=False)}, te)),
        ("dopri5 rtol 1e-2, step ends", nm({"method": "dopri5", "rtol": 1e-2}, None)),
        ("dop853 rtol 1e-2, step ends", nm({"method": "dop853", "rtol": 1e-2}, None)),
    ]
    for name, f in cases:
        tr = f()
        err = float(np.max(np.abs(tr.q[-1][:7] - ref[:7]))) if tr.success else float("nan")
        print(f"{name:42s} ok={tr.success} err {err:.2g} rad, dE {tr.energy_drift:.2g} J, "
              f"closure {np.max(tr.phi_norm):.1e} m, {tr.n_steps} steps, {len(tr.t)} samples")
    res: dict[str, list[float]] = {n: [] for n, _ in cases}
    for st in ("stiff", "default"):
        res[f"mujoco Euler {st} dt 2e-4"] = []
    for rnd in range(5):
        for name, f in cases:
            c = time.process_time()
            for _ in range(30):
                f()
            res[name].append((time.process_time() - c) / 30)
        for st in ("stiff", "default"):
            r = ap.run_mujoco(2e-4, st, "Euler", 5)
            res[f"mujoco Euler {st} dt 2e-4"].append(statistics.median(r["wall_runs_s"]))
            if rnd == 0:
                print(f"mujoco Euler {st} dt 2e-4: err {r['error_vs_reference_max']:.2g} rad, "
                      f"dE {r['energy_drift']:.2g} J, closure {r['closure_max']:.1e} m")
    for k, v in res.items():
        print(f"{k:42s} {statistics.median(v) * 1e3:.3f} ms CPU per 0.03-s run")


if __name__ == "__main__":
    main()
