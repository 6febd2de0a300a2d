"""Robots from MJCF: MuJoCo's parser, Pinocchio's algorithms.

This is the only nonmin module that imports :mod:`mujoco` (extra ``mujoco``).

Design choice (documented): the MJCF file is compiled by MuJoCo itself
(``mujoco.MjModel.from_xml_path``: defaults, ``fromto``, inertias from geoms, ``autolimits`` …
are all MuJoCo's), and the compiled tree is converted joint by joint into a ``pinocchio.Model``
whose rigid-body algorithms then give M, C, gravity and the frame Jacobians, exactly like a
URDF robot. The conversion is exact:

* a body with joints ``j₁ … j_k`` (MuJoCo applies them in order, each about its anchor
  ``jnt_pos`` and axis ``jnt_axis`` in the body frame) becomes a chain of Pinocchio joints
  ``T(p₁)·J₁·T(−p₁)·T(p₂)·J₂·T(−p₂)…`` (intermediate bodies massless); hinge →
  ``JointModelRevoluteUnaligned``, slide → ``JointModelPrismaticUnaligned``, ball →
  ``JointModelSpherical``, free → ``JointModelFreeFlyer``;
* bodies without joints are welded to their parent (inertia appended to the supporting joint);
* every body and site becomes a Pinocchio frame of the same name (the world body is
  ``"universe"``);
* ``dof_armature`` → ``model.armature``, ``dof_damping`` → joint damping, ``opt.gravity`` →
  gravity. Joint stiffness, damping of free joints, tendon and flex equalities are rejected
  (:class:`ModelError`).

Coordinates are Pinocchio's (quaternions ``x, y, z, w``); :meth:`RobotModel.from_mujoco_qpos`
and :meth:`RobotModel.to_mujoco_qpos` reorder MuJoCo's ``w, x, y, z``. MuJoCo's ``qvel`` equals
``qd`` for hinge and slide joints (free/ball joints: see the module doc of ``_pinocchio``).

Every ``<equality>`` becomes a nonmin constraint (Pinocchio and Drake import only ``connect``):

* ``connect`` → :meth:`FrameConstraint.point` (anchor in body1, MuJoCo's compiled anchor in
  body2; site semantic: the two sites),
* ``weld`` → :meth:`FrameConstraint.weld` with frame a = body1 · (relpose) and frame b =
  body2 · (anchor), i.e. MuJoCo's ``x₁ R₁ relpos = x₂ + R₂ anchor`` and ``q₁ relquat = q₂``
  (``torquescale`` only weights MuJoCo's soft error and does not change the constraint),
* ``joint`` → :class:`JointCoupling` with ``polycoef`` and references ``qpos0``.

Constraint names are the equality names (``eq<i>`` when unnamed); those with ``active="true"``
(MuJoCo's ``eq_active0``) are active by default.
"""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from ...errors import FileFormatError, JointLimitWarning, ModelError, missing_dependency
from ._constraints import (
    FrameConstraint,
    JointCoupling,
    RobotConstraint,
    _joint_limits_option,
    _robot_file,
)

try:
    import mujoco
except ImportError as exc:  # pragma: no cover - exercised in a subprocess test
    raise missing_dependency("mujoco", "mujoco", "Robots from MJCF (RobotModel.from_mjcf)") from exc
try:
    import pinocchio as pin
except ImportError as exc:  # pragma: no cover - exercised in a subprocess test
    raise missing_dependency("pinocchio", "pin", "Robots from URDF/MJCF (nonmin.model.robots)") from exc

__all__ = ["MAX_MJCF_BYTES", "build_pinocchio_model", "equality_constraints", "load_mjcf"]

#: Largest MJCF file read (bytes).
MAX_MJCF_BYTES = 64 * 2**20


def _quat_wxyz_to_rot(qw: ArrayLike) -> Any:
    w, x, y, z = np.asarray(qw, dtype=float)
    return pin.Quaternion(w, x, y, z).normalized().toRotationMatrix()


def _name(mj: Any, obj: Any, i: int, prefix: str) -> str:
    nm = mujoco.mj_id2name(mj, obj, i)
    return nm if nm else f"{prefix}{i}"


