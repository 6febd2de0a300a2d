"""The engine's simulation loop against the general (Python) driver and the numba loop.

Wall time per simulated second of ``nonmin.simulate`` with ``engine="engine"`` (the C++ loop,
nonmin/sim/_engine.py), ``"python"`` (the general driver) and, where it applies, ``"compiled"``
(the numba loop: planar RK4 + projection without controller or events), on the same model and
settings; the results of the engines are compared (max |q_engine − q_other|).

Cases: the crossed four-bar and A02 N = 2 (planar programs), the UR5 with its tool point pinned
and the dual-arm grasp (robots: TreeProgram), the UR5 with a regulator (controller called back),
the arm2r_wall contact run (impact and release), the UR5 falling 5 cm onto a floor (contact
events and the joint limits of its URDF, located and applied in the engine's event layer), a
pendulum FunctionModel (PyProgram: the model called back). Medians of ``--repeat`` runs after
one warm-up (which includes any compilation).

``--contact-overhead`` (issue #17, target 3): the UR5 on the floor against the same run without
contact (``EventSet(contact=False)``: no floor, no joint limits), RK4 dt = 1e-3, 3 s sampled every
10 ms, runs interleaved, ratio of the medians. And the target's like-for-like case: the UR5 of
target 2 (its tool point pinned, ``ur5_point``, with the joint limits of its URDF) whose elbow
falls onto the floor it stands on (a unilateral contact of ``forearm_link`` with the plane
z = 0), against that robot without the floor (``closed``, its uncontrolled run) and without the
floor and the limits (``closed_no_limits``).

    python benchmarks/loop_bench.py [--repeat 3] [--engines engine,python] [--json out.json]
    python benchmarks/loop_bench.py --contact-overhead [--repeat 15]

``--planar`` times the planar settings of the issue's target 4 instead: the crossed four-bar and
A02 N = 2, 40, 80 at RK4 dt 1e-3 with every step recorded and at dt 1e-3 … 5e-2 with samples
every 0.01 s (the settings of sim_bench.py), engines interleaved run by run, medians of wall and
of process CPU time per simulated second and their ratios to the first engine. The engine
``numba`` is the numba loop of nonmin ≤ 0.1 (``simulate(engine="compiled")``), frozen in
``benchmarks/numba_baseline`` (needs ``pip install numba``): it runs from the engine's first
sample to the end (its setup outside the timing; the engine's whole ``simulate`` call is timed):

    python benchmarks/loop_bench.py --planar [--repeat 5] [--block 4] [--engines engine,numba]

``--block K`` times K consecutive runs per sample; the engines alternate A B, B A, ... and the
table adds the median and quartiles of the side-by-side CPU ratios of each repetition.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

import nonmin
from nonmin import library

sys.path.insert(0, str(Path(__file__).resolve().parent))


def _robot(name: str) -> tuple[Any, np.ndarray]:
    import robot_bench as rb  # (needs Pinocchio and example-robot-data)

    case = rb.CASES[name](1.0)
    return case.model, case.q0


def _ur5_floor() -> tuple[Any, np.ndarray]:
    """The UR5 (no closure) at the ur5_point case's configuration, its ee_link 5 cm above a
    floor (a unilateral contact ``"floor"``); it falls onto it under gravity."""
    import robot_bench as rb

    from nonmin.model.robots import FrameConstraint, RobotModel

    urdf = rb._erd_root() / "ur_description" / "urdf" / "ur5_robot.urdf"
    q0 = np.array([0.2, -1.0, 1.3, -0.6, 0.9, 0.4])
    z = RobotModel.from_urdf(urdf).frame_placement(q0, "ee_link")[2, 3]
    plane = np.eye(4)
    plane[2, 3] = z - 0.05
    model = RobotModel.from_urdf(urdf, constraints=[FrameConstraint.contact("floor", "ee_link",
                                                                            plane_placement=plane)])  # fmt: skip
    return model, q0


def _ur5_point_floor() -> tuple[Any, Any, np.ndarray]:
    """The UR5 of target 2 (``ur5_point``: its tool point pinned, the joint limits of its URDF)
    and the same robot standing on a floor, the plane z = 0 of its base: its elbow
    (``forearm_link``, 0.45 m above it at the start) falls onto the floor (at t ≈ 0.8 s) and
    stays there (a unilateral contact ``"floor"``, plastic)."""
    from nonmin.model.robots import FrameConstraint

    closed, q0 = _robot("ur5_point")
    floor = FrameConstraint.contact("floor", "forearm_link", plane_placement=np.eye(4))
    return closed, closed.replace(robot_constraints=(*closed.robot_constraints, floor)), q0


def contact_overhead(repeat: int, T: float = 3.0) -> dict[str, Any]:
    """The UR5 on the floor against the same run without contact, and against the floor as a
    bilateral constraint held from the start (no events: the cost of the constraint itself);
    and the like-for-like case of the target, the pinned UR5 whose elbow falls onto the floor
    (:func:`_ur5_point_floor`) against the same robot without the floor. Wall and CPU (process)
    time, runs interleaved, medians; ratios to ``no_contact`` (``wall_ratio``, ``cpu_ratio``)
    and, for the closed-loop runs, to ``closed`` (``*_ratio_closed``)."""
    from nonmin.sim import EventSet

    model, q0 = _ur5_floor()
    closed, closed_floor, qc = _ur5_point_floor()
    te = np.linspace(0.0, T, round(100 * T) + 1)
    qb = q0.copy()  # the bilateral reference starts on the floor (its tool point assembled)
    qb = nonmin.model.assemble(model, qb, active={"floor"}).q
    runs: dict[str, tuple[Any, Any, dict[str, Any]]] = {
        "contact": (model, q0, {}),
        "no_contact": (model, q0, {"events": EventSet(contact=False)}),
        "floor_bilateral": (model, qb, {"events": EventSet(contact=False), "active": {"floor"}}),
        "closed": (closed, qc, {}),
        "closed_no_limits": (closed, qc, {"events": EventSet(contact=False)}),
        "closed_floor": (closed_floor, qc, {}),
    }
    wall: dict[str, list[float]] = {k: [] for k in runs}
    cpu: dict[str, list[float]] = {k: [] for k in runs}
    trs: dict[str, Any] = {}
    for i in range(repeat + 1):
        for name, (mdl, q, kw) in runs.items():
            w, c = time.perf_counter(), time.process_time()
            trs[name] = nonmin.simulate(mdl, T, q, np.zeros(6), dt=1e-3, t_eval=te, engine="engine",
                                        progress=False, **kw)  # fmt: skip
            if i:  # (the first round is the warm-up)
                wall[name].append(time.perf_counter() - w)
                cpu[name].append(time.process_time() - c)
    out: dict[str, Any] = {"T": T, "repeat": repeat}
    for name in runs:
        out[name] = {"wall_ms_per_s": 1e3 * statistics.median(wall[name]) / T,
                     "cpu_ms_per_s": 1e3 * statistics.median(cpu[name]) / T,
                     "wall_ratio": statistics.median(wall[name]) / statistics.median(wall["no_contact"]),
                     "cpu_ratio": statistics.median(cpu[name]) / statistics.median(cpu["no_contact"]),
                     "events": len(trs[name].events), "n_rhs": trs[name].n_rhs}  # fmt: skip
        if name.startswith("closed"):
            out[name]["wall_ratio_closed"] = statistics.median(wall[name]) / statistics.median(wall["closed"])
            out[name]["cpu_ratio_closed"] = statistics.median(cpu[name]) / statistics.median(cpu["closed"])
    out["contact_events"] = [(round(e.t, 4), e.name) for e in trs["contact"].events]
    out["closed_events"] = [(round(e.t, 4), e.name) for e in trs["closed"].events]
    out["closed_floor_events"] = [(round(e.t, 4), e.name) for e in trs["closed_floor"].events]
    return out


def _cases() -> dict[str, Callable[[], tuple[Any, dict[str, Any], float]]]:
    def cfb() -> tuple[Any, dict[str, Any], float]:
        return library.get("crossed_four_bar"), {"dt": 1e-3}, 1.0

    def a02() -> tuple[Any, dict[str, Any], float]:
        return library.get("A02_n_four_bar", N=2), {"dt": 1e-3}, 1.0

    def ur5() -> tuple[Any, dict[str, Any], float]:
        model, q0 = _robot("ur5_point")
        return model, {"q0": q0, "dt": 1e-3}, 1.0

    def ur5_reg() -> tuple[Any, dict[str, Any], float]:
        from nonmin.control import Regulator

        model, q0 = _robot("ur5_point")
        target = nonmin.simulate(model, (0.0, 0.3), q0, dt=1e-3, engine="engine", progress=False).q[-1]
        reg = Regulator(model, target=target, Kp=50.0, Kd=10.0, on_infeasible="least_squares")
        return model, {"q0": q0, "dt": 1e-3, "controller": reg}, 1.0

    def dual() -> tuple[Any, dict[str, Any], float]:
        model, q0 = _robot("dual_arm_grasp")
        return model, {"q0": q0, "dt": 1e-3}, 1.0

    def wall() -> tuple[Any, dict[str, Any], float]:
        u_amp = np.array([10.0, -6.0])

        def ctrl(t: float, q: Any, qd: Any, state: Any = None, *, active: Any = None) -> Any:
            return u_amp * np.cos(2.0 * t)

        return library.get("arm2r_wall"), {"dt": 1e-3, "controller": ctrl}, 0.45

    def ur5_floor() -> tuple[Any, dict[str, Any], float]:
        model, q0 = _ur5_floor()
        return model, {"q0": q0, "dt": 1e-3}, 1.0

    def pend() -> tuple[Any, dict[str, Any], float]:
        from nonmin.model import FunctionConstraint, FunctionModel

        rod = FunctionConstraint.holonomic(
            "rod", phi=lambda q: [0.5 * (q @ q - 1.0)], jacobian=lambda q: q[None, :],
            adot_qd=lambda q, qd: [qd @ qd],
        )  # fmt: skip
        model = FunctionModel(
            name="pendulum", coordinate_names=("x", "y"), mass=lambda q: np.eye(2),
            coriolis=lambda q, qd: np.zeros((2, 2)), conservative=lambda q: [0.0, -9.81],
            potential=lambda q: 9.81 * q[1], constraints=(rod,),
        )  # fmt: skip
        return model, {"q0": [1.0, 0.0], "dt": 1e-3}, 1.0

    return {"crossed_four_bar": cfb, "A02_N2": a02, "ur5_point": ur5, "ur5_point_regulator": ur5_reg,
            "dual_arm_grasp": dual, "arm2r_wall_contact": wall, "ur5_floor_contact": ur5_floor,
            "pendulum_function_model": pend}  # fmt: skip


def run(names: list[str], engines: list[str], repeat: int) -> list[dict[str, Any]]:
    rows = []
    for name, make in _cases().items():
        if names and name not in names:
            continue
        try:
            model, kw, T = make()
        except ImportError as exc:
            print(f"{name}: skipped ({exc})", file=sys.stderr)
            continue
        kw = dict(kw)
        q0 = kw.pop("q0", None)
        res: dict[str, Any] = {"case": name, "T": T}
        trajs = {}
        for eng in engines:
            def once(eng: str = eng, model: Any = model, T: float = T, q0: Any = q0,
                     kw: dict[str, Any] = kw) -> Any:  # fmt: skip
                return nonmin.simulate(model, (0.0, T), q0, engine=eng, progress=False, **kw)

            try:
                tr = once()  # warm-up (and numba compilation)
            except nonmin.errors.InputError as exc:
                res[eng] = None
                print(f"{name} {eng}: {exc}", file=sys.stderr)
                continue
            times = []
            for _ in range(repeat):
                w = time.perf_counter()
                tr = once()
                times.append(time.perf_counter() - w)
            trajs[eng] = tr
            res[eng] = {"ms_per_s": 1e3 * statistics.median(times) / T, "ran": tr.metadata["engine"],
                        "steps": tr.n_steps, "n_rhs": tr.n_rhs, "events": len(tr.events)}  # fmt: skip
        if "engine" in trajs:
            for eng, tr in trajs.items():
                if eng != "engine" and len(tr) == len(trajs["engine"]):
                    res[eng]["max_q_diff_to_engine"] = float(np.max(np.abs(tr.q - trajs["engine"].q)))
        rows.append(res)
        print(json.dumps(res), file=sys.stderr)
    return rows


def markdown(rows: list[dict[str, Any]], engines: list[str]) -> str:
    head = "| case | " + " | ".join(f"{e} (ms per simulated s)" for e in engines) + " | engine speed-up vs python |"
    lines = [head, "|" + "---|" * (len(engines) + 2)]
    for r in rows:
        cells = []
        for e in engines:
            v = r.get(e)
            cells.append("—" if v is None else f"{v['ms_per_s']:.1f}")
        sp = "—"
        if r.get("engine") and r.get("python"):
            sp = f"{r['python']['ms_per_s'] / r['engine']['ms_per_s']:.1f}×"
        lines.append(f"| {r['case']} | " + " | ".join(cells) + f" | {sp} |")
    return "\n".join(lines)


#: (case, N, simulated seconds) of the planar settings; (dt, sample spacing or None = every step).
PLANAR_CASES = (("crossed_four_bar", 0, 2.0), ("A02_N2", 2, 2.0), ("A02_N40", 40, 0.5), ("A02_N80", 80, 0.25))
PLANAR_SETTINGS = ((1e-3, None), (1e-3, 0.01), (1e-2, 0.01), (2e-2, 0.01), (5e-2, 0.01))


class _Ran:
    """What planar_rows reads of a run: samples q, steps, metadata."""

    def __init__(self, q: Any, n_steps: int, metadata: dict[str, Any]) -> None:
        self.q, self.n_steps, self.metadata = q, n_steps, metadata


def planar_rows(names: list[str], engines: list[str], repeat: int, block: int = 1) -> list[dict[str, Any]]:
    """Each planar case at each setting, the engines interleaved run by run (after one warm-up
    run each): medians of wall and process CPU time per simulated second.

    Each timed sample is ``block`` consecutive runs (short runs of a few ms are timed in blocks).
    The engines' order alternates from one repetition to the next (A B, B A, ...), and each
    repetition gives the CPU ratio of the first engine to each other one measured side by side
    (``pair_cpu_ratios``): their median and quartiles are robust to the host's speed drifting
    between repetitions, which the ratio of the medians is not (this host: ±15 % within a
    minute, 2026-11-27 14:21)."""
    rows = []
    for name, N, T in PLANAR_CASES:
        if names and name not in names:
            continue
        mech = library.get("crossed_four_bar") if N == 0 else library.get("A02_n_four_bar", N=N)
        for dt, spacing in PLANAR_SETTINGS:
            if dt >= T:
                continue
            kw: dict[str, Any] = {"dt": dt}
            if spacing is not None:
                kw["t_eval"] = np.linspace(0.0, T, round(T / spacing) + 1)
            walls: dict[str, list[float]] = {e: [] for e in engines}
            cpus: dict[str, list[float]] = {e: [] for e in engines}
            trajs: dict[str, Any] = {}
            nprog = None
            if "numba" in engines:
                from numba_baseline import fastpath as nb

                nprog = nb.program(mech.model, mech.state.active)
            for rep in range(repeat + 1):
                for eng in (engines if rep % 2 == 0 else engines[::-1]):
                    if eng == "numba":
                        first = trajs[engines[0]]
                        tv = kw.get("t_eval")
                        w, c = time.perf_counter(), time.process_time()
                        for _ in range(block):
                            fr = nb.simulate(nprog, 0.0, T, dt, first.q[0], first.qd[0], tv)
                        w, c = (time.perf_counter() - w) / block, (time.process_time() - c) / block
                        qs = np.concatenate([first.q[:1]] + [b["q"] for b in fr.blocks])
                        tr = _Ran(qs, first.n_steps if fr.failed else fr.steps,
                                  {"engine": "numba" + (" (failed)" if fr.failed else "")})  # fmt: skip
                    else:
                        w, c = time.perf_counter(), time.process_time()
                        for _ in range(block):
                            tr = nonmin.simulate(mech, (0.0, T), engine=eng, progress=False, **kw)
                        w, c = (time.perf_counter() - w) / block, (time.process_time() - c) / block
                    if rep:  # (the first run of each engine is the warm-up)
                        walls[eng].append(w)
                        cpus[eng].append(c)
                    trajs[eng] = tr
            res: dict[str, Any] = {"case": name, "T": T, "dt": dt, "samples": "every step" if spacing is None
                                   else f"every {spacing} s", "steps": trajs[engines[0]].n_steps}  # fmt: skip
            for eng in engines:
                res[eng] = {"wall_ms_per_s": 1e3 * statistics.median(walls[eng]) / T,
                            "cpu_ms_per_s": 1e3 * statistics.median(cpus[eng]) / T,
                            "ran": trajs[eng].metadata["engine"]}  # fmt: skip
                if eng != engines[0]:
                    pr = sorted(a / b for a, b in zip(cpus[engines[0]], cpus[eng], strict=True))
                    q1, q2, q3 = statistics.quantiles(pr, n=4) if len(pr) > 1 else (pr[0],) * 3
                    res[eng]["pair_cpu_ratios"] = {"median": q2, "q1": q1, "q3": q3, "max": pr[-1]}
                if eng != engines[0] and np.shape(trajs[eng].q) == np.shape(trajs[engines[0]].q):
                    res[eng]["max_q_diff"] = float(np.max(np.abs(trajs[eng].q - trajs[engines[0]].q)))
            rows.append(res)
            print(json.dumps(res), file=sys.stderr)
    return rows


def planar_markdown(rows: list[dict[str, Any]], engines: list[str]) -> str:
    e0 = engines[0]
    head = ("| case | dt | samples | " + " | ".join(f"{e} wall / CPU (ms per s)" for e in engines)
            + " | " + " | ".join(f"{e0} / {e} wall, CPU" for e in engines[1:]) + " |")  # fmt: skip
    if len(engines) > 1:
        head += " " + " | ".join(f"{e0} / {e} CPU side by side: median (quartiles)" for e in engines[1:]) + " |"
    lines = [head, "|" + "---|" * (3 + 2 * len(engines) - 1 + (len(engines) - 1 if len(engines) > 1 else 0))]
    for r in rows:
        cells = [f"{r[e]['wall_ms_per_s']:.2f} / {r[e]['cpu_ms_per_s']:.2f}" for e in engines]
        rat = [f"{r[e0]['wall_ms_per_s'] / r[e]['wall_ms_per_s']:.2f}, "
               f"{r[e0]['cpu_ms_per_s'] / r[e]['cpu_ms_per_s']:.2f}" for e in engines[1:]]  # fmt: skip
        pair = [f"**{r[e]['pair_cpu_ratios']['median']:.2f}** ({r[e]['pair_cpu_ratios']['q1']:.2f}–"
                f"{r[e]['pair_cpu_ratios']['q3']:.2f})" for e in engines[1:] if "pair_cpu_ratios" in r[e]]  # fmt: skip
        lines.append(f"| {r['case']} | {r['dt']:g} | {r['samples']} | " + " | ".join(cells + rat + pair) + " |")
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--engines", default="engine,python")
    ap.add_argument("--cases", default="")
    ap.add_argument("--json", default="")
    ap.add_argument("--contact-overhead", action="store_true", help="the UR5 on the floor vs no contact")
    ap.add_argument("--planar", action="store_true", help="the planar settings of target 4")
    ap.add_argument("--block", type=int, default=1, help="--planar: runs per timed sample (short runs)")
    a = ap.parse_args()
    if a.contact_overhead:
        res = contact_overhead(a.repeat)
        print(json.dumps(res, indent=1))
        if a.json:
            Path(a.json).write_text(json.dumps({"date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
                                                "contact_overhead": res}, indent=1))  # fmt: skip
        return
    engines = [e for e in a.engines.split(",") if e]
    if a.planar:
        prow = planar_rows([c for c in a.cases.split(",") if c], engines, a.repeat, max(a.block, 1))
        print(planar_markdown(prow, engines))
        if a.json:
            Path(a.json).write_text(json.dumps({"date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
                                                "planar": prow}, indent=1))  # fmt: skip
        return
    rows = run([c for c in a.cases.split(",") if c], engines, a.repeat, max(a.block, 1))
    print(markdown(rows, engines))
    if a.json:
        Path(a.json).write_text(json.dumps({"date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
                                            "rows": rows}, indent=1))  # fmt: skip


if __name__ == "__main__":
    main()
