"""The dual-arm grasp at the coarse end of its work–precision diagram (issue 18, target 4).

Pinocchio's RK4 loop at its coarsest step (dt 1.6e-2, Baumgarte Kp 100 and 0) against nonmin's
coarsest runs of the same robot without its joint limits (``robot_bench.without_joint_limits``:
the peers' models have none and the motion stays inside them over the 0.6 s): RK4 at dt 1e-2 …
1.6e-2 with the samples every 0.01 s (as ``robot_bench.py --wp`` records them) or at the step ends
(``t_eval=None``), and DOPRI5 at rtol 1e-3 / 3e-3 and DOP853 at rtol 1e-2 at their step ends. Errors as in
``robot_bench.py``: the largest joint-angle error against nonmin's RK4 at dt 1e-4 at the instants
common with its 0.01-s grid (``robot_bench.py``'s rule: a run at dt 1.6e-2 is compared at the
multiples of 0.08 s), and at every sample of the run (the reference sampled at them); energy
drift and closure. Process CPU time per simulated second, medians over
``--rounds`` interleaved rounds (``--calls`` runs of each setting per round), in one process::

    OPENBLAS_NUM_THREADS=1 python benchmarks/dual_coarse_end.py            # ~40 s
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import robot_bench as rb

T = 0.6


def settings(case: rb.Case) -> list[tuple[str, Callable[[], dict[str, Any]]]]:
    """The timed settings: Pinocchio's two coarse points, then nonmin's candidates."""
    free = rb.without_joint_limits(case.model)
    out: list[tuple[str, Callable[[], dict[str, Any]]]] = [
        ("pinocchio rk4 Kp=100 dt 1.6e-2", lambda: rb.run_pinocchio(case, 1.6e-2, T)),
        ("pinocchio rk4 Kp=0 dt 1.6e-2", lambda: rb.run_pinocchio(case, 1.6e-2, T, 0.0)),
    ]

    def nm(label: str, t_eval: Any, **kw: Any) -> None:
        out.append((f"nonmin {label}", lambda: _run_nonmin(case, free, t_eval, **kw)))

    grid = rb._samples(T)
    for dt in (1e-2, 1.2e-2):
        nm(f"rk4 dt {dt:g}, samples 0.01", grid, method="rk4", dt=dt)
    for dt in (1e-2, 1.2e-2, 1.5e-2, 1.6e-2, 2e-2):
        nm(f"rk4 dt {dt:g}, step ends", None, method="rk4", dt=dt)
    for m, r in (("dopri5", 1e-3), ("dopri5", 3e-3), ("dop853", 1e-2)):
        nm(f"{m} rtol {r:g}, step ends", None, method=m, rtol=r, atol=r * 1e-2)
    return out


def _run_nonmin(case: rb.Case, model: Any, t_eval: Any, **kw: Any) -> dict[str, Any]:
    import nonmin

    traj = nonmin.simulate(model, (0.0, T), case.q0, np.zeros(model.n), t_eval=t_eval, progress=False, **kw)
    return {"t": traj.t, "q": traj.q, "closure": float(np.max(traj.phi_norm)),
            "dE": float(np.max(np.abs(traj.energy - traj.energy[0]))), "status": traj.status.value,
            "n_steps": traj.n_steps}  # fmt: skip


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--calls", type=int, default=5, help="runs of each setting per round")
    a = ap.parse_args(argv)
    import os

    load0 = os.getloadavg()
    case = rb.CASES["dual_arm_grasp"](T)
    grid = rb.run_nonmin(case, 1e-4, T)
    cases = settings(case)
    for name, f in cases:
        r = f()
        t = np.asarray(r["t"])
        keep = t <= T + 1e-12  # Pinocchio's dt 1.6e-2 runs 38 steps, to 0.608 s
        # the reference (robot_bench's: nonmin RK4 at dt 1e-4) at the run's own instants
        own = rb.run_nonmin(case, 1e-4, T, t_eval=t[keep])
        err_grid = rb._errors(case, r["t"], r["q"], (grid["t"], grid["q"]))
        err_all = rb._errors(case, t[keep], np.asarray(r["q"])[keep], (own["t"], own["q"]))
        print(f"{name:38s} {r['status']}: err {err_grid:.2g} rad at the 0.01-s grid's common instants, "
              f"{err_all:.2g} at all {int(keep.sum())} samples; dE {r['dE']:.2g} J, closure {r['closure']:.1e} m",
              flush=True)
    res: dict[str, list[float]] = {n: [] for n, _ in cases}
    for _ in range(a.rounds):
        for name, f in cases:
            c = time.process_time()
            for _ in range(a.calls):
                f()
            res[name].append((time.process_time() - c) / a.calls / T)
    base = statistics.median(res[cases[0][0]])
    for k, v in res.items():
        med = statistics.median(v)
        print(f"{k:38s} {med * 1e3:6.2f} ms CPU per simulated s (range {min(v) * 1e3:.2f}–{max(v) * 1e3:.2f}), "
              f"{med / base:.2f}× Pinocchio Kp=100")
    print(f"load {load0[0]:.1f} → {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
