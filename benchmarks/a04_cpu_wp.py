"""A04 Bricard: nonmin spatial (n = 35) against MuJoCo in one process, CPU time per run
(time.process_time instead of perf_counter, for a loaded machine): library_wp.py's runs, the
spatial RK4 dt 0.2 … 1e-2 and DOP853 rtol 1e-4 … 1e-10, MuJoCo default and stiff over its steps.

    python benchmarks/a04_cpu_wp.py [out.json]
"""
import json
import sys
import time
import types
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import library_wp as W

W.time = types.SimpleNamespace(perf_counter=time.process_time)
rows = []
cfgs = [{"method": "rk4", "dt": dt} for dt in (0.2, 0.1, 5e-2, 2e-2, 1e-2)] + \
       [{"method": "dop853", "rtol": r, "atol": r * 1e-2} for r in (1e-4, 1e-6, 1e-8, 1e-10)]
for cfg in cfgs:
    rows.append(W.run("A04_bricard", cfg, 2))
    print(rows[-1]["setting"], cfg.get("dt"), rows[-1]["error_vs_reference_max"], rows[-1]["energy_drift"], rows[-1]["wall_per_sim_s"], flush=True)
for setting in ("default", "stiff"):
    for dt in W.MUJOCO_DTS:
        rows.append(W.run_mujoco_a04(dt, setting, 2))
        print("mujoco", setting, dt, rows[-1]["error_vs_reference_max"], rows[-1]["energy_drift"], rows[-1]["wall_per_sim_s"], flush=True)
if len(sys.argv) > 1:
    Path(sys.argv[1]).write_text(json.dumps(rows, indent=1))
