"""A robot's description for the compiled engine: :func:`compile_tree`.

Extracted once, when a :class:`~nonmin.model.robots.RobotModel` is built, from its Pinocchio
model (URDF, MJCF through the MuJoCo conversion, or any ``pinocchio.Model``): the tree (joint
types, parents, axes, placements, body inertias, armature, gravity), every frame, the
constraints in row order, the actuated velocity components and the damping. The engine's
:class:`nonmin._engine.TreeProgram` (``engine/include/nonmin/rbd``) then evaluates M, h, f_p,
B, the constraint rows and the energy without calling Pinocchio.

Joint types the engine evaluates: revolute (``RX``, ``RY``, ``RZ``, ``RevoluteUnaligned``),
prismatic (``PX``, ``PY``, ``PZ``, ``PrismaticUnaligned``), ``Spherical``, ``FreeFlyer`` and
``Translation``. A tree with another joint type (e.g. ``SphericalZYX``, ``Universal``,
``Helical``, composite or mimic joints) has no engine program: :func:`compile_tree` returns
None and the model evaluates through Pinocchio as before.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from .._protocol import FloatArray
from ._constraints import (
    DistanceDriver,
    FrameConstraint,
    JointCoupling,
    JointDriver,
    JointLimit,
    PathDriver,
    RobotConstraint,
    complete_basis,
)

__all__ = ["ROW_TYPES", "compile_tree", "tree_arrays"]

#: Engine codes of the joint types (rbd::JointType) by Pinocchio short name: (code, axis index).
_JOINTS: dict[str, tuple[int, int]] = {
    "JointModelRX": (0, 0),
    "JointModelRY": (0, 1),
    "JointModelRZ": (0, 2),
    "JointModelRevoluteUnaligned": (0, -1),
    "JointModelPX": (1, 0),
    "JointModelPY": (1, 1),
    "JointModelPZ": (1, 2),
    "JointModelPrismaticUnaligned": (1, -1),
    "JointModelSpherical": (2, -1),
    "JointModelFreeFlyer": (3, -1),
    "JointModelTranslation": (4, -1),
}

#: Engine codes of the constraint row types (rbd::RowType).
ROW_TYPES: dict[str, int] = {
    "unit_quaternion": 0,
    "point": 1,
    "weld": 2,
    "hinge": 3,
    "planar_point": 4,
    "planar_weld": 5,
    "point_on_plane": 6,
    "contact": 7,
    "joint": 8,
    "joint_limit": 9,
    "joint_driver": 10,
    "path_driver": 11,
    "distance_driver": 12,
}


def tree_arrays(
    pm: Any,
    quaternion_starts: Sequence[tuple[str, int]],
    constraints: Sequence[RobotConstraint],
    frame_ids: Mapping[str, tuple[int, int]],
    joint_q: Mapping[str, int],
    actuated_v: Sequence[int],
    damping: FloatArray,
) -> dict[str, Any] | None:
    """The keyword arguments of ``nonmin._engine.TreeProgram``, or None if unsupported.

    Parameters
    ----------
    pm : pinocchio.Model
        The robot's tree, with the constraint frames already added.
    quaternion_starts : sequence of (name, int)
        The structural unit-quaternion constraints: name and first coordinate of the quaternion.
    constraints : sequence of RobotConstraint
        The user constraints, in row order (after the structural ones).
    frame_ids : mapping
        Constraint name -> (frame a, frame b) ids in ``pm``.
    joint_q : mapping
        Scalar joint name -> its coordinate index (joint couplings and limits).
    actuated_v : sequence of int
        Velocity index of each actuator (columns of B).
    damping : ndarray, shape (nv,)
    """
    nj = pm.njoints - 1
    types = np.zeros(nj, dtype=np.int64)
    axis_index = np.full(nj, -1, dtype=np.int64)
    axes = np.zeros((nj, 3))
    axes[:, 2] = 1.0
    for i in range(nj):
        jm = pm.joints[i + 1]
        code = _JOINTS.get(jm.shortname())
        if code is None:
            return None
        types[i], axis_index[i] = code
        if code[1] >= 0:
            axes[i] = np.eye(3)[code[1]]
        elif code[0] in (0, 1):
            ax = np.array(jm.extract().axis, dtype=float)
            if abs(float(np.linalg.norm(ax)) - 1.0) > 1e-12:
                return None  # Pinocchio does not normalize: keep its own evaluation
            axes[i] = ax
    parents = np.array([pm.parents[j] - 1 for j in range(1, pm.njoints)], dtype=np.int64)
    iq = np.array([pm.joints[j].idx_q for j in range(1, pm.njoints)], dtype=np.int64)
    iv = np.array([pm.joints[j].idx_v for j in range(1, pm.njoints)], dtype=np.int64)
    placements = np.array(
        [np.array(pm.jointPlacements[j].homogeneous) for j in range(1, pm.njoints)]
    ).reshape(nj, 4, 4)
    inertias = [pm.inertias[j] for j in range(1, pm.njoints)]
    masses = np.array([float(Y.mass) for Y in inertias])
    coms = np.array([np.array(Y.lever) for Y in inertias]).reshape(nj, 3)
    rot = np.array([np.array(Y.inertia) for Y in inertias]).reshape(nj, 3, 3)
    nf = len(pm.frames)
    frame_joints = np.array([pm.frames[f].parentJoint - 1 for f in range(nf)], dtype=np.int64)
    frame_placements = np.array(
        [np.array(pm.frames[f].placement.homogeneous) for f in range(nf)]
    ).reshape(nf, 4, 4)

    names: list[str] = []
    ctypes: list[int] = []
    cframes: list[tuple[int, int]] = []
    caxes: list[FloatArray] = []
    cu: list[FloatArray] = []
    ciq: list[tuple[int, int]] = []
    ccoef: list[tuple[float, ...]] = []
    cref: list[tuple[float, float]] = []
    cdrv: list[tuple[int, int, int]] = []
    z = np.array([0.0, 0.0, 1.0])
    basis = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    for name, start in quaternion_starts:
        names.append(name)
        ctypes.append(ROW_TYPES["unit_quaternion"])
        cframes.append((-1, -1))
        caxes.append(z)
        cu.append(basis)
        ciq.append((start, -1))
        ccoef.append((0.0,) * 5)
        cref.append((0.0, 0.0))
    drivers: list[Any] = []
    for c in constraints:
        names.append(c.name)
        drv = [-1, -1, -1]
        if isinstance(c, PathDriver):  # e_i·(p_b − p_a) − f_i(t): driver indices per world axis
            for i, fn in zip(c.axes, c.motions, strict=True):
                drv[i] = len(drivers)
                drivers.append(fn.engine())
        elif isinstance(c, DistanceDriver):  # (dᵀd − f²)/(2L): reference length L in ref1
            drv[0] = len(drivers)
            drivers.append(c.motion.engine())
        cdrv.append((drv[0], drv[1], drv[2]))
        if isinstance(c, PathDriver | DistanceDriver):
            ctypes.append(ROW_TYPES["path_driver" if isinstance(c, PathDriver) else "distance_driver"])
            cframes.append(frame_ids[c.name])
            caxes.append(z)
            cu.append(basis)
            ciq.append((-1, -1))
            ccoef.append((0.0,) * 5)
            cref.append((c.reference if isinstance(c, DistanceDriver) else 0.0, 0.0))
            continue
        if isinstance(c, JointCoupling):
            ctypes.append(ROW_TYPES["joint"])
            cframes.append((-1, -1))
            caxes.append(z)
            cu.append(basis)
            ciq.append((joint_q[c.joint1], -1 if c.joint2 is None else joint_q[c.joint2]))
            ccoef.append(tuple(c.polycoef))
            cref.append((c.reference1, c.reference2))
            continue
        if isinstance(c, JointDriver):  # q - f(t): the time function's index in iq2
            ctypes.append(ROW_TYPES["joint_driver"])
            cframes.append((-1, -1))
            caxes.append(z)
            cu.append(basis)
            ciq.append((joint_q[c.joint], len(drivers)))
            drivers.append(c.motion.engine())
            ccoef.append((0.0,) * 5)
            cref.append((0.0, 0.0))
            continue
        if isinstance(c, JointLimit):  # gap s (q - bound): sign in coef[0], bound in ref1
            ctypes.append(ROW_TYPES["joint_limit"])
            cframes.append((-1, -1))
            caxes.append(z)
            cu.append(basis)
            ciq.append((joint_q[c.joint], -1))
            ccoef.append((c.sign, 0.0, 0.0, 0.0, 0.0))
            cref.append((c.bound, 0.0))
            continue
        assert isinstance(c, FrameConstraint)
        ctypes.append(ROW_TYPES[c.type])
        cframes.append(frame_ids[c.name])
        caxes.append(np.asarray(c.axis, dtype=float))
        u1, u2 = complete_basis(c.axis)
        cu.append(np.vstack([u1, u2]))
        ciq.append((-1, -1))
        ccoef.append((0.0,) * 5)
        cref.append((0.0, 0.0))
    nc = len(names)
    return {
        "nq": int(pm.nq),
        "nv": int(pm.nv),
        "types": types,
        "parents": parents,
        "axis_index": axis_index,
        "axes": np.ascontiguousarray(axes),
        "iq": iq,
        "iv": iv,
        "placements": np.ascontiguousarray(placements),
        "masses": masses,
        "coms": np.ascontiguousarray(coms),
        "inertias": np.ascontiguousarray(rot),
        "gravity": np.array(pm.gravity.linear, dtype=float),
        "armature": np.array(pm.armature, dtype=float).reshape(pm.nv),
        "frame_joints": frame_joints,
        "frame_placements": np.ascontiguousarray(frame_placements),
        "c_names": names,
        "c_types": np.array(ctypes, dtype=np.int64).reshape(nc),
        "c_frames": np.array(cframes, dtype=np.int64).reshape(nc, 2),
        "c_axes": np.array(caxes, dtype=float).reshape(nc, 3),
        "c_u": np.array(cu, dtype=float).reshape(nc, 2, 3),
        "c_iq": np.array(ciq, dtype=np.int64).reshape(nc, 2),
        "c_coef": np.array(ccoef, dtype=float).reshape(nc, 5),
        "c_ref": np.array(cref, dtype=float).reshape(nc, 2),
        "actuated": np.array(actuated_v, dtype=np.int64),
        "damping": np.ascontiguousarray(damping, dtype=float),
        "drivers": drivers,
        "c_drv": np.array([(-1, -1, -1)] * len(quaternion_starts) + cdrv, dtype=np.int64).reshape(nc, 3),
    }


def compile_tree(*args: Any, **kwargs: Any) -> Any | None:
    """The engine's ``TreeProgram`` of a robot (arguments of :func:`tree_arrays`), or None."""
    arrays = tree_arrays(*args, **kwargs)
    if arrays is None:
        return None
    from ... import _engine  # type: ignore[attr-defined]  # compiled extension, no stub

    return _engine.TreeProgram(**arrays)
