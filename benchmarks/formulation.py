"""Choosing a formulation: A02 N four-bar in body coordinates (the library model) against
natural coordinates (points only), at equal RK4 steps (issue 18, "formulation guidance").

Models:

* ``body`` — ``nonmin.library`` A02 (planar builder): every bar a body with (x, y, θ), pins as
  two rows each: 6N + 3 coordinates, 6N + 2 rows.
* ``natural`` — the same mechanism in natural coordinates (a SymPy model compiled to the
  engine's tape): the moving points B0 … BN only (2N + 2 coordinates), one rigid-distance row
  per bar, ``φ = s (|B_i − A_i|² − 1)`` (cranks) and ``s (|B_i − B_{i−1}|² − 1)`` (couplers),
  default ``s = 1/2``; constant mass matrix (uniform bar: ``m/6 [2 1; 1 2] ⊗ I₂``; a crank
  pinned at its end: ``m/3 I₂`` on its tip), gravity at the points (half of each bar's weight
  on each end).

Controlled variants (same motion, one change each): ``natural`` with the rows scaled by 100
(``s = 50``: the scaling of A); the rank tolerance (``rank_rtol`` 1e-6 and 1e-13 instead of the
fixed-step default 1e-10); no projection (``stabilization=None``); the projection in the
Euclidean metric; the singular-passage placement off (``RK4(passages=False)``).

Measured per run: B0's largest distance from the exact 1-DOF reduction
(:func:`nonmin.library.n_four_bar_reference`) over samples every 0.01 s, the energy drift,
the closure, CPU time (process, the load-independent measure) and wall time.

Run ``python benchmarks/formulation.py --N 2 --dts 1e-2,5e-3,2e-3,1e-3 --variants all`` and
``python benchmarks/formulation.py --N 40 --dts 1e-2,5e-3,2e-3 --variants body,natural``
(``--json`` writes the rows).
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import json
import time
from pathlib import Path
from typing import Any

import numpy as np

HERE = Path(__file__).resolve().parent

VARIANTS = ("body", "natural", "natural_x100", "body_rank1e-6", "body_rank1e-13", "natural_rank1e-6",
            "body_noproj", "natural_noproj", "body_euclid", "natural_euclid", "body_nopassage",
            "natural_nopassage")  # fmt: skip


def natural_model(N: int, *, scale: float = 0.5, g: float = 9.81) -> tuple[Any, np.ndarray, np.ndarray]:
    """A02 in natural coordinates: (model, q0, qd0); q = (x0, y0, …, xN, yN) of B0 … BN."""
    import sympy as sp

    from nonmin.model.symbolic import SymbolicConstraint, SymbolicModel

    x = sp.symbols(f"x0:{N + 1}")
    y = sp.symbols(f"y0:{N + 1}")
    xd = sp.symbols(f"xd0:{N + 1}")
    yd = sp.symbols(f"yd0:{N + 1}")
    T: Any = 0
    V: Any = 0
    cons = []
    for i in range(N + 1):  # crank i: pinned at A_i = (i, 0), tip B_i; T = (m/3)|Ḃ|²/2
        T += sp.Rational(1, 6) * (xd[i] ** 2 + yd[i] ** 2)
        V += g * y[i] / 2
        cons.append(SymbolicConstraint.holonomic(f"crank{i}", scale * ((x[i] - i) ** 2 + y[i] ** 2 - 1)))
    for i in range(1, N + 1):  # coupler B_{i-1} B_i: T = m/6 (|ṗ|² + ṗ·ṙ + |ṙ|²)
        T += sp.Rational(1, 6) * (xd[i - 1] ** 2 + yd[i - 1] ** 2 + xd[i - 1] * xd[i] + yd[i - 1] * yd[i]
                                  + xd[i] ** 2 + yd[i] ** 2)  # fmt: skip
        V += g * (y[i - 1] + y[i]) / 2
        cons.append(SymbolicConstraint.holonomic(
            f"coupler{i}", scale * ((x[i] - x[i - 1]) ** 2 + (y[i] - y[i - 1]) ** 2 - 1)))  # fmt: skip
    q = [v for i in range(N + 1) for v in (x[i], y[i])]
    qd = [v for i in range(N + 1) for v in (xd[i], yd[i])]
    model = SymbolicModel.from_energy(f"A02_natural_{N}", q=q, qd=qd, T=T, V=V, constraints=cons)
    q0 = np.array([v for i in range(N + 1) for v in (float(i), 1.0)])
    qd0 = np.array([v for i in range(N + 1) for v in (1.0, 0.0)])
    return model, q0, qd0


_CACHE: dict[tuple[str, int, float], Any] = {}


def _model(kind: str, N: int, scale: float) -> tuple[Any, np.ndarray, np.ndarray]:
    key = (kind, N, scale)
    if key not in _CACHE:
        if kind == "body":
            from nonmin import library

            mech = library.get("A02_n_four_bar", N=N)
            _CACHE[key] = (mech.model, mech.state.q, mech.state.qd)
        else:
            _CACHE[key] = natural_model(N, scale=scale)
    return _CACHE[key]


def run(variant: str, N: int, dt: float, T: float) -> dict[str, Any]:
    from nonmin import simulate
    from nonmin.library import n_four_bar_reference
    from nonmin.sim import RK4, Projection

    kind = variant.split("_")[0]
    scale = 50.0 if variant.endswith("x100") else 0.5
    model, q0, qd0 = _model(kind, N, scale)
    kw: dict[str, Any] = {"method": RK4(dt), "stabilization": Projection()}
    if "rank" in variant:
        kw["rank_rtol"] = float(variant.split("rank")[1])
    if variant.endswith("noproj"):
        kw["stabilization"] = None
    if variant.endswith("euclid"):
        kw["stabilization"] = Projection(metric="euclidean")
    if variant.endswith("nopassage"):
        kw["method"] = RK4(dt, passages=False)
    t_eval = np.round(np.arange(0.0, T + 1e-9, 0.01), 10)
    c0, w0 = time.process_time(), time.perf_counter()
    tr = simulate(model, (0.0, T), q0, qd0, t_eval=t_eval, progress=False, throw=False, **kw)
    cpu, wall = time.process_time() - c0, time.perf_counter() - w0
    q = np.asarray(tr.q)
    if kind == "body":  # B0 = crank0's centre + ½ (cos θ, sin θ)
        B0 = np.stack([q[:, 0] + 0.5 * np.cos(q[:, 2]), q[:, 1] + 0.5 * np.sin(q[:, 2])], axis=1)
    else:
        B0 = q[:, :2]
    ref = n_four_bar_reference(np.asarray(tr.t), N=N)["B0.position"]
    d = np.linalg.norm(B0 - ref, axis=1)
    return {"variant": variant, "N": N, "dt": dt, "t_final": T, "n": int(q.shape[1]),
            "status": tr.status.name, "t_end": float(tr.t[-1]), "b0_error_max": float(d.max()),
            "b0_error_end": float(d[-1]), "energy_drift": float(tr.energy_drift),
            "closure_max": float(np.max(tr.phi_norm)), "steps": int(tr.n_steps), "cpu_s": cpu,
            "wall_s": wall, "engine": tr.metadata.get("engine")}  # fmt: skip


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--N", type=int, default=2)
    ap.add_argument("--t-final", type=float, default=None, help="default: 10 s for N = 2, else 20 s")
    ap.add_argument("--dts", default="1e-2,5e-3,2e-3,1e-3")
    ap.add_argument("--variants", default="body,natural", help="comma list, or 'all': " + ",".join(VARIANTS))
    ap.add_argument("--json", default=None)
    a = ap.parse_args(argv)
    T = a.t_final if a.t_final is not None else (10.0 if a.N == 2 else 20.0)
    variants = VARIANTS if a.variants == "all" else tuple(a.variants.split(","))
    out: dict[str, Any] = {"command": "python benchmarks/formulation.py " + " ".join(argv or []),
                           "date_utc": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
                           "load_before": [round(x, 2) for x in os.getloadavg()], "rows": []}  # fmt: skip
    print("| variant | n | dt | B0 error max [m] | B0 error at T [m] | energy drift [J] | closure [m] | CPU [s] |")
    print("|---|---|---|---|---|---|---|---|")
    for dt in (float(s) for s in a.dts.split(",")):
        for v in variants:
            r = run(v, a.N, dt, T)
            out["rows"].append(r)
            st = "" if r["status"] == "SUCCESS" else f" ({r['status']} at {r['t_end']:.3g} s)"
            print(f"| {v}{st} | {r['n']} | {dt:g} | {r['b0_error_max']:.2e} | {r['b0_error_end']:.2e} | "
                  f"{r['energy_drift']:.2e} | {r['closure_max']:.1e} | {r['cpu_s']:.2f} |", flush=True)  # fmt: skip
    out["load_after"] = [round(x, 2) for x in os.getloadavg()]
    if a.json:
        Path(a.json).write_text(json.dumps(out, indent=1), encoding="utf-8")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
