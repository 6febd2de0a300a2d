"""Where projecting RK4's stages pays near a singular passage (docs/theory.md, "Projected RK4
stages near a singular passage"), and the error sequences of issue 18's targets 1–2.

``--per-step CASE DT T``: the general driver runs CASE (``cfb`` the crossed four-bar, ``a02``
A02 N = 2, ``a02_40`` N = 40) for T s at RK4 step DT; every step is taken from the same state
twice, with and without projected stages (both ends projected): ``e_x`` = the difference of the
two ends, ``e_o`` = the projected-stage step's own error by step doubling (×16/15). Prints, near
each passage, σ, |σ̇|, τ/h = σ/(|σ̇| h), ‖q̇‖/‖q̈‖ and e_x/e_o (velocity, max norm).

``--sequences``: the engine's error sequences (crossed four-bar: 10 s energy and branch residual
at dt 1e-3 … 1e-4 with every step, and at dt 1e-3 … 5e-2 sampled every 0.01 s; A02 N = 2, 10 s,
samples every 0.01 s: B0 error against the exact reduction and energy at dt 4e-3 … 5e-5 and at
coarse steps).

    python benchmarks/passage_stages.py --per-step cfb 1e-3 1.2
    python benchmarks/passage_stages.py --sequences [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any

import numpy as np

import nonmin.sim._integrators as integ
from nonmin.library._iftomm import a02_n_four_bar, n_four_bar_reference
from nonmin.library._planar import crossed_four_bar
from nonmin.sim import RK4, simulate


def _rk4(fun: Any, t: float, y: np.ndarray, f: np.ndarray | None, h: float, project: Any, staged: bool) -> np.ndarray:
    def proj(tt: float, yy: np.ndarray) -> np.ndarray:
        return project(tt, yy) if staged else yy

    k1 = fun(t, y) if f is None else f
    k2 = fun(t + 0.5 * h, proj(t + 0.5 * h, y + 0.5 * h * k1))
    k3 = fun(t + 0.5 * h, proj(t + 0.5 * h, y + 0.5 * h * k2))
    k4 = fun(t + h, proj(t + h, y + h * k3))
    return y + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)


def per_step(case: str, dt: float, T: float) -> list[dict[str, float]]:
    rec: list[dict[str, float]] = []
    original = integ._fixed_step

    def both_ways(method: Any, fun: Any, state: Any, t_bound: float, project: Any, place: Any) -> Any:
        t = state.t
        h = integ._clip(t, state.h if place is None else place(t, state.h), t_bound)
        if project is None or not isinstance(place, integ.SingularPassages):
            return original(method, fun, state, t_bound, project, place)
        f = fun(t, state.y) if state.f is None else state.f
        yp = project(t + h, _rk4(fun, t, state.y, f, h, project, True))
        yu = project(t + h, _rk4(fun, t, state.y, f, h, project, False))
        ym = project(t + 0.5 * h, _rk4(fun, t, state.y, f, 0.5 * h, project, True))
        y2 = project(t + h, _rk4(fun, t + 0.5 * h, ym, None, 0.5 * h, project, True))
        n = len(yp) // 2
        holds = place.t_star is not None and t < place.t_star <= t + (1.0 + integ.PASSAGE_BAND) * h
        rec.append({"t": t, "h": h, "sigma": place.sigma, "rate": place.rate, "holds": float(holds),
                    "T_motion": float(np.linalg.norm(f[:n]) / np.linalg.norm(f[n:])),
                    "e_x": float(np.abs(yu[n:] - yp[n:]).max()),
                    "e_o": float(np.abs(y2[n:] - yp[n:]).max()) * 16 / 15})  # fmt: skip
        t1 = t_bound if h == t_bound - t else t + h
        return integ.StepResult(integ.StepperState(t1, yp, None, state.h), h, 0, None)

    integ._fixed_step = both_ways  # type: ignore[assignment]
    try:
        mech = crossed_four_bar() if case == "cfb" else a02_n_four_bar(N=40 if case == "a02_40" else 2)
        simulate(mech, (0.0, T), method=RK4(dt), engine="python", progress=False)
    finally:
        integ._fixed_step = original  # type: ignore[assignment]
    print(" t        h        sigma     |dsig/dt|  tau/h   |qd|/|qdd|  holds  e_x/e_o")
    for r in rec:
        tau_h = r["sigma"] / (r["rate"] * r["h"]) if r["rate"] > 0 else float("inf")
        if tau_h < 40 or r["holds"]:
            print(f"{r['t']:.4f}  {r['h']:.1e}  {r['sigma']:.2e}  {r['rate']:.2e}  {tau_h:7.2f}  {r['T_motion']:.3e}"
                  f"   {int(r['holds'])}    {r['e_x'] / max(r['e_o'], 1e-300):.2e}")  # fmt: skip
    return rec


def _a02(dt: float, rtol: float = 1e-12, T: float = 10.0) -> tuple[float, float, int]:
    tr = simulate(a02_n_four_bar(N=2), (0.0, T), method=RK4(dt), t_eval=np.linspace(0, T, 1001), progress=False)
    ref = n_four_bar_reference(tr.t, N=2, rtol=rtol, atol=rtol)
    th = tr.q[:, 2]
    b0 = np.stack([tr.q[:, 0] + 0.5 * np.cos(th), tr.q[:, 1] + 0.5 * np.sin(th)], axis=1)
    return float(np.abs(b0 - ref["B0.position"]).max()), float(np.abs(tr.energy - tr.energy[0]).max()), tr.n_steps


def _cfb(dt: float, T: float = 10.0, spacing: float | None = None) -> tuple[float, float, int]:
    mech = crossed_four_bar()
    kw = {} if spacing is None else {"t_eval": np.linspace(0, T, round(T / spacing) + 1)}
    tr = simulate(mech, (0.0, T), method=RK4(dt), progress=False, **kw)
    branch = max(abs(float(mech.model.outputs(t, q, qd)["anti_branch_residual"])) for t, q, qd in zip(tr.t, tr.q, tr.qd))
    return float(np.abs(tr.energy - tr.energy[0]).max()), branch, tr.n_steps


def sequences() -> dict[str, tuple[float, float, int]]:
    out: dict[str, tuple[float, float, int]] = {}
    for dt in (1e-3, 7e-4, 5e-4, 2.5e-4, 1e-4):
        out[f"crossed four-bar dt {dt:g}, every step: energy J, branch, steps"] = _cfb(dt)
    for dt in (1e-3, 1e-2, 2e-2, 5e-2):
        out[f"crossed four-bar dt {dt:g}, every 0.01 s: energy J, branch, steps"] = _cfb(dt, spacing=0.01)
    for dt in (4e-3, 2e-3, 1e-3, 1e-2, 2e-2, 5e-2):
        out[f"A02 N=2 dt {dt:g}: B0 m, energy J, steps"] = _a02(dt)
    for dt in (2.5e-4, 2e-4, 1e-4, 5e-5):
        out[f"A02 N=2 dt {dt:g} (reference rtol 1e-13): B0 m, energy J, steps"] = _a02(dt, rtol=1e-13)
    for k, v in out.items():
        print(f"{k:70s} {v[0]:.3e} {v[1]:.3e} {v[2]}")
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--per-step", nargs=3, metavar=("CASE", "DT", "T"))
    ap.add_argument("--sequences", action="store_true")
    ap.add_argument("--json", default="")
    a = ap.parse_args()
    res: dict[str, Any] = {}
    if a.per_step:
        res["per_step"] = per_step(a.per_step[0], float(a.per_step[1]), float(a.per_step[2]))
    if a.sequences:
        res["sequences"] = sequences()
    if not res:
        ap.print_help(sys.stderr)
    if a.json:
        with open(a.json, "w") as fh:
            json.dump(res, fh, indent=1)


if __name__ == "__main__":
    main()
