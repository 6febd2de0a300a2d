"""Robots with loop closures: whole simulations against Pinocchio and MuJoCo (issue 17, targets 2-3).

Pipeline against pipeline, on the same physical model, from the same initial state (at rest,
assembled), over the same horizon:

* **nonmin**: ``nonmin.simulate(model, (0, T), method="rk4", dt=dt)`` (projection
  stabilization, the default), whatever engine ``"auto"`` picks (reported);
* **Pinocchio**: a Python loop of RK4 steps, four ``pinocchio.constraintDynamics`` calls per
  step (the same number of dynamics evaluations as nonmin's RK4), the configuration advanced
  with ``pinocchio.integrate`` (Lie group), Baumgarte gains on the constraints (``Kp``, ``Kd``
  below; Pinocchio's own corrector) — the fastest way a Pinocchio user simulates a closed loop
  from Python;
* **MuJoCo**: ``mj_step`` with the model written from the same Pinocchio model (bodies, joint
  axes, inertias; no geometry, so no contacts) and the closures as equality constraints
  (``connect`` for a point, ``weld`` for a weld) whose anchors are set from Pinocchio's frames
  and checked to hold to 1e-9 at the initial state; integrators ``RK4`` and ``implicitfast``,
  default and stiff ``solref``.

Accuracy of every run: ``err`` = max over samples (every 0.01 s) of the largest joint-angle error
against a reference run (nonmin RK4 at ``dt_ref``; the arm joints, in rad), ``closure`` = max
constraint residual (m; from Pinocchio's kinematics for every engine), ``dE`` = max |E − E₀| (J;
each engine's own energy). Wall time per simulated second is the median of ``--repeat`` runs
after a warm-up run.

Cases: ``ur5_point`` (UR5 of example-robot-data, 6 DoF, its tool point pinned to the world: 3
rows) and ``dual_arm_grasp`` (two 4-dof arms welded / pinned to a free-floating box:
``nonmin.model.robots.two_arm_grasp``, 9 rows + the box's quaternion row).

Usage::

    OPENBLAS_NUM_THREADS=1 python benchmarks/robot_bench.py                 # everything, ~4 min
    python benchmarks/robot_bench.py --quick                                 # smoke test
    python benchmarks/robot_bench.py --cases ur5_point --engines nonmin,pinocchio

Writes ``results/robot_bench.json`` and prints a Markdown table (ROBOTS.md quotes it).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

HERE = Path(__file__).resolve().parent
SAMPLE_DT = 0.01
KP, KD = 100.0, 20.0  # Pinocchio's Baumgarte gains (its corrector)


# --------------------------------------------------------------------------- cases


@dataclass
class Case:
    name: str
    model: Any  # nonmin RobotModel
    q0: np.ndarray  # nonmin coordinates
    pin_constraints: Callable[[Any], list[Any]]  # pinocchio model -> [RigidConstraintModel]
    mj_equalities: list[tuple[str, str, str, Any, Any]]  # (type, body1, body2, M1, M2)
    horizon: float


def _erd_root() -> Path:
    import pinocchio as pin

    return Path(pin.__file__).resolve().parents[4] / "share" / "example-robot-data" / "robots"


def case_ur5_point(horizon: float) -> Case:
    import pinocchio as pin

    from nonmin.model import assemble
    from nonmin.model.robots import FrameConstraint, RobotModel

    urdf = _erd_root() / "ur_description" / "urdf" / "ur5_robot.urdf"
    q_guess = np.array([0.2, -1.0, 1.3, -0.6, 0.9, 0.4])
    free = RobotModel.from_urdf(urdf)
    oMe = free.frame_placement(q_guess, "ee_link")
    con = FrameConstraint.point("closure", "ee_link", placement_b=oMe)
    model = RobotModel.from_urdf(urdf, constraints=[con])
    q0 = assemble(model, q_guess).q
    pm = model.pinocchio_model
    fid = pm.getFrameId("ee_link")
    fr = pm.frames[fid]

    def pin_cons(pm: Any) -> list[Any]:
        cm = pin.RigidConstraintModel(
            pin.ContactType.CONTACT_3D, pm, fr.parentJoint, fr.placement, 0, pin.SE3(oMe), pin.ReferenceFrame.LOCAL
        )
        return [cm]

    return Case("ur5_point", model, q0, pin_cons,
                [("connect", fr.parentJoint, 0, fr.placement, pin.SE3(oMe))], horizon)


def case_dual_arm(horizon: float) -> Case:
    import pinocchio as pin

    from nonmin.model.robots import two_arm_grasp

    model, state = two_arm_grasp()
    pm = model.pinocchio_model
    Hb = np.eye(4)
    Hb[:3, :3] = [[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]
    fl, fbl = pm.frames[pm.getFrameId("left_ee")], pm.frames[pm.getFrameId("box_left")]
    fr, fbr = pm.frames[pm.getFrameId("right_ee")], pm.frames[pm.getFrameId("box_right")]
    weld_a, weld_b = fl.placement, fbl.placement * pin.SE3(Hb)
    # the nonmin weld holds placement_b = Hb on frame b (box_left): p_a·I = p_b·Hb

    def pin_cons(pm: Any) -> list[Any]:
        w = pin.RigidConstraintModel(pin.ContactType.CONTACT_6D, pm, fl.parentJoint, weld_a,
                                     fbl.parentJoint, weld_b, pin.ReferenceFrame.LOCAL)
        p = pin.RigidConstraintModel(pin.ContactType.CONTACT_3D, pm, fr.parentJoint, fr.placement,
                                     fbr.parentJoint, fbr.placement, pin.ReferenceFrame.LOCAL)
        return [w, p]

    eqs = [("weld", fl.parentJoint, fbl.parentJoint, weld_a, weld_b),
           ("connect", fr.parentJoint, fbr.parentJoint, fr.placement, fbr.placement)]
    return Case("dual_arm_grasp", model, np.array(state.q), pin_cons, eqs, horizon)


CASES: dict[str, Callable[[float], Case]] = {"ur5_point": case_ur5_point, "dual_arm_grasp": case_dual_arm}


# --------------------------------------------------------------------------- helpers


def _pin_closure(case: Case, pm: Any, pd: Any, cms: list[Any], qp: np.ndarray) -> float:
    import pinocchio as pin

    pin.forwardKinematics(pm, pd, qp)
    worst = 0.0
    for cm in cms:
        M1 = pd.oMi[cm.joint1_id] * cm.joint1_placement
        M2 = pd.oMi[cm.joint2_id] * cm.joint2_placement
        if cm.type == pin.ContactType.CONTACT_3D:
            worst = max(worst, float(np.linalg.norm(M1.translation - M2.translation)))
        else:
            worst = max(worst, float(np.linalg.norm(pin.log6(M1.inverse() * M2).vector)))
    return worst


def _arm_indices(case: Case) -> list[int]:
    """nonmin coordinate indices of the revolute joints (the error metric's coordinates)."""
    return [i for i, nm in enumerate(case.model.coordinate_names) if "." not in nm]


def _samples(T: float) -> np.ndarray:
    return np.round(np.arange(0.0, T + 1e-12, SAMPLE_DT), 10)


def _errors(case: Case, t: np.ndarray, Q: np.ndarray, ref: tuple[np.ndarray, np.ndarray]) -> float:
    """Max joint error against the reference at the common sample times."""
    tr, Qr = ref
    idx = _arm_indices(case)
    common = np.intersect1d(np.round(t, 10), np.round(tr, 10))
    a = Q[np.searchsorted(np.round(t, 10), common)][:, idx]
    b = Qr[np.searchsorted(np.round(tr, 10), common)][:, idx]
    return float(np.max(np.abs(a - b)))


#: The clock of every timed run: wall time, or the process's CPU time (``--cpu``).
CLOCK: list[Callable[[], float]] = [time.perf_counter]


def _timed(fn: Callable[[], Any], repeat: int) -> tuple[float, Any]:
    out = fn()  # warm-up (and the result reported)
    walls = []
    for _ in range(repeat):
        t0 = CLOCK[0]()
        fn()
        walls.append(CLOCK[0]() - t0)
    return statistics.median(walls), out


def without_joint_limits(model: Any) -> Any:
    """The robot without its joint-limit constraints (the peers' models have none; over the
    0.6 s horizon no limit is reached at fine steps, so the motion is the same). A model
    without unilateral constraints runs start to end in the engine (no guards watched)."""
    from nonmin.model.robots import JointLimit

    return model.replace(robot_constraints=tuple(c for c in model.robot_constraints if not isinstance(c, JointLimit)))


# --------------------------------------------------------------------------- engines


def run_nonmin(case: Case, dt: float | None, T: float, model: Any = None, **kw: Any) -> dict[str, Any]:
    """nonmin RK4 at ``dt``, or (``dt=None``) the adaptive ``kw["method"]`` at ``kw["rtol"]``;
    ``model`` replaces the case's (e.g. :func:`without_joint_limits`)."""
    import nonmin

    kw = {"method": "rk4", "dt": dt, **kw} if dt is not None else kw
    model = case.model if model is None else model
    kw.setdefault("t_eval", _samples(T))
    traj = nonmin.simulate(model, (0.0, T), case.q0, np.zeros(model.n), progress=False, **kw)
    return {"t": traj.t, "q": traj.q, "closure": float(np.max(traj.phi_norm)),
            "dE": float(np.max(np.abs(traj.energy - traj.energy[0]))), "status": traj.status.value,
            "engine": str(getattr(traj, "diagnostics", {}).get("engine", "?"))
            if isinstance(getattr(traj, "diagnostics", None), dict) else "?"}


def run_pinocchio(case: Case, dt: float, T: float, kp: float = KP) -> dict[str, Any]:
    """RK4 over ``constraintDynamics`` with Baumgarte gains ``kp`` and ``Kd = 2 √kp``."""
    import pinocchio as pin

    pm = case.model.pinocchio_model
    pd = pm.createData()
    cms = pin.StdVec_RigidConstraintModel()
    for cm in case.pin_constraints(pm):
        cms.append(cm)
    for cm in cms:
        bp = cm.m_baumgarte_parameters
        bp.Kp = kp
        bp.Kd = 2.0 * np.sqrt(kp)
        cm.setBaumgarteCorrectorParameters(bp)
    cds = pin.StdVec_RigidConstraintData()
    for cm in cms:
        cds.append(cm.createData())
    pin.initConstraintDynamics(pm, pd, cms, cds)
    prox = pin.ProximalSettings(1e-12, 1e-12, 1)
    tau = np.zeros(pm.nv)
    q = case.model.pinocchio_configuration(case.q0)
    v = np.zeros(pm.nv)
    steps = round(T / dt)
    every = max(1, round(SAMPLE_DT / dt))
    ts, Qs, E = [0.0], [q.copy()], []

    def energy(q: np.ndarray, v: np.ndarray) -> float:
        return float(pin.computeKineticEnergy(pm, pd, q, v) + pin.computePotentialEnergy(pm, pd, q))

    def acc(q: np.ndarray, v: np.ndarray) -> np.ndarray:
        return pin.constraintDynamics(pm, pd, q, v, tau, cms, cds, prox).copy()

    E.append(energy(q, v))
    clos = _pin_closure(case, pm, pd, cms, q)
    for k in range(1, steps + 1):
        a1 = acc(q, v)
        q2, v2 = pin.integrate(pm, q, 0.5 * dt * v), v + 0.5 * dt * a1
        a2 = acc(q2, v2)
        q3, v3 = pin.integrate(pm, q, 0.5 * dt * v2), v + 0.5 * dt * a2
        a3 = acc(q3, v3)
        q4, v4 = pin.integrate(pm, q, dt * v3), v + dt * a3
        a4 = acc(q4, v4)
        q = pin.integrate(pm, q, dt / 6.0 * (v + 2 * v2 + 2 * v3 + v4))
        v = v + dt / 6.0 * (a1 + 2 * a2 + 2 * a3 + a4)
        if not np.all(np.isfinite(v)):
            return {"t": np.array(ts), "q": np.array(Qs), "closure": np.inf, "dE": np.inf, "status": "nonfinite"}
        if k % every == 0:
            ts.append(k * dt)
            Qs.append(q.copy())
            E.append(energy(q, v))
            clos = max(clos, _pin_closure(case, pm, pd, cms, q))
    # Pinocchio's q is nonmin's q for these robots (revolute joints; free flyer x y z qx qy qz qw)
    return {"t": np.array(ts), "q": np.array(Qs), "closure": clos,
            "dE": float(np.max(np.abs(np.array(E) - E[0]))), "status": "success"}


def _mjcf(case: Case) -> str:
    """MJCF of the Pinocchio model: bodies at q = 0 (Pinocchio's neutral placement), no geometry."""
    import pinocchio as pin

    pm = case.model.pinocchio_model
    g = pm.gravity.linear
    children: dict[int, list[int]] = {}
    for j in range(1, pm.njoints):
        children.setdefault(int(pm.parents[j]), []).append(j)

    def num(x: Any) -> str:
        return " ".join(f"{float(v):.17g}" for v in np.atleast_1d(x))

    def quat(R: np.ndarray) -> str:
        qq = pin.Quaternion(R)
        return num([qq.w, qq.x, qq.y, qq.z])

    def body(j: int, ind: str) -> str:
        jm = pm.joints[j]
        M = pm.jointPlacements[j]
        I = pm.inertias[j]
        c = I.inertia  # about the CoM, joint frame axes
        s = [f'{ind}<body name="j{j}" pos="{num(M.translation)}" quat="{quat(M.rotation)}">']
        s.append(f'{ind}  <inertial pos="{num(I.lever)}" mass="{num(I.mass)}" '
                 f'fullinertia="{num([c[0, 0], c[1, 1], c[2, 2], c[0, 1], c[0, 2], c[1, 2]])}"/>')
        sn = jm.shortname()
        if sn == "JointModelFreeFlyer":
            s.append(f'{ind}  <freejoint name="{pm.names[j]}"/>')
        elif sn in ("JointModelRX", "JointModelRY", "JointModelRZ"):
            ax = {"X": "1 0 0", "Y": "0 1 0", "Z": "0 0 1"}[sn[-1]]
            s.append(f'{ind}  <joint name="{pm.names[j]}" type="hinge" axis="{ax}"/>')
        elif sn == "JointModelRevoluteUnaligned":
            ax = num(jm.extract().axis)
            s.append(f'{ind}  <joint name="{pm.names[j]}" type="hinge" axis="{ax}"/>')
        else:
            raise NotImplementedError(f"robot_bench MJCF writer: joint type {sn}")
        for ch in children.get(j, []):
            s.append(body(ch, ind + "  "))
        s.append(f"{ind}</body>")
        return "\n".join(s)

    bodies = "\n".join(body(j, "    ") for j in children.get(0, []))
    return f"""<mujoco model="{case.name}">
  <compiler angle="radian" autolimits="true"/>
  <option gravity="{num(g)}"/>
  <worldbody>
{bodies}
  </worldbody>
</mujoco>"""


def _mj_model(case: Case, integrator: str, dt: float, stiff: bool) -> tuple[Any, Any]:
    import mujoco

    spec = mujoco.MjSpec.from_string(_mjcf(case))
    for k, (typ, j1, j2, _M1, _M2) in enumerate(case.mj_equalities):
        eq = spec.add_equality()
        eq.name = f"eq{k}"
        eq.type = mujoco.mjtEq.mjEQ_CONNECT if typ == "connect" else mujoco.mjtEq.mjEQ_WELD
        eq.objtype = mujoco.mjtObj.mjOBJ_BODY
        eq.name1 = f"j{j1}"
        eq.name2 = f"j{j2}" if j2 else "world"
        if stiff:
            eq.solref = [0.002, 1.0]  # time constant = 2 × the smallest timestep tried
            eq.solimp = [0.99, 0.999, 0.001, 0.5, 2.0]
    m = spec.compile()
    m.opt.timestep = dt
    m.opt.integrator = {"RK4": mujoco.mjtIntegrator.mjINT_RK4,
                        "implicitfast": mujoco.mjtIntegrator.mjINT_IMPLICITFAST}[integrator]
    m.opt.enableflags |= mujoco.mjtEnableBit.mjENBL_ENERGY
    # anchors from Pinocchio's frames (both bodies; MuJoCo body frame = Pinocchio joint frame)
    for k, (typ, _j1, _j2, M1, M2) in enumerate(case.mj_equalities):
        if typ == "connect":
            m.eq_data[k, 0:3] = M1.translation
            m.eq_data[k, 3:6] = M2.translation
        else:  # weld: the anchor (origin of the welded frame) in body2 and in body1, then the
            # orientation of body2 relative to body1 (w x y z) that the weld holds
            import pinocchio as pin

            qq = pin.Quaternion((M1 * M2.inverse()).rotation)
            m.eq_data[k, 0:3] = M2.translation
            m.eq_data[k, 3:6] = M1.translation
            m.eq_data[k, 6:10] = [qq.w, qq.x, qq.y, qq.z]
            m.eq_data[k, 10] = 1.0
    d = mujoco.MjData(m)
    return m, d


def _to_mj_qpos(case: Case, q: np.ndarray) -> np.ndarray:
    names = case.model.coordinate_names
    out = []
    i = 0
    while i < len(names):
        if names[i].endswith(".x"):  # free flyer: x y z qx qy qz qw -> x y z qw qx qy qz
            out += [*q[i:i + 3], q[i + 6], *q[i + 3:i + 6]]
            i += 7
        else:
            out.append(q[i])
            i += 1
    return np.array(out)


def _from_mj_qpos(case: Case, qpos: np.ndarray) -> np.ndarray:
    names = case.model.coordinate_names
    out = []
    i = 0
    while i < len(names):
        if names[i].endswith(".x"):
            out += [*qpos[i:i + 3], *qpos[i + 4:i + 7], qpos[i + 3]]
            i += 7
        else:
            out.append(qpos[i])
            i += 1
    return np.array(out)


def run_mujoco(case: Case, dt: float, T: float, integrator: str, stiff: bool) -> dict[str, Any]:
    import mujoco

    m, d = _mj_model(case, integrator, dt, stiff)
    d.qpos[:] = _to_mj_qpos(case, case.q0)
    d.qvel[:] = 0.0
    mujoco.mj_forward(m, d)
    eq_pos = np.abs(d.efc_pos[: d.ne]) if d.ne else np.zeros(0)
    if eq_pos.size and eq_pos.max() > 1e-9:
        raise RuntimeError(f"MuJoCo equalities do not hold at the initial state: {eq_pos.max():.2e}")
    E0 = float(d.energy.sum())
    steps = round(T / dt)
    every = max(1, round(SAMPLE_DT / dt))
    ts, Qs, dE = [0.0], [case.q0.copy()], 0.0
    for k in range(1, steps + 1):
        mujoco.mj_step(m, d)
        if k % every == 0:
            if not np.all(np.isfinite(d.qpos)):
                return {"t": np.array(ts), "q": np.array(Qs), "closure": np.inf, "dE": np.inf, "status": "nonfinite"}
            ts.append(k * dt)
            Qs.append(_from_mj_qpos(case, d.qpos))
            mujoco.mj_energyPos(m, d)
            mujoco.mj_energyVel(m, d)
            dE = max(dE, abs(float(d.energy.sum()) - E0))
    pm = case.model.pinocchio_model
    pd = pm.createData()
    cms = case.pin_constraints(pm)
    clos = max(_pin_closure(case, pm, pd, cms, case.model.pinocchio_configuration(q)) for q in Qs)
    return {"t": np.array(ts), "q": np.array(Qs), "closure": clos, "dE": dE, "status": "success"}


# --------------------------------------------------------------------------- driver


def machine() -> dict[str, Any]:
    info: dict[str, Any] = {"python": sys.version.split()[0], "platform": platform.platform(),
                            "cpus": os.cpu_count(), "loadavg": os.getloadavg()}
    for mod in ("numpy", "pinocchio", "mujoco"):
        try:
            info[mod] = __import__(mod).__version__
        except Exception:  # a missing peer is reported, not fatal
            info[mod] = None
    import nonmin

    info["nonmin"] = nonmin.__version__
    return info


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", default=",".join(CASES))
    ap.add_argument("--engines", default="nonmin,pinocchio,mujoco")
    # 0.6 s: the dual-arm grasp's left wrist reaches its joint stop (π) at 0.719 s; nonmin enforces
    # URDF limits, the peers' models here do not, so longer runs compare different physics.
    ap.add_argument("--horizon", type=float, default=0.6)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--dt-ref", type=float, default=1e-4)
    ap.add_argument("--quick", action="store_true", help="short horizon, one dt per engine")
    ap.add_argument("--json", default=str(HERE / "results" / "robot_bench.json"))
    ap.add_argument("--wp", default=None, metavar="JSON",
                    help="work-precision mode: every engine over its full range (nonmin RK4 and "
                         "DOPRI5/DOP853 rtol 1e-2..1e-10, with and without joint limits, the coarse end "
                         "also at its step ends; Pinocchio Kp 0 and 100, MuJoCo), dt up to 1.6e-2; rows "
                         "also written in work_precision.py's format to JSON")
    ap.add_argument("--cpu", action="store_true", help="time with the process's CPU time instead of wall time")
    a = ap.parse_args(argv)
    if a.cpu:
        CLOCK[0] = time.process_time
    T = 0.2 if a.quick else a.horizon
    dts = [1e-3] if a.quick else [5e-4, 1e-3, 2e-3, 4e-3, 8e-3] + ([1.6e-2] if a.wp else [])
    engines = a.engines.split(",")
    rows: list[dict[str, Any]] = []
    for cname in a.cases.split(","):
        case = CASES[cname](T)
        ref = run_nonmin(case, a.dt_ref, T)
        refpair = (ref["t"], ref["q"])
        runs: list[tuple[str, str, float, Callable[[], dict[str, Any]]]] = []
        for dt in dts:
            if "nonmin" in engines:
                runs.append(("nonmin", "rk4", dt, lambda dt=dt, case=case: run_nonmin(case, dt, T)))
            if "pinocchio" in engines:
                runs.append(("pinocchio", f"rk4 Kp={KP:g} Kd={KD:g}", dt, lambda dt=dt, case=case: run_pinocchio(case, dt, T)))
                if a.wp:
                    runs.append(("pinocchio", "rk4 Kp=0 Kd=0", dt, lambda dt=dt, case=case: run_pinocchio(case, dt, T, 0.0)))
            if "mujoco" in engines:
                for integ in ("RK4", "implicitfast"):
                    for stiff in (False, True):
                        label = f"{integ} {'stiff' if stiff else 'default'}"
                        runs.append(("mujoco", label, dt,
                                     lambda dt=dt, integ=integ, stiff=stiff, case=case: run_mujoco(case, dt, T, integ, stiff)))
        if a.wp and "nonmin" in engines:
            for meth in ("dopri5", "dop853"):
                for rtol in (1e-2, 3e-3, 1e-3, 1e-4, 1e-6, 1e-8, 1e-10):
                    runs.append(("nonmin", f"{meth} rtol={rtol:g}", None,
                                 lambda meth=meth, rtol=rtol, case=case: run_nonmin(case, None, T, method=meth, rtol=rtol,
                                                                                    atol=rtol * 1e-2)))
            # the same robot without its joint limits, as the peers model it (no guards to watch:
            # the whole run in the engine); the coarse end of the range
            free = without_joint_limits(case.model)
            if free.constraint_names != case.model.constraint_names:
                for dt in (4e-3, 8e-3, 1e-2, 1.6e-2, 3.2e-2):
                    runs.append(("nonmin", "rk4 no joint limits", dt,
                                 lambda dt=dt, case=case, free=free: run_nonmin(case, dt, T, model=free)))
                # recorded at the step ends (t_eval=None), as the peers record theirs; the error
                # at every step end (the reference sampled there)
                for dt in (1.2e-2, 1.5e-2, 1.6e-2, 2e-2):
                    runs.append(("nonmin", "rk4 no joint limits step ends", dt,
                                 lambda dt=dt, case=case, free=free: run_nonmin(case, dt, T, model=free, t_eval=None)))
                for meth in ("dopri5", "dop853"):
                    for rtol in (1e-2, 3e-3, 1e-3):
                        runs.append(("nonmin", f"{meth} no joint limits step ends rtol={rtol:g}", None,
                                     lambda meth=meth, rtol=rtol, case=case, free=free: run_nonmin(
                                         case, None, T, model=free, method=meth, rtol=rtol, atol=rtol * 1e-2,
                                         t_eval=None)))
                for meth in ("dopri5", "dop853"):
                    for rtol in (1e-2, 3e-3, 1e-3, 1e-4):
                        runs.append(("nonmin", f"{meth} no joint limits rtol={rtol:g}", None,
                                     lambda meth=meth, rtol=rtol, case=case, free=free: run_nonmin(
                                         case, None, T, model=free, method=meth, rtol=rtol, atol=rtol * 1e-2)))
        for eng, setting, dt, fn in runs:
            try:
                wall, out = _timed(fn, a.repeat)
            except Exception as exc:  # a failing peer setting is a result
                rows.append({"case": cname, "engine": eng, "setting": setting, "dt": dt, "error": repr(exc)})
                print(f"{cname:15s} {eng:10s} {setting:22s} dt={dt or 0:.2g}  FAILED: {exc!r}", flush=True)
                continue
            if out["status"] != "success":
                err = np.inf
            elif "step ends" in setting:  # every step end, against the reference sampled there
                own = run_nonmin(case, a.dt_ref, T, t_eval=np.asarray(out["t"]))
                err = _errors(case, out["t"], out["q"], (own["t"], own["q"]))
            else:
                err = _errors(case, out["t"], out["q"], refpair)
            row = {"case": cname, "engine": eng, "setting": setting, "dt": dt, "T": T,
                   "wall_per_sim_s": wall / T, "err_rad": err, "closure_m": out["closure"],
                   "dE_J": out["dE"], "status": out["status"], "nonmin_engine": out.get("engine")}
            rows.append(row)
            print(f"{cname:15s} {eng:10s} {setting:22s} dt={dt or 0:.2g}  {wall / T * 1e3:9.2f} ms/s  "
                  f"err {err:.1e} rad  closure {out['closure']:.1e}  dE {out['dE']:.1e}  {out['status']}",
                  flush=True)
    res = {"machine": machine(), "horizon": T, "dt_ref": a.dt_ref, "rows": rows,
           "clock": "process CPU time" if a.cpu else "wall time", "date_utc": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
           "command": " ".join(["python", "benchmarks/robot_bench.py", *(argv or sys.argv[1:])])}
    Path(a.json).parent.mkdir(parents=True, exist_ok=True)
    Path(a.json).write_text(json.dumps(res, indent=1, default=float))
    if a.wp:
        Path(a.wp).write_text(json.dumps(to_work_precision(res), indent=1, default=float))


def to_work_precision(res: dict[str, Any]) -> dict[str, Any]:
    """The rows in ``work_precision.py``'s format: one mechanism per case; the joint-angle error
    (rad) stands in the position-error column."""
    mechs: dict[str, Any] = {}
    for r in res["rows"]:
        if "error" in r:
            continue
        ok = r["status"] == "success" and bool(np.isfinite(r["err_rad"]))
        mechs.setdefault(r["case"], {"t_final": r["T"], "rows": []})["rows"].append({
            "engine": r["engine"], "setting": r["setting"], "mechanism": r["case"], "dt": r["dt"],
            "t_final": r["T"], "status": "ok" if ok else r["status"], "on_branch": ok,
            "error_vs_reference_max": r["err_rad"], "energy_drift": r["dE_J"], "closure_max": r["closure_m"],
            "wall_per_sim_s": r["wall_per_sim_s"] if ok else None,
        })  # fmt: skip
    return {"command": res["command"], "machine": res["machine"], "mechanisms": mechs}


if __name__ == "__main__":
    main()
