"""Work–precision of nonmin's methods on the library mechanisms that ``sim_bench.py`` has no
peer models of: A03 Andrews' squeezing mechanism (0.03 s, the Test Set's stiff problem: angles
at 0.03 s against its PSIDE reference) and A04 Bricard (10 s, one redundant constraint: P3
against a fine DOP853 run whose turning points match the quadrature period to 2e-12 s; energy
and closure), with MuJoCo on A04 (``--peers``: its Euler, default and stiff equalities). Every method over its steps or tolerances; the rows have the
format of ``sim_bench.py``'s, so ``work_precision.py`` draws them.

Run ``python benchmarks/library_wp.py --peers --json results/library_wp.json`` then
``python benchmarks/work_precision.py results/library_wp.json``.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import json
import statistics
import sys
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
        *({"method": "rk4", "dt": dt} for dt in (0.2, 0.1, 5e-2, 2e-2, 1e-2, 5e-3, 2e-3, 1e-3)),
        *({"method": m, "rtol": r, "atol": r * 1e-2} for m in ("dopri5", "dop853") for r in (1e-4, 1e-6, 1e-8, 1e-10)),
    ],
}
HORIZON = {"A03_andrews": 0.03, "A04_bricard": 10.0}


#: MuJoCo peer on A04 (issue 18, target 4): Euler (its default) over coarse to fine steps,
#: default and stiff equality settings (as sim_bench.py's: solref = 2 dt, solimp 0.99 0.999).
MUJOCO_DTS = (1e-2, 5e-3, 2e-3, 1e-3, 5e-4, 2e-4)
_A04_FINE: dict[str, np.ndarray] = {}


#: Output sampling interval of the A04 runs (s), both engines (``--sample``).
SAMPLE = {"dt": 0.01}


def a04_fine_reference() -> dict[str, np.ndarray]:
    """P3 every 0.01 s over 10 s from nonmin's DOP853 at rtol 1e-12 (its turning points lie
    within 1.8e-12 s of k·T/2 of the quadrature period, nonmin.validation.a04_bricard_period)."""
    if not _A04_FINE:
        from nonmin import library, simulate

        mech = library.get("A04_bricard")
        te = np.round(np.arange(0.0, 10.0 + 1e-9, 0.01), 10)
        tr = simulate(mech, (0.0, 10.0), method="dop853", rtol=1e-12, atol=1e-14, t_eval=te, progress=False)
        _A04_FINE["t"] = np.asarray(tr.t)
        _A04_FINE["P3"] = np.asarray(tr.outputs(mech.model)["P3.position"])
    k = round(SAMPLE["dt"] / 0.01)
    return {"t": _A04_FINE["t"][::k], "P3": _A04_FINE["P3"][::k]}


def _v(a: Any) -> str:
    return " ".join(repr(float(x)) for x in a)


def _a04_mjcf(dt: float, setting: str) -> str:
    """A04 as a MuJoCo hinge chain ground → rod1 … rod5 (body frames at the joints, aligned with
    the world at the tabulated configuration) closed by two <connect> points on J6's axis."""
    from nonmin.library.bricard import _JOINTS, _RODS

    mass, width = 1.0, 0.1
    axial, transverse = mass * width**2 / 6.0, mass * (1.0 + width**2) / 12.0
    eq = "" if setting == "default" else f' solref="{2.0 * float(dt)!r} 1" solimp="0.99 0.999 0.001"'
    xml, prev = "", np.zeros(3)
    for (name, start, end), (_, point, axis, _, _) in zip(_RODS, _JOINTS[:5], strict=True):
        p0, p1 = np.asarray(start), np.asarray(end)
        inertia = np.where(np.abs(p1 - p0) > 0.5, axial, transverse)
        c = 0.5 * (p0 + p1) - np.asarray(point)
        rel = np.asarray(point) - prev
        prev = np.asarray(point)
        xml += (f'<body name="{name}" pos="{_v(rel)}">'
                f'<joint name="{name}_j" type="hinge" axis="{_v(axis)}" pos="0 0 0"/>'
                f'<inertial pos="{_v(c)}" mass="{mass}" diaginertia="{_v(inertia)}"/>')  # fmt: skip
    xml += "</body>" * 5
    # rod5's frame sits at J5 = (0, -1, 1): J6 = (0, 0, 1) is (0, 1, 0) in it, (1, 0, 1) is (1, 1, 0)
    eqs = (f'<connect body1="rod5" body2="world" anchor="0 1 0"{eq}/>'
           f'<connect body1="rod5" body2="world" anchor="1 1 0"{eq}/>')  # fmt: skip
    return ('<mujoco model="bricard"><compiler angle="radian"/>'
            f'<option timestep="{float(dt)!r}" gravity="0 -9.81 0" integrator="Euler">'
            '<flag contact="disable" energy="enable"/></option>'
            f"<worldbody>{xml}</worldbody><equality>{eqs}</equality></mujoco>")  # fmt: skip


