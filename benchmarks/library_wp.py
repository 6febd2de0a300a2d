"""Work–precision of nonmin's methods on the library mechanisms that ``sim_bench.py`` has no
peer models of: A03 Andrews' squeezing mechanism (0.03 s, the Test Set's stiff problem: angles
at 0.03 s against its PSIDE reference; energy and closure every 1e-3 s) and A04 Bricard (10 s,
one redundant constraint: P3 against a fine DOP853 run whose turning points match the quadrature
period to 2e-12 s; energy and closure). ``--peers`` adds MuJoCo, Pinocchio and Exudyn over their
settings on both (A03's peer models: ``andrews_peers.py``). nonmin runs two models of each: the
library's and a second formulation (A03: the same equations compiled from SymPy; A04: a tree of
hinges closed by one hinge). Every method over its steps or tolerances; the rows have the
format of ``sim_bench.py``'s, so ``work_precision.py`` draws them.

Run ``python benchmarks/library_wp.py --peers --cpu --json results/library_wp.json`` then
``python benchmarks/work_precision.py results/library_wp.json``.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import functools
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
        # the same equations (M, V, g1 … g6 of the Test Set) given as SymPy expressions: the
        # symbolic source compiles them to a tape the engine evaluates (the library's model is
        # Python methods, called back from the engine at every evaluation)
        *({"model": "symbolic", "method": "rk4", "dt": dt} for dt in (1e-3, 5e-4, 2e-4, 1e-4, 5e-5, 2e-5, 1e-5, 5e-6, 2e-6)),
        *({"model": "symbolic", "method": m, "rtol": r, "atol": r}
          for m in ("dopri5", "dop853") for r in (1e-2, 1e-3, 1e-4, 1e-6, 1e-8, 1e-10, 1e-12)),
        # RK4 without the singular-passage placement (Andrews' mechanism passes no singular
        # configuration; at coarse steps its fast-turning A makes the indicator project the
        # stage states: the coarse end's setting, issue 18 target 4)
        *({"method": "rk4", "dt": dt, "passages": False} for dt in (3e-3, 2e-3, 1.5e-3, 1e-3, 5e-4)),
    ],
    "A04_bricard": [
        *({"method": "rk4", "dt": dt} for dt in (0.2, 0.1, 5e-2, 2e-2, 1e-2, 5e-3, 2e-3, 1e-3)),
        *({"method": m, "rtol": r, "atol": r * 1e-2} for m in ("dopri5", "dop853") for r in (1e-4, 1e-6, 1e-8, 1e-10)),
        # the same mechanism as a tree of five hinges closed by one hinge constraint (n = 5):
        # nonmin's robot source on the Pinocchio model that the Pinocchio peer uses
        *({"model": "robot", "method": "rk4", "dt": dt} for dt in (0.4, 0.2, 0.1, 5e-2, 2e-2, 1e-2, 5e-3, 2e-3, 1e-3, 5e-4, 2e-4, 1e-4)),
        *({"model": "robot", "method": m, "rtol": r, "atol": r * 1e-2} for m in ("dopri5", "dop853") for r in (1e-4, 1e-6, 1e-8, 1e-10, 1e-12, 1e-13)),
    ],
}
HORIZON = {"A03_andrews": 0.03, "A04_bricard": 10.0}


#: MuJoCo peer on A04 (issue 18, target 4): Euler (its default) over coarse to fine steps,
#: default and stiff equality settings (as sim_bench.py's: solref = 2 dt, solimp 0.99 0.999).
MUJOCO_DTS = (1e-2, 5e-3, 2e-3, 1e-3, 5e-4, 2e-4)
_A04_FINE: dict[str, np.ndarray] = {}


#: The clock of every timed run: wall time, or the process's CPU time (``--cpu``, for a loaded
#: machine: the measure its load does not inflate).
CLOCK = [time.perf_counter]

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
        t0 = CLOCK[0]()
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
            walls.append(CLOCK[0]() - t0)
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
        "wall_per_sim_s": statistics.median(walls) / T if ok and walls else None,
    }  # fmt: skip


#: Pinocchio peer on A04: a Python loop of proximal ``constraintDynamics`` (the same hinge chain,
#: closed by two ``CONTACT_3D`` points on J6's axis), semi-implicit Euler and RK4, Baumgarte
#: gains Kp = 0 (none) and Kp = 100 (Kd = 2 √Kp), proximal mu 1e-8.
PIN_DTS = (1e-2, 5e-3, 2e-3, 1e-3, 5e-4, 2e-4)
PIN_SETTINGS = tuple((m, kp) for m in ("euler", "rk4") for kp in (0.0, 100.0))
#: Exudyn peer on A04: rigid bodies (Euler parameters) with five revolute joints and J6, its
#: generalized-α solver (index 3) over spectral radii 0.6 / 0.9 / 1.0, redundant rows allowed
#: (``linearSolver.ignoreSingularJacobian`` with the dense LU; the sparse one fails to factorize).
EXUDYN_DTS = (1e-2, 5e-3, 2e-3, 1e-3, 5e-4, 2e-4)
EXUDYN_RHOS = (0.6, 0.9, 1.0)


def _a04_rod_inertia(start: Any, end: Any, mass: float = 1.0, width: float = 0.1) -> np.ndarray:
    """Principal moments of a rod about its centre in the world-aligned frame (axial m a²/6)."""
    p0, p1 = np.asarray(start), np.asarray(end)
    axial, transverse = mass * width**2 / 6.0, mass * (1.0 + width**2) / 12.0
    return np.where(np.abs(p1 - p0) > 0.5, axial, transverse)


def _peer_row(engine: str, setting: str, dt: float, walls: list[float], ok: bool, p3: list[Any],
              energy: list[float] | None, closure: list[float] | None, n: int) -> dict[str, Any]:
    ref = a04_fine_reference()
    P = np.array(p3)
    m = min(len(P), len(ref["P3"]))
    ok = ok and bool(np.all(np.isfinite(P)))
    err = float(np.max(np.abs(P[:m] - ref["P3"][:m]))) if ok else None
    T = HORIZON["A04_bricard"]
    E = np.array(energy) if energy else None
    return {
        "engine": engine, "setting": setting, "mechanism": "A04_bricard", "dt": dt, "t_final": T,
        "status": "ok" if ok else "diverged", "on_branch": ok,
        "closure_max": float(np.max(closure)) if closure else None,
        "energy_drift": float(np.max(np.abs(E - E[0]))) if E is not None and ok else None,
        "error_vs_reference_max": err, "n_steps": n, "n_rejected": 0, "wall_runs_s": walls,
        "wall_per_sim_s": statistics.median(walls) / T if ok and walls else None,
    }  # fmt: skip


def a04_pinocchio_model() -> Any:
    """A04 as a Pinocchio hinge chain ground → rod1 … rod5 (joint frames at J1 … J5, aligned
    with the world at the tabulated configuration; a frame per joint, named ``rod<i>_j``)."""
    import pinocchio as pin

    from nonmin.library.bricard import _JOINTS, _RODS

    model = pin.Model()
    model.gravity.linear = np.array([0.0, -9.81, 0.0])
    revolute = {0: pin.JointModelRX, 1: pin.JointModelRY, 2: pin.JointModelRZ}
    parent, prev = 0, np.zeros(3)
    for (name, start, end), (_, point, axis, _, _) in zip(_RODS, _JOINTS[:5], strict=True):
        jm = revolute[int(np.argmax(np.abs(axis)))]()
        parent = model.addJoint(parent, jm, pin.SE3(np.eye(3), np.asarray(point) - prev), f"{name}_j")
        c = 0.5 * (np.asarray(start) + np.asarray(end)) - np.asarray(point)
        model.appendBodyToJoint(parent, pin.Inertia(1.0, c, np.diag(_a04_rod_inertia(start, end))),
                                pin.SE3.Identity())
        model.addJointFrame(parent)
        prev = np.asarray(point)
    return model


def run_pinocchio_a04(dt: float, method: str, kp: float, repeat: int, mu: float = 1e-8) -> dict[str, Any]:
    """One Pinocchio run of A04 over 10 s (Python loop of ``constraintDynamics``)."""
    import pinocchio as pin
    from pin_loops import point_closures, timed_runs  # beside this script

    model = a04_pinocchio_model()
    parent = model.njoints - 1
    data = model.createData()
    # rod5's frame sits at J5 = (0, -1, 1): the points (0, 1, 0) and (1, 1, 0) of it are J6's axis
    local = (np.array([0.0, 1.0, 0.0]), np.array([1.0, 1.0, 0.0]))
    world = (np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 1.0]))
    pairs = [(parent, a, 0, b) for a, b in zip(local, world, strict=True)]
    cms, cdatas, prox = point_closures(model, data, pairs, kp, mu)
    tau = np.zeros(model.nv)
    T = HORIZON["A04_bricard"]
    n = round(T / dt)
    every = max(1, round(SAMPLE["dt"] / dt))
    rod3 = 3  # joint 3 sits at J3 = P3

    def acc(q: np.ndarray, v: np.ndarray) -> np.ndarray:
        return pin.constraintDynamics(model, data, q, v, tau, cms, cdatas, prox)

    p3: list[Any] = []
    energy: list[float] = []
    closure: list[float] = []

    def start() -> tuple[np.ndarray, np.ndarray]:
        p3.clear()
        energy.clear()
        closure.clear()
        return np.zeros(model.nq), np.zeros(model.nv)

    def sample(q: np.ndarray, v: np.ndarray) -> None:
        pin.forwardKinematics(model, data, q)
        p3.append(data.oMi[rod3].translation.copy())
        energy.append(float(pin.computeMechanicalEnergy(model, data, q, v)))
        M5 = data.oMi[parent]
        closure.append(max(float(np.abs(M5.act(a) - b).max()) for a, b in zip(local, world, strict=True)))

    walls, ok = timed_runs(acc, start, sample, dt, n, every, method, repeat, CLOCK[0])
    setting = f"{'semi-implicit Euler' if method == 'euler' else 'RK4'} prox Kp={kp:g}"
    return _peer_row("pinocchio", setting, dt, walls, ok, p3, energy, closure, n)


def run_exudyn_a04(dt: float, rho: float, repeat: int) -> dict[str, Any]:
    """One Exudyn run of A04 over 10 s: generalized-α (index 3) with spectral radius ``rho``."""
    import exudyn as exu
    import exudyn.utilities  # (adds the Create* methods to MainSystem)
    from exudyn.itemInterface import SensorBody
    from exudyn.utilities import InertiaCuboid, RigidBodyInertia

    from nonmin.library.bricard import _JOINTS, _RODS

    T = HORIZON["A04_bricard"]

    def build() -> tuple[Any, Any, Any, Any]:
        sc = exu.SystemContainer()
        mbs = sc.AddSystem()
        bodies = {"ground": mbs.CreateGround()}
        for name, start, end in _RODS:
            p0, p1 = np.asarray(start), np.asarray(end)
            sides = np.where(np.abs(p1 - p0) > 0.5, 1.0, 0.1)
            inertia = InertiaCuboid(density=1.0 / float(np.prod(sides)), sideLengths=list(sides))
            assert isinstance(inertia, RigidBodyInertia)
            bodies[name] = mbs.CreateRigidBody(inertia=inertia, referencePosition=list(0.5 * (p0 + p1)),
                                               gravity=[0.0, -9.81, 0.0])
        for _, point, axis, a, b in _JOINTS:
            mbs.CreateRevoluteJoint(itemNumbers=[bodies[a], bodies[b]], position=list(point),
                                    axis=list(axis), useGlobalFrame=True)
        def sensor(body: str, kind: Any, local: Any = (0.0, 0.0, 0.0)) -> Any:
            return mbs.AddSensor(SensorBody(bodyNumber=bodies[body], localPosition=list(local),
                                            storeInternal=True, outputVariableType=kind))

        O = exu.OutputVariableType
        centre = {name: 0.5 * (np.asarray(a) + np.asarray(b)) for name, a, b in _RODS}
        sens = {"P3": sensor("rod3", O.Position, np.asarray(_RODS[2][1]) - centre["rod3"]),
                "J6": [sensor("rod5", O.Position, np.asarray(p) - centre["rod5"]) for p in ((0, 0, 1), (1, 0, 1))]}
        for name, *_ in _RODS:  # energy: centre position and velocity, body angular velocity
            sens[name] = (sensor(name, O.Position), sensor(name, O.Velocity), sensor(name, O.AngularVelocityLocal))
        mbs.Assemble()
        s = exu.SimulationSettings()
        s.timeIntegration.numberOfSteps = round(T / dt)
        s.timeIntegration.endTime = T
        s.timeIntegration.verboseMode = 0
        s.timeIntegration.generalizedAlpha.spectralRadius = rho
        s.timeIntegration.generalizedAlpha.computeInitialAccelerations = True
        s.linearSolver.ignoreSingularJacobian = True  # the redundant row (dense LU only)
        s.linearSolver.solverType = exu.LinearSolverType.EigenDense
        s.solution.file.write = False
        s.solution.sensors.writePeriod = SAMPLE["dt"]
        s.show.statistics = False
        s.show.computationTime = False
        return sc, mbs, sens, s

    walls: list[float] = []
    ok = True
    mbs = sens = None
    for rep in range(repeat + 1):
        _sc, mbs, sens, s = build()
        t0 = CLOCK[0]()
        try:
            ok = bool(mbs.SolveDynamic(s))
        except Exception:  # Exudyn raises on Newton failure
            ok = False
        if rep:
            walls.append(CLOCK[0]() - t0)
        if not ok:
            break
    assert mbs is not None and sens is not None
    if not ok:
        return _peer_row("exudyn", f"gen-alpha rho={rho:g}", dt, walls, ok, [], None, None, round(T / dt))

    def series(sid: Any) -> np.ndarray:
        return np.asarray(mbs.GetSensorStoredData(sid))[:, 1:4]

    energy = 0.0
    for name, start, end in _RODS:
        pos, vel, om = (series(x) for x in sens[name])
        inertia = _a04_rod_inertia(start, end)
        energy = energy + 0.5 * np.sum(vel**2, axis=1) + 0.5 * (om**2 @ inertia) + 9.81 * pos[:, 1]
    closure = np.maximum(*(np.abs(series(x) - p).max(axis=1) for x, p in zip(sens["J6"], ((0, 0, 1), (1, 0, 1)), strict=True)))
    return _peer_row("exudyn", f"gen-alpha rho={rho:g}", dt, walls, ok, list(series(sens["P3"])), list(energy),
                     list(closure), round(T / dt))


def _andrews() -> Any:
    """``benchmarks/andrews_peers.py`` (A03's peer models), imported beside this script."""
    if "andrews_peers" not in sys.modules:
        sys.path.insert(0, str(HERE))
        import andrews_peers  # noqa: F401

        sys.path.remove(str(HERE))
    return sys.modules["andrews_peers"]


#: A03 peers over their ranges (andrews_peers.py): MuJoCo's Euler and RK4 with its default and
#: stiff equalities (implicitfast equals Euler here: no velocity-dependent forces), Pinocchio's
#: loop (semi-implicit Euler, RK4; Baumgarte Kp 0 and 1e4), Exudyn's generalized-α.
A03_MUJOCO_DTS = (2e-4, 1e-4, 5e-5, 2e-5, 1e-5, 5e-6, 2e-6, 1e-6)
A03_PIN_DTS = (1e-4, 5e-5, 2e-5, 1e-5, 5e-6, 2e-6)
A03_PIN_SETTINGS = tuple((m, kp) for m in ("euler", "rk4") for kp in (0.0, 1e4))
A03_EXUDYN_DTS = (2e-4, 1e-4, 5e-5, 2e-5, 1e-5, 5e-6, 2e-6)


def a03_peers(engines: list[str], repeat: int) -> list[Any]:
    ap = _andrews()
    out: list[Any] = []
    if "mujoco" in engines:
        out += [functools.partial(ap.run_mujoco, dt, st, integ, repeat)
                for integ in ("Euler", "RK4") for st in ("default", "stiff") for dt in A03_MUJOCO_DTS]
    if "pinocchio" in engines:
        out += [functools.partial(ap.run_pinocchio, dt, m, kp, repeat) for m, kp in A03_PIN_SETTINGS
                for dt in A03_PIN_DTS if m == "rk4" or dt >= 5e-6]  # fmt: skip
    if "exudyn" in engines:
        out += [functools.partial(ap.run_exudyn, dt, rho, repeat) for rho in EXUDYN_RHOS for dt in A03_EXUDYN_DTS]
    return out


def a04_robot() -> Any:
    """A04 with nonmin's robot source: :func:`a04_pinocchio_model` (five hinges, n = 5) closed by
    a :meth:`~nonmin.model.robots.FrameConstraint.hinge` between rod5 and the ground at J6
    (5 rows; with Bricard's geometry one of them is redundant along the whole motion)."""
    from nonmin.model.robots import FrameConstraint, RobotModel

    j6 = FrameConstraint.hinge("J6", "rod5_j", axis=(1.0, 0.0, 0.0), placement_a=np.array([0.0, 1.0, 0.0]),
                               placement_b=np.array([0.0, 0.0, 1.0]))
    return RobotModel.from_pinocchio(a04_pinocchio_model(), constraints=[j6], gravity=[0.0, -9.81, 0.0],
                                     joint_limits="ignore", name="A04_bricard_robot")


_A03_SYMBOLIC: list[Any] = []


def a03_symbolic() -> Any:
    """A03 with nonmin's symbolic source: the library model's own equations as SymPy
    expressions (``AndrewsModel.symbolic()``: the Test Set's M(q), V = c0 (ℓ − l0)²/2 − mom·β
    and g1 … g6), compiled to the engine's expression tape at first use (needs SymPy). The
    library model runs the same tape, shipped precompiled."""
    if _A03_SYMBOLIC:
        return _A03_SYMBOLIC[0]
    from nonmin.library import AndrewsModel

    _A03_SYMBOLIC.append(AndrewsModel().symbolic().replace(name="A03_andrews_symbolic"))
    return _A03_SYMBOLIC[0]


def a04_robot_p3(robot: Any, q: np.ndarray) -> np.ndarray:
    """P3 (the origin of joint 3's frame, J3) along the rows of ``q``, by Pinocchio's kinematics."""
    import pinocchio as pin

    model = a04_pinocchio_model()
    data = model.createData()
    out = np.empty((len(q), 3))
    for k, qk in enumerate(q):
        pin.forwardKinematics(model, data, qk)
        out[k] = data.oMi[3].translation
    return out


def run(name: str, cfg: dict[str, Any], repeat: int) -> dict[str, Any]:
    from nonmin import library, simulate
    from nonmin.validation._references import load_a03_reference

    T = HORIZON[name]
    cfg = dict(cfg)
    kind = cfg.pop("model", None)
    passages = cfg.pop("passages", True)
    label = f"{cfg['method']} projection" + ("" if passages else " passages=False")
    dt_row = cfg.get("dt")
    if not passages:
        from nonmin.sim import RK4

        cfg["method"] = RK4(dt=cfg.pop("dt"), passages=False)
    robot = kind == "robot"
    mech: Any = a04_robot() if robot else a03_symbolic() if kind == "symbolic" else library.get(name)
    # A03: every 1e-3 s (the peers' samples: energy and closure along the run; the error at 0.03 s)
    t_eval = np.round(np.arange(0.0, T + 1e-12, 1e-3 if name == "A03_andrews" else SAMPLE["dt"]), 10)
    walls = []
    tr = None
    for _ in range(repeat + 1):  # one warm-up run
        t0 = CLOCK[0]()
        if robot:
            tr = simulate(mech, (0.0, T), np.zeros(5), np.zeros(5), t_eval=t_eval, throw=False, progress=False, **cfg)
        elif kind == "symbolic":
            from nonmin.library._andrews import ANDREWS_Q0

            tr = simulate(mech, (0.0, T), ANDREWS_Q0, np.zeros(7), t_eval=t_eval, throw=False, progress=False, **cfg)
        else:
            tr = simulate(mech, (0.0, T), t_eval=t_eval, throw=False, progress=False, **cfg)
        walls.append(CLOCK[0]() - t0)
        if not tr.success:
            break
    assert tr is not None
    walls = walls[1:] or walls
    err = None
    if name == "A03_andrews" and tr.success:
        _, ref = load_a03_reference()
        err = float(np.max(np.abs(np.asarray(tr.q[-1])[:7] - ref[:7])))
    if name == "A04_bricard" and tr.success:
        p3 = a04_robot_p3(mech, np.asarray(tr.q)) if robot else np.asarray(tr.outputs(mech.model)["P3.position"])
        err = float(np.max(np.abs(p3 - a04_fine_reference()["P3"])))
    setting = ("robot tree+hinge " if robot else "symbolic tape " if kind == "symbolic" else "") + label + (f" rtol={cfg['rtol']:g}" if "rtol" in cfg else "")
    ok = bool(tr.success)
    return {
        "engine": "nonmin", "setting": setting + f" [{tr.metadata.get('engine')}]", "mechanism": name,
        "dt": dt_row, "t_final": T, "status": "ok" if ok else f"failed: {tr.message[:80]}",
        "on_branch": ok, "closure_max": float(np.max(tr.phi_norm)), "energy_drift": tr.energy_drift,
        "error_vs_reference_max": err, "n_steps": tr.n_steps, "n_rejected": tr.n_rejected,
        "wall_runs_s": walls, "wall_per_sim_s": statistics.median(walls) / T if ok else None,
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", default=str(HERE / "results" / "library_wp.json"))
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--mechanisms", default="A03_andrews,A04_bricard")
    ap.add_argument("--peers", action="store_true", help="add the peers (--peer-engines)")
    ap.add_argument("--peer-engines", default="mujoco,pinocchio,exudyn",
                    help="peers: MuJoCo (A04 Euler, A03 Euler and RK4; default and stiff equalities), Pinocchio "
                         "(constraintDynamics loop, Euler/RK4, A04 Kp 0/100, A03 Kp 0/1e4), Exudyn (gen-alpha)")
    ap.add_argument("--peers-only", action="store_true", help="skip nonmin's rows (merge files later)")
    ap.add_argument("--models", default="spatial,robot,library,symbolic",
                    help="nonmin's models: A04 spatial (the library's, n = 35) and robot (tree + hinge, n = 5); "
                         "A03 library (the hand-written Python model) and symbolic (the same equations "
                         "compiled from SymPy)")
    ap.add_argument("--sample", type=float, default=0.01, help="A04 output interval (s), a multiple of 0.01")
    ap.add_argument("--cpu", action="store_true", help="time with the process's CPU time instead of wall time")
    a = ap.parse_args(argv)
    if a.cpu:
        CLOCK[0] = time.process_time
        _andrews().CLOCK[0] = time.process_time
    SAMPLE["dt"] = float(a.sample)
    load = os.getloadavg()
    out: dict[str, Any] = {"command": "python benchmarks/library_wp.py " + " ".join(sys.argv[1:] if argv is None else argv),
                           "date_utc": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
                           "load_before": [round(x, 2) for x in load], "mechanisms": {},
                           "clock": "process CPU time" if a.cpu else "wall time"}  # fmt: skip
    for name in a.mechanisms.split(","):
        rows = []
        engines = a.peer_engines.split(",") if a.peers else []
        peers: list[Any] = []
        if name == "A03_andrews":
            peers = a03_peers(engines, a.repeat)
            engines = []
        if "mujoco" in engines:
            peers += [functools.partial(run_mujoco_a04, dt, st, a.repeat) for st in ("default", "stiff") for dt in MUJOCO_DTS]
        if "pinocchio" in engines:
            peers += [functools.partial(run_pinocchio_a04, dt, m, kp, a.repeat) for m, kp in PIN_SETTINGS for dt in PIN_DTS]
        if "exudyn" in engines:
            peers += [functools.partial(run_exudyn_a04, dt, rho, a.repeat) for rho in EXUDYN_RHOS for dt in EXUDYN_DTS]
        default_model = "spatial" if name == "A04_bricard" else "library"
        mine = [c for c in CONFIGS[name] if c.get("model", default_model) in a.models.split(",")]
        for cfg in [*(mine if not a.peers_only else []), *peers]:
            r = cfg() if callable(cfg) else run(name, cfg, a.repeat)
            rows.append(r)
            print(f"{name:>12} {r['setting']:<36} dt={r['dt']} err={r['error_vs_reference_max']} "
                  f"dE={r['energy_drift']} closure={r['closure_max']} steps={r['n_steps']} "
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