def build_pinocchio_model(mj: Any) -> tuple[Any, dict[str, Any]]:
    """Convert a compiled ``mujoco.MjModel`` into a ``pinocchio.Model`` (see module doc).

    Returns
    -------
    pin_model : pinocchio.Model
    info : dict
        ``body_frames`` (body id → frame name), ``joint_names`` (joint id → name),
        ``site_frames`` (site id → frame name).
    """
    pm = pin.Model()
    g = np.array(mj.opt.gravity, dtype=float)
    pm.gravity = pin.Motion(g, np.zeros(3))
    JT = mujoco.mjtJoint
    support = {0: 0}
    X = {0: pin.SE3.Identity()}
    body_frames = {0: "universe"}
    joint_names: dict[int, str] = {}
    if np.any(np.asarray(mj.jnt_stiffness) != 0.0):
        raise ModelError("MJCF joint stiffness (springs) is not supported by RobotModel")
    for b in range(1, mj.nbody):
        parent = int(mj.body_parentid[b])
        rel = pin.SE3(_quat_wxyz_to_rot(mj.body_quat[b]), np.array(mj.body_pos[b], dtype=float))
        cur_joint = support[parent]
        cur = X[parent] * rel
        adr, num = int(mj.body_jntadr[b]), int(mj.body_jntnum[b])
        for j in range(adr, adr + num):
            jtype = int(mj.jnt_type[j])
            name = _name(mj, mujoco.mjtObj.mjOBJ_JOINT, j, "joint")
            pos = np.array(mj.jnt_pos[j], dtype=float)
            axis = np.array(mj.jnt_axis[j], dtype=float)
            if jtype == JT.mjJNT_FREE:
                if cur_joint != 0 or num != 1:
                    raise ModelError(f"free joint {name!r} must be the only joint of a top-level body")
                jm: Any = pin.JointModelFreeFlyer()
                placement = pin.SE3.Identity()
                after = pin.SE3.Identity()
            else:
                if jtype == JT.mjJNT_HINGE:
                    jm = pin.JointModelRevoluteUnaligned(axis)
                elif jtype == JT.mjJNT_SLIDE:
                    jm = pin.JointModelPrismaticUnaligned(axis)
                elif jtype == JT.mjJNT_BALL:
                    jm = pin.JointModelSpherical()
                else:  # pragma: no cover - MuJoCo has no other joint types
                    raise ModelError(f"joint {name!r}: unsupported MuJoCo joint type {jtype}")
                placement = cur * pin.SE3(np.eye(3), pos)
                after = pin.SE3(np.eye(3), -pos)
            cur_joint = pm.addJoint(cur_joint, jm, placement, name)
            joint_names[j] = name
            cur = after
        support[b] = cur_joint
        X[b] = cur
        Ri = _quat_wxyz_to_rot(mj.body_iquat[b])
        inertia = pin.Inertia(
            float(mj.body_mass[b]),
            np.array(mj.body_ipos[b], dtype=float),
            Ri @ np.diag(np.array(mj.body_inertia[b], dtype=float)) @ Ri.T,
        )
        pm.appendBodyToJoint(cur_joint, inertia, cur)
        bname = _name(mj, mujoco.mjtObj.mjOBJ_BODY, b, "body")
        if pm.existFrame(bname):
            bname = f"{bname}_body"
        pm.addFrame(pin.Frame(bname, cur_joint, cur, pin.FrameType.BODY), False)
        body_frames[b] = bname
    site_frames: dict[int, str] = {}
    for s in range(mj.nsite):
        b = int(mj.site_bodyid[s])
        sname = _name(mj, mujoco.mjtObj.mjOBJ_SITE, s, "site")
        if pm.existFrame(sname):
            sname = f"{sname}_site"
        local = pin.SE3(_quat_wxyz_to_rot(mj.site_quat[s]), np.array(mj.site_pos[s], dtype=float))
        pm.addFrame(pin.Frame(sname, support[b], X[b] * local, pin.FrameType.OP_FRAME), False)
        site_frames[s] = sname
    for j, name in joint_names.items():
        if int(mj.jnt_type[j]) == JT.mjJNT_FREE:
            dofs = slice(int(mj.jnt_dofadr[j]), int(mj.jnt_dofadr[j]) + 6)
            if np.any(np.asarray(mj.dof_damping[dofs]) != 0.0):
                raise ModelError(
                    f"free joint {name!r}: damping is not supported (MuJoCo damps its world-frame "
                    "linear velocity, RobotModel damps Pinocchio's body-frame velocity)"
                )
    if pm.nv != mj.nv or pm.nq != mj.nq:  # pragma: no cover - guarded by construction
        raise ModelError(f"MJCF conversion mismatch: nq {pm.nq}/{mj.nq}, nv {pm.nv}/{mj.nv}")
    pm.armature = np.array(mj.dof_armature, dtype=float)
    return pm, {"body_frames": body_frames, "joint_names": joint_names, "site_frames": site_frames}


