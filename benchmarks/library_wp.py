"""Work–precision of nonmin's methods on the library mechanisms that ``sim_bench.py`` has no
peer models of: A03 Andrews' squeezing mechanism (0.03 s, the Test Set's stiff problem: angles
at 0.03 s against its PSIDE reference) and A04 Bricard (10 s, one redundant constraint: no
closed form; energy and closure). Every method over its steps or tolerances; the rows have the
format of ``sim_bench.py``'s, so ``work_precision.py`` draws them.

Run ``python benchmarks/library_wp.py --json results/library_wp.json`` then
``python benchmarks/work_precision.py results/library_wp.json``.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import json
import statistics
import time
from pathlib import Path
from typing import Any

import numpy as np

HERE = Path(__file__).resolve().parent

#: (method, options) per mechanism: fixed steps and tolerances spanning coarse to tight.
CONFIGS: dict[str, list[dict[str, Any]]] = {
    "A03_andrews": [
        *({"method": "rk4", "dt": dt} for dt in (1e-5, 5e-6, 2e-6)),
        *({"method": m, "rtol": r, "atol": r} for m in ("dopri5", "dop853") for r in (1e-6, 1e-8, 1e-10, 1e-12)),
    ],
    "A04_bricard": [
        *({"method": "rk4", "dt": dt} for dt in (1e-2, 5e-3, 2e-3, 1e-3)),
        *({"method": m, "rtol": r, "atol": r * 1e-2} for m in ("dopri5", "dop853") for r in (1e-6, 1e-8, 1e-10)),
    ],
}
HORIZON = {"A03_andrews": 0.03, "A04_bricard": 10.0}


def run(name: str, cfg: dict[str, Any], repeat: int) -> dict[str, Any]:
    from nonmin import library, simulate
    from nonmin.validation._references import load_a03_reference

    T = HORIZON[name]
    mech = library.get(name)
    t_eval = np.array([0.0, T]) if name == "A03_andrews" else np.round(np.arange(0.0, T + 1e-9, 0.01), 10)
    walls = []
    tr = None
    for _ in range(repeat + 1):  # one warm-up run
        t0 = time.perf_counter()
        tr = simulate(mech, (0.0, T), t_eval=t_eval, throw=False, progress=False, **cfg)
        walls.append(time.perf_counter() - t0)
        if not tr.success:
            break
    assert tr is not None
    walls = walls[1:] or walls
    err = None
    if name == "A03_andrews" and tr.success:
        _, ref = load_a03_reference()
        err = float(np.max(np.abs(np.asarray(tr.q[-1])[:7] - ref[:7])))
    setting = f"{cfg['method']} projection" + (f" rtol={cfg['rtol']:g}" if "rtol" in cfg else "")
    ok = bool(tr.success)
    return {
        "engine": "nonmin", "setting": setting + f" [{tr.metadata.get('engine')}]", "mechanism": name,
        "dt": cfg.get("dt"), "t_final": T, "status": "ok" if ok else f"failed: {tr.message[:80]}",
        "on_branch": ok, "closure_max": float(np.max(tr.phi_norm)), "energy_drift": tr.energy_drift,
        "error_vs_reference_max": err, "n_steps": tr.n_steps, "n_rejected": tr.n_rejected,
        "wall_runs_s": walls, "wall_per_sim_s": statistics.median(walls) / T if ok else None,
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", default=str(HERE / "results" / "library_wp.json"))
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--mechanisms", default="A03_andrews,A04_bricard")
    a = ap.parse_args(argv)
    load = os.getloadavg()
    out: dict[str, Any] = {"command": "python benchmarks/library_wp.py " + " ".join(argv or []),
                           "date_utc": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
                           "load_before": [round(x, 2) for x in load], "mechanisms": {}}  # fmt: skip
    for name in a.mechanisms.split(","):
        rows = []
        for cfg in CONFIGS[name]:
            r = run(name, cfg, a.repeat)
            rows.append(r)
            print(f"{name:>12} {r['setting']:<36} dt={r['dt']} err={r['error_vs_reference_max']} "
                  f"dE={r['energy_drift']:.2e} closure={r['closure_max']:.1e} steps={r['n_steps']} "
                  f"rej={r['n_rejected']} wall/s={r['wall_per_sim_s']} {r['status']}", flush=True)  # fmt: skip
        out["mechanisms"][name] = {"t_final": HORIZON[name], "rows": rows}
    out["load_after"] = [round(x, 2) for x in os.getloadavg()]
    Path(a.json).parent.mkdir(parents=True, exist_ok=True)
    Path(a.json).write_text(json.dumps(out, indent=1, default=float), encoding="utf-8")
    print(f"wrote {a.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
