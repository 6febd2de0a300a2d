"""A03 Andrews' squeezing mechanism as MuJoCo, Pinocchio and Exudyn models (issue 18, target 4).

The Test Set (Mazzia & Magherini, problem ``andrews``; Hairer & Wanner II §VII.7) states the
mechanism in seven relative angles q = (β, Θ, γ, Φ, δ, Ω, ε) with a given mass matrix, three loop
closures at the point E and a spring between C and D. The peers need it as bodies and joints.
Read back from the Test Set's formulas (``nonmin.library.AndrewsModel``), all in the plane:

=====  ==============  =====================  ======================================================
body   pivot (frame)   frame angle            points in the body frame
=====  ==============  =====================  ======================================================
1      O = (0, 0)      β                      F = (rr, 0); centre of mass at (ra, 0)
2      F               β + Θ                  E = (−d, 0); centre of mass (−da, 0)
3      B = (xb, yb)    γ                      E = (0, −ss); D = (sd, −sc); centre of mass (sb, −sa)
5      A = (xa, ya)    δ                      G = (zt, 0); centre of mass (ta, tb)
4      G               Φ + δ                  E = (0, −e); centre of mass (0, −(e − ea))
7      A               ε                      H = (0, −u); centre of mass (ub, −ua)
6      H               Ω + ε                  E = (zf, 0); centre of mass (zf − fa, 0)
=====  ==============  =====================  ======================================================

This reproduces every entry of the Test Set's M(q) and its constraints g1 … g6 (E of body 2 = E
of bodies 3, 4 and 6). The Test Set fixes only the distance of the centres of mass of bodies 1,
3, 5 and 7 from their ground pivots (ra, √(sa² + sb²), √(ta² + tb²), √(ua² + ub²)); without
gravity their direction in the body does not enter the dynamics. The motor torque ``mom`` acts
on β (ground → body 1), the spring (c0, l0) between C = (xc, yc) on the ground and D on body 3.

Each peer is checked against the Test Set's PSIDE reference at 0.03 s at its finest setting
(``tests/validation/test_andrews_peers.py``). Rows in ``sim_bench.py``'s format (``work_precision.py``
draws them): ``error_vs_reference_max`` = max over the seven angles at 0.03 s against the reference
(rad), ``energy_drift`` = max |E − E0| of E = T + c0 (ℓ − l0)²/2 − mom β over samples every
1e-3 s, ``closure_max`` = the largest distance between the four bodies' copies of E (m).
"""

from __future__ import annotations

import math
import statistics
import time
from collections.abc import Callable
from typing import Any

import numpy as np

T_FINAL = 0.03
SAMPLE_DT = 1e-3
#: The clock of every timed run (library_wp.py sets it: wall or process CPU time).
CLOCK: list[Callable[[], float]] = [time.perf_counter]

#: tree order (MuJoCo's and Pinocchio's depth-first numbering) from the Test Set's order
#: β Θ γ Φ δ Ω ε: the tree runs b1 b2 b3 b5 b4 b7 b6, i.e. β Θ γ δ Φ ε Ω
TREE_FROM_TESTSET = np.array([0, 1, 2, 4, 3, 6, 5])
TESTSET_FROM_TREE = np.argsort(TREE_FROM_TESTSET)


def params() -> Any:
    from nonmin.library import AndrewsModel

    return AndrewsModel()


def q0() -> np.ndarray:
    from nonmin.library._andrews import ANDREWS_Q0

    return np.array(ANDREWS_Q0)


def _rot(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s], [s, c]])


