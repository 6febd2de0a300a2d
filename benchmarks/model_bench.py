"""Benchmark of the planar multibody model's evaluation (``PlanarModel.evaluate``) and of the
resulting simulation speed.

Timed, each from Python, in one run:

* ``model.evaluate(t, q, qd, active)`` — M, h, f_passive, B and the constraint terms
  (A, γ, φ, velocity residual) at the mechanism's initial state and default active set:
  crossed four-bar, IFToMM A02 with N = 2 and N = 40, five-bar, 2R arm at the wall (also with
  the wall contact active: a point-on-line row), A01 (a rod), slider-crank (prismatic joint
  and actuator);
* ``model.constraint_terms(...)`` alone;
* ``simulate(mechanism, (0, T), method="rk4", dt=1e-3)`` — wall time per simulated second
  for the crossed four-bar and A02 N = 2 (includes the core solve and the simulator's own work).

Each evaluation timing is the median over ``--repeat`` calls after a warm-up; the simulation
timing is the median of three runs after one warm-up run (JIT compilation excluded).

``--robots`` times instead one evaluation of model + kernel from (q, qd) on two robots: the
UR5 (example-robot-data, 6 DoF) with its tool frame held by a point loop closure to the world,
and the dual-arm grasp (``two_arm_grasp``: two 4-DoF arms welded / pinned to a free-floating
box, n = 15, nv = 14, 10 rows). Each in one process, at one consistent state:

* ``engine model+kernel``: ``_engine.Forward`` — the robot's TreeProgram evaluates M, h, A, γ
  and the engine's Solver returns q̈, in one call from Python;
* ``engine evaluate``: ``Program.evaluate_into`` (M, h, A, γ) alone;
* ``python API``: ``RobotModel.evaluate`` + ``nonmin.core.forward_dynamics``;
* ``pin constraintDynamics``: Pinocchio's exact KKT (proximal mu = 0, one iteration) on the same
  tree and constraint frames (CONTACT_3D / CONTACT_6D, LOCAL), from a Python loop;

with the ratio engine / Pinocchio of the medians (wall and thread CPU time), and the largest
relative difference of the accelerations (nonmin's q̈ mapped to Pinocchio's a = T q̈ + Ṫ q̇).
The machine is shared: medians of wall time move with the load; the thread CPU time is the
steadier figure.

Usage::

    python benchmarks/model_bench.py                  # prints a Markdown table
    python benchmarks/model_bench.py --label after --json benchmarks/results/model_after.json
    python benchmarks/model_bench.py --quick          # few repeats (smoke test)
    python benchmarks/model_bench.py --robots --json benchmarks/results/model_robots.json
    python benchmarks/model_bench.py --report benchmarks/results/model_before.json \
        benchmarks/results/model_after.json            # tables into MODEL.md

Results of the runs quoted in ``benchmarks/MODEL.md`` are in ``benchmarks/results/model_*.json``.

``--engine`` times the compiled engine's programs instead (``Model.engine_program()``), each
against the Python evaluation and, for model + kernel, against MuJoCo, in one run:

* evaluation: ``program.evaluate_into`` with everything (``NEED_ALL``) and with what a step
  needs (h, A, γ; M once for a constant M), against ``model.evaluate``;
* model + kernel from ``(t, q, qd)``: ``_engine.Forward`` (one C++ call: Program evaluation
  and the core solve) against the Python pipeline (``model.evaluate`` +
  ``nonmin.core.forward_dynamics``) and against ``mujoco.mj_forward`` on the same mechanism
  (``sim_bench.mjcf``: hinge tree, loops closed with ``<equality connect>``);
* batched model + kernel over ``--batch`` distinct states: ``Forward.batch`` on 1 and 2
  threads against MuJoCo's C batch ``mujoco.rollout.rollout(..., nstep=1)`` (one ``mj_step``
  per state: ``mj_forward`` plus the Euler update) on 1 and 2 threads.

Medians of wall times; ratios are engine / peer (< 1: the engine is faster). The machine is
shared (load average recorded): re-measure on a quiet machine before quoting. Usage::

    python benchmarks/model_bench.py --engine --json benchmarks/results/model_engine.json
    python benchmarks/model_bench.py --engine --quick
    python benchmarks/model_bench.py --engine-report benchmarks/results/model_engine.json
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent

#: (label, library name, parameters, all constraints active instead of the default set)
CASES: list[tuple[str, str, dict[str, Any], bool]] = [
    ("crossed_four_bar", "crossed_four_bar", {}, False),
    ("A02 N=2", "A02_n_four_bar", {"N": 2}, False),
    ("A02 N=40", "A02_n_four_bar", {"N": 40}, False),
    ("five_bar", "five_bar", {}, False),
    ("arm2r_wall", "arm2r_wall", {}, False),
    ("arm2r_wall, wall active", "arm2r_wall", {}, True),
    ("A01_pendulum (rod)", "A01_pendulum", {}, False),
    ("slider_crank", "slider_crank", {}, False),
]
SIM_CASES: list[tuple[str, str, dict[str, Any]]] = [
    ("crossed_four_bar", "crossed_four_bar", {}),
    ("A02 N=2", "A02_n_four_bar", {"N": 2}),
]


def median_us(fn: Callable[[], object], repeat: int, warmup: int = 20) -> tuple[float, float]:
    """Medians of ``fn()``'s wall time and of its CPU time (this thread), in microseconds.

    The CPU time is measured over batches of 10 calls (the clock's resolution); it is robust to
    other processes competing for the cores, the wall time is not.
    """
    for _ in range(warmup):
        fn()
    wall = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        wall.append(time.perf_counter() - t0)
    cpu = []
    for _ in range(max(1, repeat // 10)):
        t0 = time.thread_time()
        for _ in range(10):
            fn()
        cpu.append((time.thread_time() - t0) / 10)
    return 1e6 * statistics.median(wall), 1e6 * statistics.median(cpu)


def machine() -> dict[str, Any]:
    import numpy as np

    try:
        commit = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"], cwd=HERE, capture_output=True, text=True, check=False
        ).stdout.strip()
    except OSError:
        commit = ""
    return {
        "python": sys.version.split()[0],
        "numpy": np.__version__,
        "platform": platform.platform(),
        "cpus": os.cpu_count(),
        "commit": commit,
    }


def run(repeat: int, sim_T: float) -> dict[str, Any]:
    from nonmin import library
    from nonmin.sim import simulate

    rows = []
    for label, name, kw, everything in CASES:
        mech = library.get(name, **kw)
        m, s = mech.model, mech.state
        t, q, qd = float(s.t), s.q, s.qd
        act = frozenset(m.constraint_names) if everything else s.active
        ev = median_us(lambda m=m, t=t, q=q, qd=qd, act=act: m.evaluate(t, q, qd, act), repeat)
        ct = median_us(lambda m=m, t=t, q=q, qd=qd, act=act: m.constraint_terms(t, q, qd, act), repeat)
        rows.append(
            {
                "case": label,
                "n": m.n,
                "m": m.num_rows(act),
                "evaluate_us": ev[0],
                "evaluate_cpu_us": ev[1],
                "constraint_terms_us": ct[0],
                "constraint_terms_cpu_us": ct[1],
            }
        )
    sims = []
    for label, name, kw in SIM_CASES:
        mech = library.get(name, **kw)
        simulate(mech, (0.0, 0.05), method="rk4", dt=1e-3, progress=False)  # warm-up (JIT)
        walls, cpus = [], []
        for _ in range(3):
            t0, c0 = time.perf_counter(), time.process_time()
            simulate(mech, (0.0, sim_T), method="rk4", dt=1e-3, progress=False)
            walls.append(time.perf_counter() - t0)
            cpus.append(time.process_time() - c0)
        sims.append(
            {
                "case": label,
                "T": sim_T,
                "wall_s_per_sim_s": statistics.median(walls) / sim_T,
                "cpu_s_per_sim_s": statistics.median(cpus) / sim_T,
            }
        )
    import nonmin

    info = machine()
    info["nonmin"] = str(Path(nonmin.__file__).parent)
    info["loadavg"] = os.getloadavg()
    return {"machine": info, "repeat": repeat, "evaluate": rows, "simulate": sims}


def _ur5_point() -> tuple[Any, Any]:
    """UR5 with the tool frame pinned to the world where it is at q0 (3-row point closure)."""
    import numpy as np
    import pinocchio as pin

    from nonmin.model.robots import FrameConstraint, RobotModel

    root = Path(pin.__file__).resolve().parents[4] / "share" / "example-robot-data" / "robots"
    path = root / "ur_description" / "urdf" / "ur5_robot.urdf"
    if not path.is_file():
        raise SystemExit(f"--robots needs example-robot-data ({path} is missing)")
    base = RobotModel.from_urdf(path, joint_limits="ignore")
    q0 = np.array([0.3, -1.0, 1.4, -0.6, 1.2, 0.4])
    pinned = base.frame_placement(q0, "tool0")[:3, 3]
    robot = base.replace(robot_constraints=(FrameConstraint.point("closure", "tool0", placement_b=pinned),))
    return robot, robot.state(q0)


def _admissible(robot: Any, state: Any, rng: Any) -> Any:
    """A velocity in the null space of the active constraints' A (scale ~1 rad/s)."""
    import numpy as np

    A = robot.constraint_terms(state.t, state.q, np.zeros(robot.n), state.active).A
    _, sv, Vt = np.linalg.svd(A)
    r = int(np.sum(sv > 1e-10 * max(1.0, sv[0])))
    return state.replace(qd=Vt[r:].T @ rng.normal(size=robot.n - r))


def _pin_setup(robot: Any, active: Any) -> tuple[Any, ...]:
    import pinocchio as pin

    pm = robot.pinocchio_model
    models = pin.StdVec_RigidConstraintModel()
    datas = pin.StdVec_RigidConstraintData()
    for c in robot.robot_constraints:
        if c.name not in active or getattr(c, "type", None) not in ("point", "weld"):
            continue  # the active frame closures only (not the URDF joint limits: inactive here)
        fa = pm.frames[robot.frame_id(f"{c.name}:a")]
        fb = pm.frames[robot.frame_id(f"{c.name}:b")]
        kind = {"point": pin.ContactType.CONTACT_3D, "weld": pin.ContactType.CONTACT_6D}[c.type]
        cm = pin.RigidConstraintModel(kind, pm, fa.parentJoint, fa.placement, fb.parentJoint,
                                      fb.placement, pin.ReferenceFrame.LOCAL)
        models.append(cm)
        datas.append(cm.createData())
    data = pm.createData()
    pin.initConstraintDynamics(pm, data, models, datas)
    return pm, data, models, datas, pin.ProximalSettings(1e-12, 0.0, 1)


def run_robots(repeat: int) -> dict[str, Any]:
    """Model + kernel from (q, qd) on the robots: the engine against Pinocchio (see doc)."""
    import numpy as np
    import pinocchio as pin

    from nonmin import _engine
    from nonmin.core import forward_dynamics
    from nonmin.model.robots import two_arm_grasp

    rng = np.random.default_rng(0)
    rows = []
    for label, make in (("UR5 + point closure", _ur5_point), ("dual-arm grasp", two_arm_grasp)):
        robot, state = make()
        state = _admissible(robot, state, rng)
        t, q, qd, act = state.t, state.q, state.qd, state.active
        prog = robot.engine_program()
        terms, ws = prog.make_terms(), prog.make_workspace()
        mask = np.array([c.name in act for c in robot.constraints], dtype=np.uint8)
        qdd = np.empty(robot.n)
        need = _engine.NEED_M | _engine.NEED_H | _engine.NEED_A | _engine.NEED_GAMMA
        fwd = _engine.Forward(prog, mask)

        def engine(fwd=fwd, t=t, q=q, qd=qd, qdd=qdd) -> None:
            fwd(t, q, qd, qdd)

        def evaluate(prog=prog, terms=terms, ws=ws, t=t, q=q, qd=qd, mask=mask, need=need) -> None:
            prog.evaluate_into(terms, ws, t, q, qd, mask, need)

        def python_api(robot=robot, t=t, q=q, qd=qd, act=act) -> Any:
            mt = robot.evaluate(t, q, qd, act)
            return forward_dynamics(mt.M, mt.h + mt.f_passive, mt.constraints.A, mt.constraints.gamma)

        pm, data, cms, cds, prox = _pin_setup(robot, act)
        qn = robot.pinocchio_configuration(q)
        v = robot.to_pinocchio_velocity(q, qd)
        tau = np.zeros(robot.nv)

        def pinocchio(pm=pm, data=data, qn=qn, v=v, tau=tau, cms=cms, cds=cds, prox=prox) -> Any:
            return pin.constraintDynamics(pm, data, qn, v, tau, cms, cds, prox)

        fwd(t, q, qd, qdd)
        a_pin = np.array(pinocchio())
        a_eng = robot.to_pinocchio_acceleration(q, qd, qdd)
        a_api = robot.to_pinocchio_acceleration(q, qd, python_api())
        scale = max(1.0, float(np.abs(a_pin).max()))
        timings = {name: median_us(fn, repeat) for name, fn in
                   (("engine", engine), ("evaluate", evaluate), ("python_api", python_api),
                    ("pinocchio", pinocchio))}
        rows.append({
            "case": label,
            "n": robot.n,
            "nv": robot.nv,
            "m": robot.num_rows(act),
            **{f"{k}_us": v_[0] for k, v_ in timings.items()},
            **{f"{k}_cpu_us": v_[1] for k, v_ in timings.items()},
            "ratio_wall": timings["engine"][0] / timings["pinocchio"][0],
            "ratio_cpu": timings["engine"][1] / timings["pinocchio"][1],
            "max_rel_diff_engine_vs_pin": float(np.abs(a_eng - a_pin).max()) / scale,
            "max_rel_diff_api_vs_pin": float(np.abs(a_api - a_pin).max()) / scale,
        })
    import nonmin

    info = machine()
    info["nonmin"] = str(Path(nonmin.__file__).parent)
    info["pinocchio"] = pin.__version__
    info["loadavg"] = os.getloadavg()
    return {"machine": info, "repeat": repeat, "robots": rows}


def markdown_robots(res: dict[str, Any], label: str) -> str:
    lines = [
        f"**{label}** (repeat={res['repeat']}, commit {res['machine']['commit']}, Pinocchio "
        f"{res['machine']['pinocchio']}, load average {res['machine']['loadavg'][0]:.1f}); "
        "medians in µs, wall / thread CPU",
        "",
        "| robot | n / nv / m | engine model+kernel | engine evaluate | python API | pin "
        "constraintDynamics | ratio wall | ratio CPU | max rel diff a (engine, API) |",
        "|---|---|---:|---:|---:|---:|---:|---:|---|",
    ]
    for r in res["robots"]:
        lines.append(
            f"| {r['case']} | {r['n']} / {r['nv']} / {r['m']} "
            f"| {r['engine_us']:.2f} / {r['engine_cpu_us']:.2f} "
            f"| {r['evaluate_us']:.2f} / {r['evaluate_cpu_us']:.2f} "
            f"| {r['python_api_us']:.1f} / {r['python_api_cpu_us']:.1f} "
            f"| {r['pinocchio_us']:.2f} / {r['pinocchio_cpu_us']:.2f} "
            f"| {r['ratio_wall']:.2f} | {r['ratio_cpu']:.2f} "
            f"| {r['max_rel_diff_engine_vs_pin']:.1e}, {r['max_rel_diff_api_vs_pin']:.1e} |"
        )
    return "\n".join(lines)


def markdown(res: dict[str, Any], label: str) -> str:
    if "robots" in res:
        return markdown_robots(res, label)
    lines = [
        f"**{label}** (repeat={res['repeat']}, commit {res['machine']['commit']}, "
        f"nonmin from {res['machine']['nonmin']}, load average {res['machine']['loadavg'][0]:.1f})",
        "",
        "| mechanism | n | m | evaluate wall (µs) | evaluate CPU (µs) | constraint_terms wall (µs) "
        "| constraint_terms CPU (µs) |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    for r in res["evaluate"]:
        lines.append(
            f"| {r['case']} | {r['n']} | {r['m']} | {r['evaluate_us']:.1f} | {r['evaluate_cpu_us']:.1f} "
            f"| {r['constraint_terms_us']:.1f} | {r['constraint_terms_cpu_us']:.1f} |"
        )
    lines += [
        "",
        "| simulate rk4, dt=1e-3 | wall s per simulated s | CPU s per simulated s |",
        "|---|---:|---:|",
    ]
    for r in res["simulate"]:
        lines.append(
            f"| {r['case']} (T={r['T']:g} s) | {r['wall_s_per_sim_s']:.2f} | {r['cpu_s_per_sim_s']:.2f} |"
        )
    return "\n".join(lines)


MODEL_MD = HERE / "MODEL.md"
START, END = "<!-- results:start -->", "<!-- results:end -->"


def report(paths: list[Path]) -> None:
    """Rewrite the results section of ``benchmarks/MODEL.md`` from result JSON files."""
    blocks = []
    for p in paths:
        res = json.loads(p.read_text())
        blocks.append(markdown(res, res.get("label", p.stem)))
    text = MODEL_MD.read_text()
    i0, i1 = text.index(START) + len(START), text.index(END)
    MODEL_MD.write_text(text[:i0] + "\n" + "\n\n".join(blocks) + "\n" + text[i1:])


# ---------------------------------------------------------------------------------------------
# engine programs (--engine)
# ---------------------------------------------------------------------------------------------
#: (label, library name, parameters, sim_bench mechanism for MuJoCo or None)
ENGINE_CASES: list[tuple[str, str, dict[str, Any], str | None]] = [
    ("crossed_four_bar", "crossed_four_bar", {}, "crossed_four_bar"),
    ("A02 N=2", "A02_n_four_bar", {"N": 2}, "A02_N2"),
    ("A02 N=40", "A02_n_four_bar", {"N": 40}, "A02_N40"),
    ("A02 N=80", "A02_n_four_bar", {"N": 80}, "A02_N80"),
    ("five_bar", "five_bar", {}, None),
    ("arm2r_wall", "arm2r_wall", {}, None),
    ("slider_crank", "slider_crank", {}, None),
    ("A04 Bricard (spatial)", "A04_bricard", {}, None),
]


def _bar(name: str) -> Any:
    sys.path.insert(0, str(HERE))
    import sim_bench

    if name == "crossed_four_bar":
        return sim_bench.crossed_four_bar_mechanism()
    return sim_bench.a02_mechanism(int(name[5:]))


def mujoco_trajectory_states(mj: Any, dat: Any, count: int) -> Any:
    """``count`` distinct consistent states for ``rollout`` (full physics, one row each): the
    steps of MuJoCo's own trajectory from rest at qpos0 (``dat`` is reset first)."""
    import mujoco
    import numpy as np

    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    x0 = np.zeros((count, mujoco.mj_stateSize(mj, spec)))
    mujoco.mj_resetData(mj, dat)
    for i in range(count):
        mujoco.mj_step(mj, dat)
        mujoco.mj_getState(mj, dat, x0[i], spec)
    return x0


def _mujoco(name: str) -> tuple[Any, Any]:
    import mujoco
    import sim_bench  # noqa: F401  (path set by _bar)

    bar = _bar(name)
    model = mujoco.MjModel.from_xml_string(sys.modules["sim_bench"].mjcf(bar, 2e-3, "default"))
    return model, mujoco.MjData(model)


#: Wall-time budget (s) of one timing: slow calls are repeated fewer times.
BUDGET_S = 2.0


def median_wall_us(fn: Callable[[], object], repeat: int, warmup: int = 20) -> float:
    """Median wall time of ``fn()`` in microseconds (batches of 10 calls below 20 µs; at most
    about :data:`BUDGET_S` seconds, at least 5 calls)."""
    t0 = time.perf_counter()
    fn()
    once = time.perf_counter() - t0
    for _ in range(min(warmup, int(0.2 * BUDGET_S / max(once, 1e-9)))):
        fn()
    repeat = max(5, min(repeat, int(BUDGET_S / max(once, 1e-9))))
    per = 10 if once < 2e-5 else 1
    wall = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        for _ in range(per):
            fn()
        wall.append((time.perf_counter() - t0) / per)
    return 1e6 * statistics.median(wall)


def _engine_case(label: str, name: str, kw: dict[str, Any], bar: str | None, repeat: int,
                 batch: int) -> dict[str, Any]:
    import numpy as np

    from nonmin import _engine, library
    from nonmin.core import forward_dynamics

    mech = library.get(name, **kw)
    m, s = mech.model, mech.state
    prog = m.engine_program()
    t, q, qd = float(s.t), s.q.copy(), s.qd.copy()
    mask = m.active_mask(s.active)
    terms, ws = prog.make_terms(), prog.make_workspace()
    step_need = _engine.NEED_H | _engine.NEED_A | _engine.NEED_GAMMA
    if not prog.constant_mass:
        step_need |= _engine.NEED_M
    r: dict[str, Any] = {"case": label, "n": m.n, "m": m.num_rows(s.active)}
    r["python_evaluate_us"] = median_wall_us(lambda: m.evaluate(t, q, qd, s.active), max(repeat // 10, 50))
    r["engine_evaluate_all_us"] = median_wall_us(lambda: prog.evaluate_into(terms, ws, t, q, qd, mask), repeat)
    r["engine_evaluate_step_us"] = median_wall_us(
        lambda: prog.evaluate_into(terms, ws, t, q, qd, mask, step_need), repeat)

    def python_forward() -> Any:
        T = m.evaluate(t, q, qd, s.active)
        return forward_dynamics(T.M, T.h, T.constraints.A, T.constraints.gamma, T.f_passive)

    r["python_forward_us"] = median_wall_us(python_forward, max(repeat // 10, 50))
    fwd = _engine.Forward(prog, mask)
    qdd = np.zeros(m.n)
    r["engine_forward_us"] = median_wall_us(lambda: fwd(t, q, qd, qdd), repeat)
    ref = python_forward()
    r["engine_forward_max_rel_diff"] = float(np.abs(qdd - ref).max() / max(1.0, np.abs(ref).max()))
    # a batch of at most about BUDGET_S seconds per timing (the core's large-m path is slow)
    N = max(10, min(batch, int(BUDGET_S / max(1e-6 * r["engine_forward_us"], 1e-9))))
    tt, Q, QD = _trajectory_states(mech, N)
    N = tt.shape[0]
    r["batch_states"] = N
    reps = 3
    # the batch's per-thread scratch is made by its first call and kept (Forward.batch): made here
    fwd.batch(tt[:128], Q[:128], QD[:128], 2)
    for threads in (1, 2):
        walls, cpus = [], []
        for _ in range(reps):
            c0, t0 = time.process_time(), time.perf_counter()
            fwd.batch(tt, Q, QD, threads)
            walls.append(time.perf_counter() - t0)
            cpus.append(time.process_time() - c0)
        r[f"engine_batch{threads}_us_per_state"] = 1e6 * statistics.median(walls) / N
        r[f"engine_batch{threads}_cpu_us_per_state"] = 1e6 * statistics.median(cpus) / N
    # like for like with the batch: single calls (from Python) over the same states (the single
    # timing above repeats the initial state, whose solve can be cheaper than a trajectory's)
    walls, cpus = [], []
    for _ in range(reps):
        c0, t0 = time.process_time(), time.perf_counter()
        for i in range(N):
            fwd(float(tt[i]), Q[i], QD[i], qdd)
        walls.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0)
    r["engine_single_states_us"] = 1e6 * statistics.median(walls) / N
    r["engine_single_states_cpu_us"] = 1e6 * statistics.median(cpus) / N
    if bar is not None:
        r.update(_mujoco_case(bar, repeat, N, reps))
    return r


def _trajectory_states(mech: Any, N: int) -> tuple[Any, Any, Any]:
    """N distinct consistent states: the steps of a simulation (RK4, dt = 1e-3) from the
    mechanism's initial state (on the constraint manifold, with its rank decisions)."""
    from nonmin.sim import simulate

    tr = simulate(mech, (0.0, N * 1e-3), method="rk4", dt=1e-3, progress=False)
    return tr.t[:N].copy(), tr.q[:N].copy(), tr.qd[:N].copy()


def _mujoco_case(bar: str, repeat: int, N: int, reps: int) -> dict[str, Any]:
    import mujoco
    import numpy as np
    from mujoco import rollout

    mj, dat = _mujoco(bar)
    rng = np.random.default_rng(1)
    dat.qvel[:] = rng.standard_normal(mj.nv)
    r: dict[str, Any] = {"mujoco_nv": int(mj.nv)}
    r["mujoco_forward_us"] = median_wall_us(lambda: mujoco.mj_forward(mj, dat), repeat)
    x0 = mujoco_trajectory_states(mj, dat, N)
    for threads in (1, 2):
        datas = [mujoco.MjData(mj) for _ in range(threads)]
        rollout.rollout(mj, datas, x0[:10], nstep=1)  # warm-up (pool, allocation)
        walls = []
        for _ in range(reps):
            t0 = time.perf_counter()
            rollout.rollout(mj, datas, x0, nstep=1)
            walls.append(time.perf_counter() - t0)
        r[f"mujoco_batch{threads}_us_per_state"] = 1e6 * statistics.median(walls) / N
    return r


def run_engine(repeat: int, batch: int) -> dict[str, Any]:
    rows = []
    for label, name, kw, bar in ENGINE_CASES:
        rows.append(_engine_case(label, name, kw, bar, repeat, batch))
        print(f"  {label}: done", file=sys.stderr)
    info = machine()
    info["loadavg"] = os.getloadavg()
    try:
        import mujoco

        info["mujoco"] = mujoco.__version__
    except ImportError:
        info["mujoco"] = None
    return {"machine": info, "repeat": repeat, "batch": batch, "engine": rows}


def engine_markdown(res: dict[str, Any]) -> str:
    def f(x: Any, d: int = 2) -> str:
        return "–" if x is None else f"{x:.{d}f}"

    mach = res["machine"]
    lines = [
        f"Commit {mach['commit']}, MuJoCo {mach.get('mujoco')}, {mach['cpus']} CPUs, load average "
        f"{mach['loadavg'][0]:.1f} (shared machine: wall times inflated and noisy), medians of "
        f"{res['repeat']} calls; batch of {res['batch']} distinct states.",
        "",
        "| mechanism | n | m | Python evaluate (µs) | engine evaluate, all (µs) | engine evaluate, "
        "step (µs) | Python evaluate / engine step |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    for r in res["engine"]:
        lines.append(
            f"| {r['case']} | {r['n']} | {r['m']} | {f(r['python_evaluate_us'], 1)} "
            f"| {f(r['engine_evaluate_all_us'])} | {f(r['engine_evaluate_step_us'])} "
            f"| {f(r['python_evaluate_us'] / r['engine_evaluate_step_us'], 0)} |"
        )
    lines += [
        "",
        "Model + kernel from (t, q, qd): q̈ (engine: one `Forward` call; Python: `evaluate` + "
        "`core.forward_dynamics`; MuJoCo: `mj_forward`).",
        "",
        "| mechanism | Python (µs) | engine (µs) | MuJoCo mj_forward (µs) | engine / MuJoCo "
        "| engine vs Python max rel. diff |",
        "|---|---:|---:|---:|---:|---:|",
    ]
    for r in res["engine"]:
        mj = r.get("mujoco_forward_us")
        lines.append(
            f"| {r['case']} | {f(r['python_forward_us'], 1)} | {f(r['engine_forward_us'])} | {f(mj)} "
            f"| {f(None if mj is None else r['engine_forward_us'] / mj)} "
            f"| {r['engine_forward_max_rel_diff']:.1e} |"
        )
    lines += [
        "",
        f"Batched model + kernel over up to {res['batch']} distinct states (fewer where one "
        f"call is slow: column 'states'; each peer's states are the steps of its own trajectory "
        "from the initial state), µs per state (engine: `Forward.batch`; MuJoCo: "
        "`rollout(nstep=1)`, one mj_step per state), medians of 3; 'single calls': a Python "
        "loop of single `Forward` calls over the batch's states (wall / CPU).",
        "",
        "| mechanism | states | single calls | engine 1 thread (CPU) | engine 2 threads (CPU) "
        "| MuJoCo 1 thread | MuJoCo 2 threads | engine / MuJoCo (2 threads) |",
        "|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in res["engine"]:
        mj2 = r.get("mujoco_batch2_us_per_state")
        lines.append(
            f"| {r['case']} | {r['batch_states']} | {f(r.get('engine_single_states_us'))} / "
            f"{f(r.get('engine_single_states_cpu_us'))} "
            f"| {f(r['engine_batch1_us_per_state'])} ({f(r.get('engine_batch1_cpu_us_per_state'))}) "
            f"| {f(r['engine_batch2_us_per_state'])} ({f(r.get('engine_batch2_cpu_us_per_state'))}) "
            f"| {f(r.get('mujoco_batch1_us_per_state'))} | {f(mj2)} "
            f"| {f(None if mj2 is None else r['engine_batch2_us_per_state'] / mj2)} |"
        )
    return "\n".join(lines)


ESTART, EEND = "<!-- engine:start -->", "<!-- engine:end -->"


def engine_report(path: Path) -> None:
    """Rewrite the engine section of ``benchmarks/MODEL.md`` from a result JSON file."""
    res = json.loads(path.read_text())
    text = MODEL_MD.read_text()
    i0, i1 = text.index(ESTART) + len(ESTART), text.index(EEND)
    MODEL_MD.write_text(text[:i0] + "\n" + engine_markdown(res) + "\n" + text[i1:])


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=2000)
    ap.add_argument("--sim-T", type=float, default=1.0, help="simulated seconds per simulate() run")
    ap.add_argument("--quick", action="store_true", help="few repeats, short simulation")
    ap.add_argument("--label", default="run")
    ap.add_argument("--robots", action="store_true",
                    help="model + kernel on the robots, engine vs Pinocchio constraintDynamics")
    ap.add_argument("--json", type=Path, default=None, help="write the results to this JSON file")
    ap.add_argument("--report", type=Path, nargs="+", default=None, metavar="JSON",
                    help="only rewrite the results section of MODEL.md from these result files")
    ap.add_argument("--engine", action="store_true",
                    help="time the engine's programs (evaluation, model + kernel, batch) and MuJoCo")
    ap.add_argument("--batch", type=int, default=10_000, help="states of the batched timing (--engine)")
    ap.add_argument("--engine-report", type=Path, default=None, metavar="JSON",
                    help="only rewrite the engine section of MODEL.md from this result file")
    args = ap.parse_args(argv)
    if args.engine_report:
        engine_report(args.engine_report)
        return
    if args.engine:
        repeat = 200 if args.quick else args.repeat
        batch = 1000 if args.quick else args.batch
        res = run_engine(repeat, batch)
        res["label"] = args.label
        if args.json is not None:
            args.json.parent.mkdir(parents=True, exist_ok=True)
            args.json.write_text(json.dumps(res, indent=2))
        print(engine_markdown(res))
        return
    if args.report:
        report(args.report)
        return
    repeat, sim_T = (100, 0.1) if args.quick else (args.repeat, args.sim_T)
    res = run_robots(repeat) if args.robots else run(repeat, sim_T)
    res["label"] = args.label
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(res, indent=2))
    print(markdown(res, args.label))


if __name__ == "__main__":
    main()