def run_mujoco_a04(dt: float, setting: str, repeat: int) -> dict[str, Any]:
    """One MuJoCo run of A04 over 10 s: P3 against the fine reference, energy, closure."""
    import mujoco

    T = HORIZON["A04_bricard"]
    model = mujoco.MjModel.from_xml_string(_a04_mjcf(dt, setting))
    data = mujoco.MjData(model)
    n = round(T / dt)
    every = max(1, round(SAMPLE["dt"] / dt))
    rod3 = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "rod3")
    rod5 = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "rod5")
    walls = []
    p3, energy, closure = [], [], []
    for rep in range(repeat + 1):
        mujoco.mj_resetData(model, data)
        mujoco.mj_forward(model, data)
        p3, energy, closure = [], [], []
        t0 = time.perf_counter()
        for k in range(n + 1):
            if k % every == 0:
                p3.append(data.xpos[rod3].copy())
                energy.append(float(data.energy[0] + data.energy[1]))
                R = data.xmat[rod5].reshape(3, 3)
                a = data.xpos[rod5] + R @ np.array([0.0, 1.0, 0.0]) - np.array([0.0, 0.0, 1.0])
                b = data.xpos[rod5] + R @ np.array([1.0, 1.0, 0.0]) - np.array([1.0, 0.0, 1.0])
                closure.append(max(float(np.abs(a).max()), float(np.abs(b).max())))
            if k < n:
                mujoco.mj_step(model, data)
        if rep:
            walls.append(time.perf_counter() - t0)
    ok = bool(np.all(np.isfinite(data.qpos)))
    ref = a04_fine_reference()
    P = np.array(p3)
    m = min(len(P), len(ref["P3"]))
    err = float(np.max(np.abs(P[:m] - ref["P3"][:m]))) if ok else None
    E = np.array(energy)
    return {
        "engine": "mujoco", "setting": setting, "mechanism": "A04_bricard", "dt": dt, "t_final": T,
        "status": "ok" if ok else "diverged", "on_branch": ok, "closure_max": float(np.max(closure)),
        "energy_drift": float(np.max(np.abs(E - E[0]))), "error_vs_reference_max": err,
        "n_steps": n, "n_rejected": 0, "wall_runs_s": walls,
        "wall_per_sim_s": statistics.median(walls) / T if ok else None,
    }  # fmt: skip


def run(name: str, cfg: dict[str, Any], repeat: int) -> dict[str, Any]:
    from nonmin import library, simulate
    from nonmin.validation._references import load_a03_reference

    T = HORIZON[name]
    mech = library.get(name)
    t_eval = np.array([0.0, T]) if name == "A03_andrews" else np.round(np.arange(0.0, T + 1e-9, SAMPLE["dt"]), 10)
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
    if name == "A04_bricard" and tr.success:
        p3 = np.asarray(tr.outputs(mech.model)["P3.position"])
        err = float(np.max(np.abs(p3 - a04_fine_reference()["P3"])))
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
    ap.add_argument("--peers", action="store_true", help="add MuJoCo (default and stiff) on A04")
    ap.add_argument("--sample", type=float, default=0.01, help="A04 output interval (s), a multiple of 0.01")
    a = ap.parse_args(argv)
    SAMPLE["dt"] = float(a.sample)
    load = os.getloadavg()
    out: dict[str, Any] = {"command": "python benchmarks/library_wp.py " + " ".join(sys.argv[1:] if argv is None else argv),
                           "date_utc": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
                           "load_before": [round(x, 2) for x in load], "mechanisms": {}}  # fmt: skip
    for name in a.mechanisms.split(","):
        rows = []
        peers = [("mujoco", s, dt) for s in ("default", "stiff") for dt in MUJOCO_DTS] \
            if name == "A04_bricard" and a.peers else []  # fmt: skip
        for cfg in [*CONFIGS[name], *peers]:
            r = run_mujoco_a04(cfg[2], cfg[1], a.repeat) if isinstance(cfg, tuple) else run(name, cfg, a.repeat)
            rows.append(r)
            print(f"{name:>12} {r['setting']:<36} dt={r['dt']} err={r['error_vs_reference_max']} "
                  f"dE={r['energy_drift']:.2e} closure={r['closure_max']:.1e} steps={r['n_steps']} "
                  f"rej={r['n_rejected']} wall/s={r['wall_per_sim_s']} {r['status']}", flush=True)  # fmt: skip
        key = name if name != "A04_bricard" or a.sample == 0.01 else f"{name}_samples_{a.sample:g}s"
        for r in rows:
            r["mechanism"] = key
        out["mechanisms"][key] = {"t_final": HORIZON[name], "rows": rows}
    out["load_after"] = [round(x, 2) for x in os.getloadavg()]
    Path(a.json).parent.mkdir(parents=True, exist_ok=True)
    Path(a.json).write_text(json.dumps(out, indent=1, default=float), encoding="utf-8")
    print(f"wrote {a.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