def _placement(pos: ArrayLike, quat_wxyz: ArrayLike | None = None) -> Any:
    H = np.eye(4)
    H[:3, 3] = np.asarray(pos, dtype=float)
    if quat_wxyz is not None:
        H[:3, :3] = _quat_wxyz_to_rot(quat_wxyz)
    return H


def equality_constraints(mj: Any, info: dict[str, Any]) -> tuple[list[RobotConstraint], set[str]]:
    """The MJCF ``<equality>`` elements as nonmin constraints, and the names active at start."""
    EQ = mujoco.mjtEq
    out: list[RobotConstraint] = []
    active: set[str] = set()
    for i in range(mj.neq):
        et = int(mj.eq_type[i])
        name = _name(mj, mujoco.mjtObj.mjOBJ_EQUALITY, i, "eq")
        data = np.array(mj.eq_data[i], dtype=float)
        o1, o2 = int(mj.eq_obj1id[i]), int(mj.eq_obj2id[i])
        site = int(mj.eq_objtype[i]) == int(mujoco.mjtObj.mjOBJ_SITE)
        c: RobotConstraint
        if et in (EQ.mjEQ_CONNECT, EQ.mjEQ_WELD):
            if site:
                fa, fb = info["site_frames"][o1], info["site_frames"][o2]
                Ha, Hb = np.eye(4), np.eye(4)
            else:
                fa, fb = info["body_frames"][o1], info["body_frames"][o2]
                if et == EQ.mjEQ_CONNECT:
                    Ha, Hb = _placement(data[0:3]), _placement(data[3:6])
                else:
                    Ha, Hb = _placement(data[3:6], data[6:10]), _placement(data[0:3])
            if et == EQ.mjEQ_CONNECT:
                c = FrameConstraint.point(name, fa, fb, placement_a=Ha, placement_b=Hb)
            else:
                c = FrameConstraint.weld(name, fa, fb, placement_a=Ha, placement_b=Hb)
        elif et == EQ.mjEQ_JOINT:
            j1 = info["joint_names"][o1]
            j2 = info["joint_names"][o2] if o2 >= 0 else None
            ref1 = float(mj.qpos0[mj.jnt_qposadr[o1]])
            ref2 = float(mj.qpos0[mj.jnt_qposadr[o2]]) if o2 >= 0 else 0.0
            c = JointCoupling(name, j1, j2, tuple(data[:5]), ref1, ref2)
        else:
            raise ModelError(
                f"MJCF equality {name!r}: type {mujoco.mjtEq(et).name} is not supported "
                "(supported: connect, weld, joint)"
            )
        out.append(c)
        if bool(mj.eq_active0[i]):
            active.add(name)
    return out, active


