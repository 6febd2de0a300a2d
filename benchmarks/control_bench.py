"""The cost of control in the engine's loop: controlled / uncontrolled wall time (issue 17, target 3).

For each case the same run (RK4, dt = 1e-3, projection, from the same state) is timed without a
controller and with each built-in controller, all compiled into the engine's loop
(``engine/src/sim_control.cpp``):

* ``regulator``: ``Regulator(target, Kp=50, Kd=10)``, the target being where the uncontrolled run
  is after 0.3 s;
* ``tracker``: ``Tracker(..., method="computed_torque")`` following a clamped cubic spline
  (``Reference.spline``) through the uncontrolled run sampled every 0.05 s (the engine evaluates
  the spline and projects it onto the manifold at every new time);
* ``passivity``: the same reference with the default ``Tracker`` law (``method="passivity"``,
  Slotine–Li on the projected dynamics, λ = 10, Kp = 100, Kd = 10; compiled as ``Law::passivity``:
  C and Ȧ from the program). Its gains are torques, applied through M̄⁻¹: with the computed-torque
  gains (Kp 400, Kd 40) the dual-arm grasp, whose wrists have M_ii = 0.0038, is a stiffness of
  ~1e4 1/s that RK4 at dt 1e-3 cannot follow (measured: |q̇| past 20 rad/s at t = 0.011 s, 337
  rad/s by 0.15 s, then NotPositiveDefiniteError; bounded at dt 2.5e-4); with Kp 100, Kd 10 every
  case runs to its end (2026-11-27 19:45);
* ``force``: ``ForceControl(regulator, {constraint: value})``, the force of one loop closure
  commanded (``on_infeasible="least_squares"`` where the actuators cannot reach it: the cost is
  the same);
* ``python_regulator`` (``--python``): a user's Python function computing the same law, called
  back by the engine (the escape hatch), for scale.

Cases: ``ur5_point`` (UR5, tool point pinned: 6 DoF, 3 rows, 6 actuators), ``dual_arm_grasp``
(two 4-dof arms grasping a free box: 15 coordinates with a quaternion, 10 rows, 8 actuators),
both from ``robot_bench.py`` (Pinocchio and example-robot-data needed), and ``five_bar`` (planar
parallel manipulator of the library: 2 actuated bases). Interleaved repeats, medians of wall and
CPU (process) time; the ratios are of medians. The load average is printed with the results
(the machine is shared: CPU-time ratios are the steadier ones).

    OPENBLAS_NUM_THREADS=1 python benchmarks/control_bench.py [--repeat 7] [--T 1.0] [--json out.json]

``--tutorial03`` times instead tutorial 03's section 4 (five-bar tracking a circle, DOPRI5
rtol 1e-7, atol 1e-9, 2 s, the passivity Tracker): compiled into the loop against the same law
called back in Python (a subclass of Tracker is never compiled), CPU time, steps and the largest
difference of the two trajectories.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

import nonmin
from nonmin import library
from nonmin.control import ForceControl, Reference, Regulator, Tracker

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
DT = 1e-3


def _quaternion_blocks(model: Any, q0: np.ndarray) -> list[list[int]]:
    blocks = []
    for c in model.constraints:
        if c.name.endswith("unit_quaternion"):
            A = model.constraint_jacobian(0.0, q0, frozenset({c.name}))
            blocks.append([int(i) for i in np.flatnonzero(np.abs(A[0]) > 0)])
    return blocks


def _case(name: str) -> tuple[Any, np.ndarray, np.ndarray, str]:
    """(model, q0, qd0, commanded constraint)."""
    if name == "five_bar":
        mech = library.get("five_bar")
        return mech.model, mech.state.q, mech.state.qd, mech.model.constraint_names[-1]
    import robot_bench as rb

    case = rb.CASES[name](1.0)
    closure = {"ur5_point": "closure", "dual_arm_grasp": "grasp_right"}[name]
    return case.model, case.q0, np.zeros(case.model.n), closure


def controllers(model: Any, q0: np.ndarray, qd0: np.ndarray, closure: str, python: bool) -> dict[str, Any]:
    free = nonmin.simulate(model, (0.0, 0.6), q0, qd0, dt=DT, engine="engine", progress=False)
    target = free.q[int(np.searchsorted(free.t, 0.3 - 1e-9))]
    qb = _quaternion_blocks(model, q0)
    reg = Regulator(model, target=target, Kp=50.0, Kd=10.0, quaternion_blocks=qb, on_infeasible="least_squares")
    idx = [min(int(np.searchsorted(free.t, s - 1e-9)), free.t.size - 1) for s in np.arange(0.0, 0.6 + 1e-9, 0.05)]
    ref = Reference.spline(free.t[idx], free.q[idx])
    trk = Tracker(model, ref, Kp=400.0, Kd=40.0, method="computed_torque", quaternion_blocks=qb,
                  on_infeasible="least_squares")  # fmt: skip
    dim = model.constraint(closure).dim
    force = ForceControl(reg, {closure: np.full(dim, 1.0)}, on_infeasible="least_squares")
    pas = Tracker(model, ref, Kp=100.0, Kd=10.0, lambda_=10.0, quaternion_blocks=qb, on_infeasible="least_squares")
    out: dict[str, Any] = {"none": None, "regulator": reg, "tracker": trk, "passivity": pas, "force": force}
    if python:
        def user(t: float, q: Any, qd: Any, state: Any = None, *, active: Any = None) -> Any:
            return reg(t, q, qd, active=active)

        out["python_regulator"] = user
    return out


def run(names: list[str], repeat: int, T: float, python: bool) -> list[dict[str, Any]]:
    rows = []
    for name in names:
        try:
            model, q0, qd0, closure = _case(name)
        except ImportError as exc:
            print(f"{name}: skipped ({exc})", file=sys.stderr)
            continue
        ctrls = controllers(model, q0, qd0, closure, python)

        def once(c: Any, model: Any = model, q0: Any = q0, qd0: Any = qd0) -> tuple[float, float, Any]:
            w, p = time.perf_counter(), time.process_time()
            tr = nonmin.simulate(model, (0.0, T), q0, qd0, dt=DT, controller=c, engine="engine", progress=False)
            return time.perf_counter() - w, time.process_time() - p, tr

        wall: dict[str, list[float]] = {k: [] for k in ctrls}
        cpu: dict[str, list[float]] = {k: [] for k in ctrls}
        ran: dict[str, str] = {}
        for k, c in ctrls.items():  # warm-up
            ran[k] = once(c)[2].metadata["engine"]
        load0 = os.getloadavg()[0]
        for _ in range(repeat):  # interleaved
            for k, c in ctrls.items():
                w, p, _ = once(c)
                wall[k].append(w)
                cpu[k].append(p)
        load1 = os.getloadavg()[0]
        res: dict[str, Any] = {"case": name, "n": model.n, "k": model.k, "T": T, "dt": DT, "repeat": repeat,
                               "load": [round(load0, 2), round(load1, 2)], "ran": ran}  # fmt: skip
        w0, c0 = statistics.median(wall["none"]), statistics.median(cpu["none"])
        for k in ctrls:
            wk, ck = statistics.median(wall[k]), statistics.median(cpu[k])
            res[k] = {"ms_per_s_wall": 1e3 * wk / T, "ms_per_s_cpu": 1e3 * ck / T,
                      "ratio_wall": wk / w0, "ratio_cpu": ck / c0}  # fmt: skip
        rows.append(res)
        print(json.dumps(res), file=sys.stderr)
    return rows


def markdown(rows: list[dict[str, Any]]) -> str:
    keys = [k for k in ("regulator", "tracker", "passivity", "force", "python_regulator") if rows and k in rows[0]]
    head = "| case | uncontrolled (ms / simulated s, CPU) | " + " | ".join(
        f"{k} / uncontrolled (CPU; wall)" for k in keys) + " | load |"  # fmt: skip
    lines = [head, "|" + "---|" * (len(keys) + 3)]
    for r in rows:
        cells = [f"{r[k]['ratio_cpu']:.2f} ({r[k]['ratio_wall']:.2f})" for k in keys]
        lines.append(f"| {r['case']} | {r['none']['ms_per_s_cpu']:.1f} | " + " | ".join(cells)
                     + f" | {r['load'][0]:.1f}–{r['load'][1]:.1f} |")  # fmt: skip
    return "\n".join(lines)


class _CalledBack(Tracker):
    """The same law, never compiled (compile_controller takes the exact class only)."""


def tutorial03(repeat: int) -> dict[str, Any]:
    """Tutorial 03 section 4: compiled passivity law against the Python law called back."""
    ts = np.linspace(0.0, 2.0, 41)
    circle = [(0.4 + 0.15 * np.sin(np.pi * t), 1.5 - 0.15 + 0.15 * np.cos(np.pi * t)) for t in ts]
    ref = Reference.spline(ts, [library.five_bar(end_effector=p).state.q for p in circle])
    model = library.five_bar().model
    off = library.five_bar(end_effector=(0.35, 1.45))
    res: dict[str, Any] = {"case": "tutorial03_section4", "load": [round(os.getloadavg()[0], 2)]}
    trajs = {}
    for name, cls in (("compiled", Tracker), ("called_back", _CalledBack)):
        cpu, wall = [], []
        for _ in range(repeat):
            track = cls(model, ref, Kp=100.0, Kd=20.0, lambda_=10.0)
            w, p = time.perf_counter(), time.process_time()
            tr = nonmin.simulate(off, (0.0, 2.0), method="dopri5", controller=track, rtol=1e-7, atol=1e-9,
                                 t_eval=ts, progress=False)  # fmt: skip
            wall.append(time.perf_counter() - w)
            cpu.append(time.process_time() - p)
        trajs[name] = tr
        res[name] = {"cpu_s": statistics.median(cpu), "wall_s": statistics.median(wall), "n_steps": tr.n_steps,
                     "n_rhs": tr.n_rhs, "engine": tr.metadata["engine"]}  # fmt: skip
    res["load"].append(round(os.getloadavg()[0], 2))
    a, b = trajs["compiled"], trajs["called_back"]
    res["max_abs_dq"] = float(np.max(np.abs(a.q - b.q)))
    res["cpu_ratio"] = res["compiled"]["cpu_s"] / res["called_back"]["cpu_s"]
    return res


def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--repeat", type=int, default=7)
    ap.add_argument("--T", type=float, default=1.0)
    ap.add_argument("--cases", default="ur5_point,dual_arm_grasp,five_bar")
    ap.add_argument("--python", action="store_true", help="also time a Python controller called back")
    ap.add_argument("--json", default="")
    ap.add_argument("--tutorial03", action="store_true", help="tutorial 03 section 4: compiled vs called back")
    a = ap.parse_args()
    if a.tutorial03:
        r = tutorial03(a.repeat)
        print(json.dumps(r, indent=1))
        if a.json:
            Path(a.json).write_text(json.dumps(r, indent=1))
        return
    rows = run([c for c in a.cases.split(",") if c], a.repeat, a.T, a.python)
    print(markdown(rows))
    if a.json:
        Path(a.json).write_text(json.dumps({"date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
                                            "rows": rows}, indent=1))  # fmt: skip


if __name__ == "__main__":
    main()