def bodies(p: Any | None = None) -> dict[str, dict[str, Any]]:
    """The seven bodies: parent (``"world"`` or a body), the frame's origin in the parent frame,
    mass, inertia about the centre of mass, the centre of mass and the named points in the body
    frame (see the module's table). Insertion order is the tree's depth-first order."""
    p = p or params()
    m, inertia = p.m, p.I
    return {
        "b1": {"parent": "world", "at": (0.0, 0.0), "m": m[0], "I": inertia[0], "com": (p.ra, 0.0),
               "points": {"F": (p.rr, 0.0)}},
        "b2": {"parent": "b1", "at": (p.rr, 0.0), "m": m[1], "I": inertia[1], "com": (-p.da, 0.0),
               "points": {"E": (-p.d, 0.0)}},
        "b3": {"parent": "world", "at": (p.xb, p.yb), "m": m[2], "I": inertia[2], "com": (p.sb, -p.sa),
               "points": {"E": (0.0, -p.ss), "D": (p.sd, -p.sc)}},
        "b5": {"parent": "world", "at": (p.xa, p.ya), "m": m[4], "I": inertia[4], "com": (p.ta, p.tb),
               "points": {"G": (p.zt, 0.0)}},
        "b4": {"parent": "b5", "at": (p.zt, 0.0), "m": m[3], "I": inertia[3], "com": (0.0, -(p.e - p.ea)),
               "points": {"E": (0.0, -p.e)}},
        "b7": {"parent": "world", "at": (p.xa, p.ya), "m": m[6], "I": inertia[6], "com": (p.ub, -p.ua),
               "points": {"H": (0.0, -p.u)}},
        "b6": {"parent": "b7", "at": (0.0, -p.u), "m": m[5], "I": inertia[5], "com": (p.zf - p.fa, 0.0),
               "points": {"E": (p.zf, 0.0)}},
    }  # fmt: skip


#: the three closures at E: (body, body), body 2's copy against each other body's
CLOSURES = (("b2", "b3"), ("b2", "b4"), ("b2", "b6"))


def frames(q: np.ndarray, p: Any | None = None) -> dict[str, tuple[np.ndarray, float]]:
    """World origin and angle of every body frame at the Test Set angles ``q`` (β Θ γ Φ δ Ω ε)."""
    bs = bodies(p)
    rel = dict(zip(bs, np.asarray(q, dtype=float)[TREE_FROM_TESTSET], strict=True))
    out: dict[str, tuple[np.ndarray, float]] = {}
    for name, b in bs.items():
        if b["parent"] == "world":
            out[name] = (np.array(b["at"], dtype=float), float(rel[name]))
        else:
            o, a = out[b["parent"]]
            out[name] = (o + _rot(a) @ np.array(b["at"]), a + float(rel[name]))
    return out


def point(fr: dict[str, tuple[np.ndarray, float]], body: str, local: Any) -> np.ndarray:
    o, a = fr[body]
    return o + _rot(a) @ np.asarray(local, dtype=float)


def closure(q: np.ndarray, p: Any | None = None) -> float:
    """The largest distance between body 2's E and the E of bodies 3, 4, 6 (m)."""
    bs = bodies(p)
    fr = frames(q, p)
    e2 = point(fr, "b2", bs["b2"]["points"]["E"])
    return max(float(np.linalg.norm(point(fr, b, bs[b]["points"]["E"]) - e2)) for _, b in CLOSURES)


def spring_length(q: np.ndarray, p: Any | None = None) -> float:
    p = p or params()
    fr = frames(q, p)
    d = point(fr, "b3", bodies(p)["b3"]["points"]["D"])
    return float(np.hypot(d[0] - p.xc, d[1] - p.yc))


def potential(q: np.ndarray, p: Any | None = None) -> float:
    """Spring and motor: c0 (ℓ − l0)²/2 − mom β (the library model's potential)."""
    p = p or params()
    return 0.5 * p.c0 * (spring_length(q, p) - p.l0) ** 2 - p.mom * float(q[0])


def reference() -> np.ndarray:
    """The seven angles at 0.03 s of the Test Set's PSIDE reference (rad)."""
    from nonmin.validation._references import load_a03_reference

    return np.asarray(load_a03_reference()[1][:7], dtype=float)