def load_mjcf(
    cls: Any,
    path: str | Path,
    *,
    constraints: tuple[RobotConstraint, ...] = (),
    gravity: ArrayLike | None = None,
    actuated: Any = None,
    default_active: Any = None,
    name: str | None = None,
    joint_limits: bool | str = True,
) -> Any:
    """Build a :class:`RobotModel` from an MJCF file (see the module docstring).

    ``cls`` is :class:`~nonmin.model.robots.RobotModel` or a subclass (this module sits below
    it: the model's ``from_mjcf`` calls here with itself).

    Joint position limits (``limited``/``range``): with ``joint_limits=True`` those of hinge
    and slide joints become unilateral :class:`JointLimit` constraints ``"<joint>.lower"`` /
    ``"<joint>.upper"`` (inactive by default; ball-joint limits are not enforced and a
    :class:`~nonmin.errors.JointLimitWarning` names them); with False (or ``"warn"``) none is
    enforced and the warning names them all; ``"ignore"`` is silent.
    MuJoCo's parse and compile errors become :class:`~nonmin.errors.FileFormatError`; moving
    bodies with non-positive mass or inertia become :class:`~nonmin.errors.ModelError`.
    """
    p = _robot_file(path, "MJCF")
    enforce = _joint_limits_option(joint_limits)
    try:
        size = p.stat().st_size
        if size > MAX_MJCF_BYTES:
            raise FileFormatError(f"path: {str(p)!r}: {size} bytes, more than the {MAX_MJCF_BYTES} an MJCF may have")
        if b"<!ENTITY" in p.read_bytes():
            raise FileFormatError(f"path: {str(p)!r}: MJCF files must not declare XML entities (<!ENTITY>)")
        mj = mujoco.MjModel.from_xml_path(str(p))
    except FileFormatError:
        raise
    except Exception as exc:  # MuJoCo raises ValueError for XML and compile errors
        raise FileFormatError(f"path: MuJoCo could not compile {str(p)!r}: {exc}") from exc
    for b in range(1, mj.nbody):
        moving = int(mj.body_dofnum[b]) > 0 or int(mj.body_weldid[b]) != 0
        mass = float(mj.body_mass[b])
        inertia = np.asarray(mj.body_inertia[b], dtype=float)
        if moving and not (np.isfinite(mass) and mass >= 0 and np.isfinite(inertia).all() and np.all(inertia >= 0)):
            raise ModelError(
                f"path: {str(p)!r}: body {_name(mj, mujoco.mjtObj.mjOBJ_BODY, b, 'body')!r} has mass "
                f"{mass!r} and inertia {inertia.tolist()}: they must be finite and ≥ 0"
            )
    limited = {
        _name(mj, mujoco.mjtObj.mjOBJ_JOINT, j, "joint"): (float(mj.jnt_range[j][0]), float(mj.jnt_range[j][1]))
        for j in range(mj.njnt)
        if bool(mj.jnt_limited[j])
    }
    scalar_types = (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE))
    scalar = {_name(mj, mujoco.mjtObj.mjOBJ_JOINT, j, "joint") for j in range(mj.njnt)
              if int(mj.jnt_type[j]) in scalar_types}
    unenforced = limited if enforce is False else {j: r for j, r in limited.items() if j not in scalar}
    if unenforced and enforce != "ignore":
        shown = ", ".join(f"{j} [{lo:g}, {hi:g}]" for j, (lo, hi) in list(unenforced.items())[:8])
        warnings.warn(
            f"{p}: joint position limits are not enforced by the dynamics: {shown}"
            f"{' and more' if len(unenforced) > 8 else ''}; a joint can move past them. Pass "
            "joint_limits=True to enforce hinge and slide limits as unilateral constraints, or "
            "joint_limits='ignore' to silence this warning",
            JointLimitWarning,
            stacklevel=3,
        )
    pm, info = build_pinocchio_model(mj)
    # the file's limits are the only ones (Pinocchio's addJoint defaults are "no limit")
    lo = np.full(pm.nq, -np.inf)
    hi = np.full(pm.nq, np.inf)
    if enforce is True:
        for jid in range(1, pm.njoints):
            jn = str(pm.names[jid])
            if jn in limited and jn in scalar:
                lo[pm.joints[jid].idx_q], hi[pm.joints[jid].idx_q] = limited[jn]
    pm.lowerPositionLimit = lo
    pm.upperPositionLimit = hi
    eqs, eq_active = equality_constraints(mj, info)
    user = tuple(constraints)
    if default_active is None:
        dflt = eq_active | {c.name for c in user if c.kind != "unilateral"}
    else:
        dflt = set(default_active)
    model_name = name or p.stem
    return cls.from_pinocchio(
        pm,
        constraints=(*eqs, *user),
        gravity=gravity,
        actuated=actuated,
        default_active=dflt,
        damping=np.array(mj.dof_damping, dtype=float),
        name=model_name,
        metadata={"source": str(p), "mujoco_joint_names": dict(info["joint_names"])},
        joint_limits=True if enforce is True else "ignore",
    )