def _row(engine: str, setting: str, dt: float, walls: list[float], q_end: np.ndarray | None,
         energy: list[float], closures: list[float], n: int, status: str = "ok") -> dict[str, Any]:
    ok = status == "ok" and q_end is not None and bool(np.all(np.isfinite(q_end)))
    err = float(np.max(np.abs(np.asarray(q_end) - reference()))) if ok else None
    E = np.array(energy)
    return {
        "engine": engine, "setting": setting, "mechanism": "A03_andrews", "dt": dt, "t_final": T_FINAL,
        "status": "ok" if ok else (status if status != "ok" else "diverged"), "on_branch": ok,
        "closure_max": float(np.max(closures)) if ok and closures else None,
        "energy_drift": float(np.max(np.abs(E - E[0]))) if ok and len(E) else None,
        "error_vs_reference_max": err, "n_steps": n, "n_rejected": 0, "wall_runs_s": walls,
        "wall_per_sim_s": statistics.median(walls) / T_FINAL if ok and walls else None,
    }  # fmt: skip


# ------------------------------------------------------------------------------------ MuJoCo


def mjcf(dt: float, setting: str, integrator: str = "Euler") -> str:
    """MJCF: the hinge tree (bodies aligned with the world at q = 0), the spring as a spatial
    tendon C–D, no contacts; the three ``connect`` equalities at E get their anchors in
    :func:`run_mujoco` (both bodies' frames)."""
    p = params()
    bs = bodies(p)

    def v(*x: float) -> str:
        return " ".join(repr(float(a)) for a in x)

    def body(name: str) -> str:
        b = bs[name]
        inner = "".join(body(c) for c, cb in bs.items() if cb["parent"] == name)
        site = "".join(f'<site name="{name}_{k}" pos="{v(*xy, 0.0)}"/>' for k, xy in b["points"].items())
        return (f'<body name="{name}" pos="{v(*b["at"], 0.0)}">'
                f'<joint name="{name}_j" type="hinge" axis="0 0 1"/>'
                f'<inertial pos="{v(*b["com"], 0.0)}" mass="{v(b["m"])}" diaginertia="{v(b["I"], b["I"], b["I"])}"/>'
                f"{site}{inner}</body>")  # fmt: skip

    tree = "".join(body(n) for n, b in bs.items() if b["parent"] == "world")
    eq = "" if setting == "default" else f' solref="{2.0 * float(dt)!r} 1" solimp="0.99 0.999 0.001"'
    eqs = "".join(f'<connect name="E_{a}_{b}" body1="{a}" body2="{b}" anchor="0 0 0"{eq}/>' for a, b in CLOSURES)
    return ('<mujoco model="andrews"><compiler angle="radian" autolimits="true"/>'
            f'<option timestep="{float(dt)!r}" gravity="0 0 0" integrator="{integrator}">'
            '<flag contact="disable" energy="enable"/></option>'
            f'<worldbody><site name="C" pos="{v(p.xc, p.yc, 0.0)}"/>{tree}</worldbody>'
            f'<tendon><spatial name="spring" stiffness="{v(p.c0)}" springlength="{v(p.l0)}">'
            '<site site="C"/><site site="b3_D"/></spatial></tendon>'
            f"<equality>{eqs}</equality></mujoco>")  # fmt: skip


def run_mujoco(dt: float, setting: str, integrator: str, repeat: int) -> dict[str, Any]:
    """MuJoCo over 0.03 s: hinge tree + three ``connect`` at E, ``mom`` as ``qfrc_applied``."""
    import mujoco

    p = params()
    bs = bodies(p)
    model = mujoco.MjModel.from_xml_string(mjcf(dt, setting, integrator))
    for k, (a, b) in enumerate(CLOSURES):  # the anchor E in each body's frame
        model.eq_data[k, 0:2] = bs[a]["points"]["E"]
        model.eq_data[k, 2] = 0.0
        model.eq_data[k, 3:5] = bs[b]["points"]["E"]
        model.eq_data[k, 5] = 0.0
    data = mujoco.MjData(model)
    qpos0 = q0()[TREE_FROM_TESTSET]
    n = round(T_FINAL / dt)
    every = max(1, round(SAMPLE_DT / dt))
    jb1 = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, "b1_j")
    assert model.jnt_qposadr[jb1] == 0 and model.nq == 7
    walls: list[float] = []
    energy: list[float] = []
    qs: list[np.ndarray] = []
    ok = True
    for rep in range(repeat + 1):
        mujoco.mj_resetData(model, data)
        data.qpos[:] = qpos0
        data.qfrc_applied[0] = p.mom
        mujoco.mj_forward(model, data)
        if rep == 0 and np.max(np.abs(data.efc_pos[: data.ne])) > 1e-12:
            raise RuntimeError(f"A03 MJCF: the equalities do not hold at q0 ({np.max(np.abs(data.efc_pos[:data.ne])):.1e})")
        qs, energy = [], []
        t0 = CLOCK[0]()
        for k in range(n + 1):
            if k % every == 0:
                qs.append(data.qpos.copy())
                energy.append(float(data.energy[1]) + 0.5 * p.c0 * (float(data.ten_length[0]) - p.l0) ** 2
                              - p.mom * float(data.qpos[0]))  # fmt: skip
            if k < n:
                mujoco.mj_step(model, data)
        wall = CLOCK[0]() - t0
        if rep:
            walls.append(wall)
        if not np.all(np.isfinite(data.qpos)):
            ok = False
            break
    Q = [qq[TESTSET_FROM_TREE] for qq in qs]
    clos = [closure(qq, p) for qq in Q] if ok else []
    name = f"{integrator} {setting}"
    return _row("mujoco", name, dt, walls, Q[-1] if ok else None, energy, clos, n, "ok" if ok else "diverged")


# ------------------------------------------------------------------------------------ Pinocchio


def pinocchio_model() -> Any:
    """The hinge tree as a Pinocchio model (``JointModelRZ``; q in the tree's order)."""
    import pinocchio as pin

    bs = bodies()
    model = pin.Model()
    model.gravity.linear = np.zeros(3)
    jid: dict[str, int] = {"world": 0}
    for name, b in bs.items():
        j = model.addJoint(jid[b["parent"]], pin.JointModelRZ(), pin.SE3(np.eye(3), np.array([*b["at"], 0.0])),
                           f"{name}_j")
        model.appendBodyToJoint(j, pin.Inertia(b["m"], np.array([*b["com"], 0.0]), np.eye(3) * b["I"]),
                                pin.SE3.Identity())
        jid[name] = j
    return model


def run_pinocchio(dt: float, method: str, kp: float, repeat: int, mu: float = 1e-8) -> dict[str, Any]:
    """A Python loop of proximal ``constraintDynamics`` (the three closures as ``CONTACT_3D``
    points at E, Baumgarte ``Kp``, ``Kd = 2√Kp``), semi-implicit Euler or RK4; the spring's
    torque on γ and ``mom`` on β as joint torques."""
    import pinocchio as pin
    from pin_loops import point_closures, timed_runs  # beside this script

    p = params()
    bs = bodies(p)
    model = pinocchio_model()
    data = model.createData()
    names = list(bs)
    pairs = [(1 + names.index(a), [*bs[a]["points"]["E"], 0.0], 1 + names.index(b), [*bs[b]["points"]["E"], 0.0])
             for a, b in CLOSURES]  # fmt: skip
    cms, cdatas, prox = point_closures(model, data, pairs, kp, mu)
    xb, yb, sd, sc, xc, yc, c0, l0, mom = p.xb, p.yb, p.sd, p.sc, p.xc, p.yc, p.c0, p.l0, p.mom
    tau = np.zeros(7)

    def acc(q: np.ndarray, v: np.ndarray) -> np.ndarray:
        g = q[2]  # γ: body 3 hangs from the ground, its frame angle is γ
        cg, sg = math.cos(g), math.sin(g)
        dx, dy = xb + sd * cg + sc * sg - xc, yb + sd * sg - sc * cg - yc
        ell = math.hypot(dx, dy)
        tau[0] = mom
        tau[2] = -c0 * (ell - l0) * (dx * (-sd * sg + sc * cg) + dy * (sd * cg + sc * sg)) / ell
        return pin.constraintDynamics(model, data, q, v, tau, cms, cdatas, prox)

    n = round(T_FINAL / dt)
    every = max(1, round(SAMPLE_DT / dt))
    qs: list[np.ndarray] = []
    vs: list[np.ndarray] = []

    def start() -> tuple[np.ndarray, np.ndarray]:
        qs.clear()
        vs.clear()
        return q0()[TREE_FROM_TESTSET].copy(), np.zeros(7)

    def sample(q: np.ndarray, v: np.ndarray) -> None:
        qs.append(q.copy())
        vs.append(v.copy())

    walls, ok = timed_runs(acc, start, sample, dt, n, every, method, repeat, CLOCK[0], limit=1e8)
    energy = [float(pin.computeKineticEnergy(model, data, qq, vv)) + potential(qq[TESTSET_FROM_TREE], p)
              for qq, vv in zip(qs, vs, strict=True)] if ok else []  # fmt: skip
    Q = [qq[TESTSET_FROM_TREE] for qq in qs]
    clos = [closure(qq, p) for qq in Q] if ok else []
    setting = f"{'semi-implicit Euler' if method == 'euler' else 'RK4'} prox Kp={kp:g}"
    return _row("pinocchio", setting, dt, walls, Q[-1] if ok else None, energy, clos, n, "ok" if ok else "diverged")


# ------------------------------------------------------------------------------------ Exudyn


def run_exudyn(dt: float, rho: float, repeat: int) -> dict[str, Any]:
    """Exudyn: seven ``NodeRigidBody2D`` bodies (x, y, angle of the centre of mass), ten
    ``RevoluteJoint2D`` (seven of the tree, three closures at E), the spring as a
    ``SpringDamper`` C–D, ``mom`` as a ``Torque`` load on body 1; generalized-α (index 3) with
    spectral radius ``rho``."""
    import exudyn as exu
    from exudyn.itemInterface import (
        LoadTorqueVector,
        MarkerBodyPosition,
        MarkerBodyRigid,
        NodeRigidBody2D,
        ObjectConnectorSpringDamper,
        ObjectGround,
        ObjectJointRevolute2D,
        ObjectRigidBody2D,
        SensorNode,
    )

    p = params()
    bs = bodies(p)
    fr = frames(q0(), p)
    n = round(T_FINAL / dt)

    def build() -> tuple[Any, Any, dict[str, tuple[Any, Any]], Any]:
        sc = exu.SystemContainer()
        mbs = sc.AddSystem()
        gnd = mbs.AddObject(ObjectGround())
        obj: dict[str, Any] = {}
        sens: dict[str, tuple[Any, Any]] = {}
        for name, b in bs.items():
            _o, a = fr[name]
            c = point(fr, name, b["com"])
            nd = mbs.AddNode(NodeRigidBody2D(referenceCoordinates=[float(c[0]), float(c[1]), a],
                                             initialVelocities=[0.0, 0.0, 0.0]))
            obj[name] = mbs.AddObject(ObjectRigidBody2D(nodeNumber=nd, mass=float(b["m"]),
                                                        inertia=float(b["I"])))
            sens[name] = tuple(mbs.AddSensor(SensorNode(nodeNumber=nd, storeInternal=True, outputVariableType=kind))
                               for kind in (exu.OutputVariableType.Coordinates, exu.OutputVariableType.Coordinates_t))  # fmt: skip

        def mark(body: str, local: Any) -> Any:
            """A position marker at ``local`` of the body frame (Exudyn's body frame: the centre)."""
            if body == "world":
                return mbs.AddMarker(MarkerBodyPosition(bodyNumber=gnd, localPosition=[float(local[0]), float(local[1]), 0.0]))
            rel = np.asarray(local, dtype=float) - np.asarray(bs[body]["com"])
            return mbs.AddMarker(MarkerBodyPosition(bodyNumber=obj[body], localPosition=[float(rel[0]), float(rel[1]), 0.0]))

        for name, b in bs.items():  # the tree's hinges: the frame origin in the parent and in the body
            parent = b["parent"]
            mbs.AddObject(ObjectJointRevolute2D(markerNumbers=[mark(parent, b["at"]), mark(name, (0.0, 0.0))]))
        for a, b in CLOSURES:
            mbs.AddObject(ObjectJointRevolute2D(markerNumbers=[mark(a, bs[a]["points"]["E"]), mark(b, bs[b]["points"]["E"])]))
        mbs.AddObject(ObjectConnectorSpringDamper(markerNumbers=[mark("world", (p.xc, p.yc)), mark("b3", bs["b3"]["points"]["D"])],
                                                  stiffness=float(p.c0), damping=0.0, referenceLength=float(p.l0)))  # fmt: skip
        mrig = mbs.AddMarker(MarkerBodyRigid(bodyNumber=obj["b1"], localPosition=[0.0, 0.0, 0.0]))
        mbs.AddLoad(LoadTorqueVector(markerNumber=mrig, loadVector=[0.0, 0.0, float(p.mom)]))
        mbs.Assemble()
        s = exu.SimulationSettings()
        s.timeIntegration.numberOfSteps = n
        s.timeIntegration.endTime = T_FINAL
        s.timeIntegration.verboseMode = 0
        s.timeIntegration.generalizedAlpha.spectralRadius = rho
        s.timeIntegration.generalizedAlpha.computeInitialAccelerations = True
        s.solution.file.write = False
        s.solution.sensors.writePeriod = SAMPLE_DT
        s.show.statistics = False
        s.show.computationTime = False
        return sc, mbs, sens, s

    walls: list[float] = []
    ok = True
    status = "ok"
    mbs = sens = None
    for rep in range(repeat + 1):
        _sc, mbs, sens, s = build()
        t0 = CLOCK[0]()
        try:
            ok = bool(mbs.SolveDynamic(s))
        except Exception as exc:  # Exudyn raises on Newton failure
            ok = False
            status = f"failed: {type(exc).__name__}"
        if rep:
            walls.append(CLOCK[0]() - t0)
        if not ok:
            break
    assert mbs is not None and sens is not None
    if not ok:
        return _row("exudyn", f"gen-alpha rho={rho:g}", dt, walls, None, [], [], n,
                    status if status != "ok" else "failed: SolveDynamic returned False")
    names = list(bs)
    coords = {k: np.asarray(mbs.GetSensorStoredData(sens[k][0]))[:, 1:4] for k in names}
    rates = {k: np.asarray(mbs.GetSensorStoredData(sens[k][1]))[:, 1:4] for k in names}
    nt = min(len(c) for c in coords.values())
    ang = {k: fr[k][1] + coords[k][:nt, 2] for k in names}  # absolute frame angles
    Q = np.stack([ang["b1"], ang["b2"] - ang["b1"], ang["b3"], ang["b4"] - ang["b5"], ang["b5"],
                  ang["b6"] - ang["b7"], ang["b7"]], axis=1)  # fmt: skip
    kinetic = sum(0.5 * bs[k]["m"] * (rates[k][:nt, 0] ** 2 + rates[k][:nt, 1] ** 2)
                  + 0.5 * bs[k]["I"] * rates[k][:nt, 2] ** 2 for k in names)  # fmt: skip
    energy = [float(kinetic[i]) + potential(Q[i], p) for i in range(nt)]
    # the closure from the bodies' own positions (not from the angles: Exudyn's tree joints are
    # constraints too)
    clos = []
    for i in range(nt):
        pos = {}
        for k in names:
            c = np.array([point(fr, k, bs[k]["com"])[0] + coords[k][i, 0], point(fr, k, bs[k]["com"])[1] + coords[k][i, 1]])
            pos[k] = c + _rot(ang[k][i]) @ (np.asarray(bs[k]["points"].get("E", (np.nan, np.nan))) - np.asarray(bs[k]["com"]))
        clos.append(max(float(np.linalg.norm(pos[b] - pos[a])) for a, b in CLOSURES))
    return _row("exudyn", f"gen-alpha rho={rho:g}", dt, walls, Q[-1], energy, clos, n)
