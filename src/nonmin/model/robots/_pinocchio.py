"""Robots from URDF (and Pinocchio models) as nonmin models: :class:`RobotModel`.

This is the only nonmin module that imports :mod:`pinocchio` (extra ``pin``).

Coordinates (the ``nq ≠ nv`` choice)
------------------------------------
nonmin keeps *dependent* coordinates and its protocol assumes ``qd = dq/dt``. A
:class:`RobotModel` therefore uses Pinocchio's configuration vector itself as its n = nq
coordinates — including the 4 components ``(x, y, z, w)`` of every quaternion (free-flyer and
spherical joints) — and ``qd = dq/dt``. Pinocchio's velocity ``v`` (nv) is a linear function
of ``qd``:

    v = T(q) qd,   T (nv × nq) block diagonal:
      scalar / vector joints  T = I
      free flyer              v_lin = R(ε̂)ᵀ ṗ          (Pinocchio's v_lin is in the body frame)
      quaternion ε = (e, w)   ω = 2 G(ε) ε̇ / |ε|²,   G(ε) = [w I − [e]×,  −e]

``T`` is exact for *any* ε ≠ 0 (it is the angular velocity of ``R(ε/|ε|)``), so the kinetic
energy ``½ qdᵀ M qd`` with ``M = Tᵀ M_v T`` is a genuine Lagrangian in q, singular only in the
radial quaternion direction (which the model removes with one holonomic constraint per
quaternion, ``φ = ½(εᵀε − 1)``, named ``"<joint>.unit_quaternion"``; these *structural*
constraints are always active: :meth:`RobotModel.resolve_active` adds them to every active set).
By the chain rule (virtual power ``τᵀ v = (Tᵀτ)ᵀ qd``):

    M = Tᵀ M_v T,   C = Tᵀ C_v T + Tᵀ M_v Ṫ,   f_g = −Tᵀ g_v,   B = Tᵀ S,   A = A_v T,
    γ = γ_v + A_v Ṫ qd,

with Pinocchio's CRBA ``M_v`` (+ armature), Coriolis matrix ``C_v`` (``computeCoriolisMatrix``),
generalized gravity ``g_v`` and selection S of the actuated velocity components.
``dM/dt − 2C = Ṫᵀ M_v T − Tᵀ M_v Ṫ + Tᵀ (dM_v/dt − 2 C_v) T`` is skew-symmetric. For robots
without quaternions T = I and every term is Pinocchio's own.

Evaluation
----------
The tree is compiled once (:mod:`nonmin.model.robots._tree`) into the engine's
``TreeProgram`` (:meth:`RobotModel.engine_program`), which evaluates these terms in C++ with
its own CRBA and RNEA (``h = −Tᵀ rnea(q, v, Ṫ qd)``, no Coriolis matrix) and frame
kinematics, and on request the Christoffel Coriolis matrix and Ȧ; Pinocchio is the parser and
the oracle (``_evaluate_pinocchio`` and the other ``_*_pinocchio`` methods), and evaluates only
trees with joint types the engine does not have, and ``geometry``.

Constraints
-----------
See :mod:`nonmin.model.robots._constraints` for the frame constraints (point, weld, hinge,
planar, point-on-plane, contact) and joint couplings. Their rows are formed from
LOCAL_WORLD_ALIGNED frame Jacobians ``Jp, Jω`` and the frame *classical* accelerations at zero
joint acceleration (``p̈ = J̇p v + …``, ``ω̇``), which is exactly the ``J̇ v`` term of
world-aligned point velocities and angular velocities.
"""

from __future__ import annotations

import dataclasses
import warnings
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from ... import _engine  # type: ignore[attr-defined]  # compiled extension, no stub
from ..._validation import as_float_array
from ...errors import (
    FileFormatError,
    InputError,
    JointLimitWarning,
    ModelError,
    NonFiniteError,
    ShapeError,
    UnknownNameError,
    missing_dependency,
)
from .._protocol import ConstraintSpec, ConstraintTerms, FloatArray, Geometry, Model, ModelTerms
from ._constraints import (
    DistanceDriver,
    FrameConstraint,
    JointCoupling,
    JointDriver,
    JointLimit,
    PathDriver,
    RobotConstraint,
    _joint_limits_option,
    _robot_file,
    complete_basis,
)
from ._tree import compile_tree

try:
    import pinocchio as pin
except ImportError as exc:  # pragma: no cover - exercised in a subprocess test
    raise missing_dependency("pinocchio", "pin", "Robots from URDF/MJCF (nonmin.model.robots)") from exc

__all__ = ["RobotModel"]

_LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED

_NEED_M, _NEED_H, _NEED_A, _NEED_GAMMA = _engine.NEED_M, _engine.NEED_H, _engine.NEED_A, _engine.NEED_GAMMA
_NEED_PHI, _NEED_VELOCITY, _NEED_B = _engine.NEED_PHI, _engine.NEED_VELOCITY, _engine.NEED_B
_NEED_ENERGY = _engine.NEED_ENERGY
_NEED_CONSTRAINTS = _NEED_A | _NEED_GAMMA | _NEED_PHI | _NEED_VELOCITY
_NEED_EVALUATE = _NEED_M | _NEED_H | _NEED_B | _NEED_CONSTRAINTS
_NONE = np.empty(0)  # placeholder output array of a term not asked for
#: Position limits at or beyond this magnitude mean "unlimited" (Pinocchio's default is ±max double).
_NO_LIMIT = 1e300


def scalar_joint_limits(pm: Any) -> dict[str, tuple[float, float]]:
    """Finite position limits ``lower < upper`` of the 1-dof joints of a Pinocchio model.

    Read from ``lowerPositionLimit`` / ``upperPositionLimit`` for every joint with one
    coordinate and one velocity (revolute, prismatic; not continuous joints, whose nq is 2);
    bounds that are infinite or of magnitude ≥ 1e300 mean "no limit on that side".
    Returns joint name -> (lower, upper) with both sides finite; a one-sided limit is kept
    with the open side as ±inf.
    """
    lo = np.asarray(pm.lowerPositionLimit, dtype=float)
    hi = np.asarray(pm.upperPositionLimit, dtype=float)
    out: dict[str, tuple[float, float]] = {}
    for jid in range(1, pm.njoints):
        jm = pm.joints[jid]
        if jm.nq != 1 or jm.nv != 1:
            continue
        a, b = float(lo[jm.idx_q]), float(hi[jm.idx_q])
        a = a if np.isfinite(a) and abs(a) < _NO_LIMIT else -np.inf
        b = b if np.isfinite(b) and abs(b) < _NO_LIMIT else np.inf
        if (np.isfinite(a) or np.isfinite(b)) and a < b:
            out[str(pm.names[jid])] = (a, b)
    return out


def joint_limit_constraints(limits: dict[str, tuple[float, float]]) -> list[JointLimit]:
    """The unilateral constraints ``<joint>.lower`` / ``<joint>.upper`` of the given limits."""
    out: list[JointLimit] = []
    for joint, (a, b) in limits.items():
        if np.isfinite(a):
            out.append(JointLimit(f"{joint}.lower", joint, a, "lower"))
        if np.isfinite(b):
            out.append(JointLimit(f"{joint}.upper", joint, b, "upper"))
    return out


def _limits_text(limits: dict[str, tuple[float, float]], where: str) -> str:
    shown = ", ".join(f"{j} [{lo:g}, {hi:g}]" for j, (lo, hi) in list(limits.items())[:8])
    more = f" and {len(limits) - 8} more" if len(limits) > 8 else ""
    return (
        f"{where}: joint position limits are not enforced by the dynamics (joint_limits=False): "
        f"{shown}{more}; a joint can move past them. Pass joint_limits=True to enforce them as "
        "unilateral constraints, or joint_limits='ignore' to silence this warning"
    )


# --------------------------------------------------------------------------- small math


def _skew(w: FloatArray) -> FloatArray:
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


def _quat_G(eps: FloatArray) -> FloatArray:
    """G(ε) (3×4) with ω_body = 2 G(ε) ε̇ for a unit quaternion ε = (x, y, z, w)."""
    e, w = eps[:3], eps[3]
    return np.hstack([w * np.eye(3) - _skew(e), -e[:, None]])


def _quat_rot(eps: FloatArray) -> FloatArray:
    x, y, z, w = eps / np.linalg.norm(eps)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def _se3(H: FloatArray) -> Any:
    return pin.SE3(np.ascontiguousarray(H[:3, :3]), np.ascontiguousarray(H[:3, 3]))


@dataclass(frozen=True)
class _Block:
    joint: str
    kind: str  # "vector", "freeflyer", "spherical"
    iq: int
    iv: int
    nq: int
    nv: int


def _joint_blocks(pm: Any) -> tuple[_Block, ...]:
    out = []
    for jid in range(1, pm.njoints):
        jm = pm.joints[jid]
        short = jm.shortname()
        name = pm.names[jid]
        if short == "JointModelFreeFlyer":
            kind = "freeflyer"
        elif short == "JointModelSpherical":
            kind = "spherical"
        elif jm.nq == jm.nv:
            kind = "vector"
        else:
            raise ModelError(
                f"joint {name!r} of type {short} has nq={jm.nq} != nv={jm.nv}; supported joints "
                "with nq != nv are free-flyer and spherical (use bounded revolute joints instead "
                "of continuous/unbounded ones, and a chain of joints instead of a planar joint)"
            )
        out.append(_Block(name, kind, jm.idx_q, jm.idx_v, jm.nq, jm.nv))
    return tuple(out)


def _coordinate_names(blocks: Sequence[_Block]) -> tuple[str, ...]:
    names: list[str] = []
    for b in blocks:
        if b.kind == "freeflyer":
            names += [f"{b.joint}.{s}" for s in ("x", "y", "z", "qx", "qy", "qz", "qw")]
        elif b.kind == "spherical":
            names += [f"{b.joint}.{s}" for s in ("qx", "qy", "qz", "qw")]
        elif b.nq == 1:
            names.append(b.joint)
        else:
            names += [f"{b.joint}.{i}" for i in range(b.nq)]
    return tuple(names)


def _quat_slice(b: _Block) -> slice:
    start = b.iq + (3 if b.kind == "freeflyer" else 0)
    return slice(start, start + 4)


def _frame_index(pm: Any, name: str, robot: str = "") -> int:
    """Index of the first frame called ``name`` (a URDF link and its joint may share a name)."""
    for i in range(len(pm.frames)):
        if pm.frames[i].name == name:
            return i
    raise UnknownNameError(f"robot {robot or pm.name!r} has no frame {name!r}")


class _Kin:
    """Kinematic quantities of one state, computed in one Pinocchio pass (scratch, per call)."""

    def __init__(
        self, robot: RobotModel, q: FloatArray, qd: FloatArray, *, dynamics: bool, jdot: bool = False
    ) -> None:
        self.robot = robot
        pm = robot._pm
        self.data = pm.createData()
        self.qn = robot.pinocchio_configuration(q)
        self.T, self.Tdot = robot._velocity_map(q, qd)
        self.v = self.T @ qd
        d = self.data
        self.jdot = jdot
        pin.computeJointJacobians(pm, d, self.qn)
        if jdot:
            pin.computeJointJacobiansTimeVariation(pm, d, self.qn, self.v)
        pin.forwardKinematics(pm, d, self.qn, self.v, np.zeros(pm.nv))
        pin.updateFramePlacements(pm, d)
        if dynamics:
            Mv = pin.crba(pm, d, self.qn)
            self.Mv = np.triu(Mv) + np.triu(Mv, 1).T
            self.Cv = np.array(pin.computeCoriolisMatrix(pm, d, self.qn, self.v))
            self.gv = np.array(pin.computeGeneralizedGravity(pm, d, self.qn))
        self._cache: dict[int, tuple[FloatArray, ...]] = {}

    def frame(self, fid: int) -> tuple[FloatArray, ...]:
        """p, R, Jp, Jw, vp, w, ap, al of frame ``fid`` (world-aligned)."""
        if fid not in self._cache:
            pm, d = self.robot._pm, self.data
            oMf = d.oMf[fid]
            J = np.array(pin.getFrameJacobian(pm, d, fid, _LWA))
            vel = pin.getFrameVelocity(pm, d, fid, _LWA)
            acc = pin.getFrameClassicalAcceleration(pm, d, fid, _LWA)
            self._cache[fid] = (
                np.array(oMf.translation),
                np.array(oMf.rotation),
                J[:3],
                J[3:],
                np.array(vel.linear),
                np.array(vel.angular),
                np.array(acc.linear),
                np.array(acc.angular),
            )
        return self._cache[fid]

    def frame_dot(self, fid: int) -> tuple[FloatArray, FloatArray]:
        """Time derivatives of the LOCAL_WORLD_ALIGNED frame Jacobian: J̇p, J̇ω (3, nv) each."""
        Jd = np.array(
            pin.getFrameJacobianTimeVariation(self.robot._pm, self.data, fid, _LWA)
        )
        return Jd[:3], Jd[3:]


# --------------------------------------------------------------------------- the model


@dataclass(frozen=True, eq=False)
class RobotModel(Model):
    """A rigid-body robot (Pinocchio kinematic tree) with named, switchable frame constraints.

    Build it with :meth:`from_urdf`, :meth:`from_pinocchio` or :meth:`from_mjcf`; coordinates
    and dynamics are described in the module docstring (n = nq, ``qd = dq/dt``; quaternions
    kept with a unit-norm constraint).

    Parameters
    ----------
    name : str
    pin_model : pinocchio.Model
        The kinematic tree (copied; never modified).
    robot_constraints : tuple of FrameConstraint or JointCoupling
        User constraints, in row order (after the structural unit-quaternion constraints).
    actuated : tuple of str, optional
        Names of the actuated joints (every velocity component of each gets an actuator).
        Default: every joint except free flyers.
    default_active_names : frozenset of str, optional
        Default active set; default: every non-unilateral constraint.
    damping : tuple of float, optional
        Viscous joint damping per velocity component (nv), ``f_p = −Tᵀ (d ⊙ v)``.
    metadata : dict
        Free information from the source (file path, MuJoCo index maps, ...).
    """

    name: str
    pin_model: Any
    robot_constraints: tuple[RobotConstraint, ...] = ()
    actuated: tuple[str, ...] | None = None
    default_active_names: frozenset[str] | None = None
    damping: tuple[float, ...] | None = None
    metadata: dict[str, Any] = field(default_factory=dict)

    coordinate_names: tuple[str, ...] = field(init=False)
    constraints: tuple[ConstraintSpec, ...] = field(init=False)
    actuator_names: tuple[str, ...] = field(init=False)
    default_active: frozenset[str] = field(init=False)
    _pm: Any = field(init=False, repr=False)
    _blocks: tuple[_Block, ...] = field(init=False, repr=False)
    _fids: dict[str, tuple[int, int]] = field(init=False, repr=False)
    _jq: dict[str, int] = field(init=False, repr=False)
    _act_v: tuple[int, ...] = field(init=False, repr=False)
    _structural: frozenset[str] = field(init=False, repr=False)
    _damp: FloatArray = field(init=False, repr=False)
    _program: Any = field(init=False, repr=False)
    _scratch: Any = field(init=False, repr=False)
    _row_cache: dict[frozenset[str], tuple[Any, Any]] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        s = object.__setattr__
        if not isinstance(self.pin_model, pin.Model):
            raise InputError(f"pin_model must be a pinocchio.Model, got {type(self.pin_model).__name__}")
        pm = self.pin_model.copy()
        blocks = _joint_blocks(pm)
        cons = tuple(self.robot_constraints)
        for c in cons:
            if not isinstance(c, RobotConstraint):
                raise InputError(
                    f"robot_constraints must be FrameConstraint, JointCoupling, JointLimit, JointDriver, "
                    f"PathDriver or DistanceDriver values, got {type(c).__name__}"
                )
        structural = [
            ConstraintSpec(f"{b.joint}.unit_quaternion", "holonomic", 1, "unit-norm quaternion")
            for b in blocks
            if b.kind != "vector"
        ]
        specs = structural + [ConstraintSpec(c.name, c.kind, c.dim, c.description) for c in cons]
        names = [c.name for c in specs]
        if len(set(names)) != len(names):
            raise InputError(f"constraint names must be unique, got {names}")
        frame_names = {pm.frames[i].name for i in range(len(pm.frames))}
        fids: dict[str, tuple[int, int]] = {}
        jq: dict[str, int] = {}
        scalar = {b.joint: b.iq for b in blocks if b.kind == "vector" and b.nq == 1}
        for c in cons:
            if isinstance(c, JointLimit | JointDriver):
                if c.joint not in scalar:
                    raise UnknownNameError(
                        f"constraint {c.name!r}: joint {c.joint!r} is not a scalar joint of the "
                        f"robot; scalar joints: {sorted(scalar)}"
                    )
                jq[c.joint] = scalar[c.joint]
                continue
            if isinstance(c, JointCoupling):
                for jn in (c.joint1, c.joint2):
                    if jn is None:
                        continue
                    if jn not in scalar:
                        raise UnknownNameError(
                            f"constraint {c.name!r}: joint {jn!r} is not a scalar joint of the "
                            f"robot; scalar joints: {sorted(scalar)}"
                        )
                    jq[jn] = scalar[jn]
                continue
            ids = []
            for side, fname, H in (("a", c.frame_a, c.placement_a), ("b", c.frame_b, c.placement_b)):
                if fname not in frame_names:
                    raise UnknownNameError(
                        f"constraint {c.name!r}: frame_{side} {fname!r} is not a frame of the "
                        f"robot; known: {sorted(frame_names)}"
                    )
                parent = pm.frames[_frame_index(pm, fname)]
                placement = parent.placement * _se3(H)
                new = pin.Frame(
                    f"{c.name}:{side}", parent.parentJoint, placement, pin.FrameType.OP_FRAME
                )
                ids.append(pm.addFrame(new, False))
            fids[c.name] = (ids[0], ids[1])
        joint_names = [b.joint for b in blocks]
        if self.actuated is None:
            act = tuple(b.joint for b in blocks if b.kind != "freeflyer")
        else:
            act = tuple(self.actuated)
            unknown = [j for j in act if j not in joint_names]
            if unknown:
                raise UnknownNameError(f"actuated: unknown joint(s) {unknown}; known: {joint_names}")
        act_v: list[int] = []
        act_names: list[str] = []
        for b in blocks:
            if b.joint in act:
                act_v += list(range(b.iv, b.iv + b.nv))
                act_names += [b.joint] if b.nv == 1 else [f"{b.joint}.{i}" for i in range(b.nv)]
        damp = np.zeros(pm.nv)
        if self.damping is not None:
            damp = np.array(as_float_array(self.damping, "damping"))
            if damp.shape != (pm.nv,):
                raise ShapeError(f"damping must have shape ({pm.nv},), got shape {damp.shape}")
            if not (np.isfinite(damp).all() and (damp >= 0.0).all()):
                raise ModelError(f"damping must be finite and ≥ 0 (viscous, one value per velocity "
                                 f"component), got {damp.tolist()}")  # fmt: skip
        struct = frozenset(c.name for c in structural)
        if self.default_active_names is None:
            dflt = frozenset(c.name for c in specs if c.kind != "unilateral")
        else:
            dflt = frozenset(self.default_active_names) | struct
        s(self, "coordinate_names", _coordinate_names(blocks))
        s(self, "constraints", tuple(specs))
        s(self, "actuator_names", tuple(act_names))
        s(self, "_pm", pm)
        s(self, "_blocks", blocks)
        s(self, "_fids", fids)
        s(self, "_jq", jq)
        s(self, "_act_v", tuple(act_v))
        s(self, "_structural", struct)
        s(self, "_damp", damp)
        quats = [(c.name, _quat_slice(b).start) for c, b in
                 zip(structural, [b for b in blocks if b.kind != "vector"])]
        prog = compile_tree(pm, quats, cons, fids, jq, act_v, damp)
        s(self, "_program", prog)
        # the engine's scratch of the Python-side evaluations (used under the GIL)
        s(self, "_scratch", None if prog is None else (prog.make_terms(), prog.make_workspace()))
        s(self, "_row_cache", {})
        s(self, "default_active", frozenset())
        s(self, "default_active", self.resolve_active(dflt))

    # ------------------------------------------------------------------ constructors
    @classmethod
    def from_pinocchio(
        cls,
        pin_model: Any,
        *,
        constraints: Iterable[RobotConstraint] = (),
        gravity: ArrayLike | None = None,
        actuated: Iterable[str] | None = None,
        default_active: Iterable[str] | None = None,
        damping: ArrayLike | None = None,
        name: str | None = None,
        metadata: dict[str, Any] | None = None,
        joint_limits: bool | str = True,
    ) -> RobotModel:
        """A robot from an existing :class:`pinocchio.Model`.

        Parameters
        ----------
        pin_model : pinocchio.Model
        constraints : iterable of FrameConstraint or JointCoupling
        gravity : array_like, shape (3,), optional
            World gravity vector; default: the model's (Pinocchio: ``(0, 0, −9.81)``).
        actuated : iterable of str, optional
            Actuated joint names; default every joint but free flyers.
        default_active : iterable of str, optional
            Default active constraint names; default every non-unilateral constraint.
        damping : array_like, shape (nv,), optional
            Viscous damping per velocity component.
        name : str, optional
        metadata : dict, optional
        joint_limits : bool or {"warn", "ignore"}, default True
            True: every finite position limit of a 1-dof joint (``lowerPositionLimit``,
            ``upperPositionLimit``; magnitudes ≥ 1e300 are "no limit") becomes a unilateral
            :class:`JointLimit` constraint, ``"<joint>.lower"`` (gap ``q − lower``) and
            ``"<joint>.upper"`` (gap ``upper − q``), inactive until ``simulate``'s automatic
            contact closes it with an impact (restitution from ``restitution={name: e}``).
            False (or ``"warn"``): not enforced, a :class:`~nonmin.errors.JointLimitWarning`
            names the limited joints. ``"ignore"``: not enforced, no warning.
        """
        if not isinstance(pin_model, pin.Model):
            raise InputError(f"pin_model must be a pinocchio.Model, got {type(pin_model).__name__}")
        enforce = _joint_limits_option(joint_limits)
        pm = pin_model.copy()
        limits = scalar_joint_limits(pm)
        if enforce is True:
            constraints = (*tuple(constraints), *joint_limit_constraints(limits))
        elif enforce is False and limits:
            warnings.warn(_limits_text(limits, f"robot {name or pm.name or 'robot'!r}"),
                          JointLimitWarning, stacklevel=2)
        if gravity is not None:
            g = np.asarray(gravity, dtype=float)
            if g.shape != (3,) or not np.isfinite(g).all():
                raise ShapeError(f"gravity must be a finite vector of shape (3,), got {g!r}")
            pm.gravity = pin.Motion(g, np.zeros(3))
        return cls(
            name=name or pm.name or "robot",
            pin_model=pm,
            robot_constraints=tuple(constraints),
            actuated=None if actuated is None else tuple(actuated),
            default_active_names=None if default_active is None else frozenset(default_active),
            damping=None if damping is None else tuple(np.asarray(damping, float).ravel()),
            metadata=dict(metadata or {}),
        )

    @classmethod
    def from_urdf(
        cls,
        path: str | Path,
        *,
        root_joint: str | None = None,
        constraints: Iterable[RobotConstraint] = (),
        gravity: ArrayLike | None = None,
        actuated: Iterable[str] | None = None,
        default_active: Iterable[str] | None = None,
        damping: ArrayLike | None = None,
        name: str | None = None,
        joint_limits: bool | str = True,
    ) -> RobotModel:
        """A robot from a URDF file (checked by nonmin, then parsed by Pinocchio).

        Parameters
        ----------
        path : str or Path
        root_joint : {None, "freeflyer"}
            ``"freeflyer"`` adds a floating base (7 coordinates: position, quaternion).
        constraints, gravity, actuated, default_active, damping, name
            As in :meth:`from_pinocchio`.
        joint_limits : bool or {"warn", "ignore"}, default True
            True: the file's joint position limits become unilateral constraints
            ``"<joint>.lower"`` / ``"<joint>.upper"`` (see :meth:`from_pinocchio`). False (or
            ``"warn"``): not enforced, a :class:`~nonmin.errors.JointLimitWarning` names them;
            ``"ignore"``: not enforced, silently.

        Raises
        ------
        FileFormatError
            Missing, unreadable or malformed file (names the file and element).
        ModelError
            Non-physical masses or inertias, a joint to an unknown link, a kinematic cycle or a
            link with two parents, inverted limits (names the file and element).
        """
        from ._urdf_check import check_urdf, joint_limit_text

        p = _robot_file(path, "URDF")
        if root_joint not in (None, "freeflyer"):
            raise InputError(f"root_joint must be None or 'freeflyer', got {root_joint!r}")
        enforce = _joint_limits_option(joint_limits)
        limits = check_urdf(p)
        try:
            if root_joint is None:
                pm = pin.buildModelFromUrdf(str(p))
            else:
                pm = pin.buildModelFromUrdf(str(p), pin.JointModelFreeFlyer())
        except Exception as exc:  # Pinocchio's parser raises ValueError/RuntimeError/...
            raise FileFormatError(
                f"path: Pinocchio could not build a model from {str(p)!r}: {type(exc).__name__}: {exc}"
            ) from exc
        if limits and enforce is False:
            warnings.warn(joint_limit_text(limits, p), JointLimitWarning, stacklevel=2)
        return cls.from_pinocchio(
            pm,
            constraints=constraints,
            gravity=gravity,
            actuated=actuated,
            default_active=default_active,
            damping=damping,
            name=name or pm.name,
            metadata={"source": str(p)},
            joint_limits=True if enforce is True else "ignore",
        )

    @classmethod
    def from_mjcf(
        cls,
        path: str | Path,
        *,
        constraints: Iterable[RobotConstraint] = (),
        gravity: ArrayLike | None = None,
        actuated: Iterable[str] | None = None,
        default_active: Iterable[str] | None = None,
        name: str | None = None,
        joint_limits: bool | str = True,
    ) -> RobotModel:
        """A robot from an MJCF file, parsed by MuJoCo (extra ``mujoco``).

        Bodies, joints, inertias, armature, damping and gravity come from MuJoCo's compiled
        model; every ``<equality>`` connect/weld/joint becomes a nonmin constraint (named as
        in the file, or ``eq<i>``), active by default when active in the file. Joint
        ``range`` limits of hinge and slide joints are handled as in :meth:`from_urdf`
        (``joint_limits``). See :func:`nonmin.model.robots._mujoco.load_mjcf`.
        """
        from ._mujoco import load_mjcf

        return load_mjcf(
            cls,
            path,
            constraints=tuple(constraints),
            gravity=gravity,
            actuated=actuated,
            default_active=default_active,
            name=name,
            joint_limits=joint_limits,
        )

    # ------------------------------------------------------------------ protocol plumbing
    def __reduce__(self) -> tuple[Any, ...]:
        """Pickle (and deep-copy) by the init fields: the engine program is built again."""
        init = {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.init}
        return (_rebuild, (type(self), init))

    def replace(self, **changes: Any) -> RobotModel:
        """A copy with some init fields replaced (e.g. ``robot_constraints``, ``actuated``)."""
        init = {f.name for f in dataclasses.fields(self) if f.init}
        unknown = set(changes) - init
        if unknown:
            raise InputError(f"replace(): unknown field(s) {sorted(unknown)}; known: {sorted(init)}")
        return dataclasses.replace(self, **changes)

    def resolve_active(self, active: Iterable[str] | str | None) -> frozenset[str]:
        """Validated active set, always including the structural unit-quaternion constraints."""
        return super().resolve_active(active) | self._structural

    @property
    def nv(self) -> int:
        """Number of Pinocchio velocity components."""
        return int(self._pm.nv)

    @property
    def structural_constraints(self) -> frozenset[str]:
        """Names of the always-active unit-quaternion constraints."""
        return self._structural

    @property
    def pinocchio_model(self) -> Any:
        """A copy of the internal Pinocchio model (with the constraint frames added)."""
        return self._pm.copy()

    def frame_id(self, name: str) -> int:
        """Index of a frame of the internal Pinocchio model (constraint frames: ``c:a``, ``c:b``)."""
        return _frame_index(self._pm, name, robot=self.name)

    def _q(self, q: ArrayLike, name: str = "q") -> FloatArray:
        arr = np.asarray(q, dtype=float)
        if arr.shape != (self.n,):
            raise ShapeError(f"{name} must have shape ({self.n},), got shape {arr.shape}")
        return arr

    def neutral_configuration(self) -> FloatArray:
        """Pinocchio's neutral configuration (identity quaternions), shape (n,)."""
        return np.array(pin.neutral(self._pm))

    def random_configuration(self, rng: np.random.Generator | int | None = None) -> FloatArray:
        """A random configuration within joint limits (unit quaternions), shape (n,)."""
        gen = np.random.default_rng(rng)
        q = self.neutral_configuration()
        lo, hi = np.array(self._pm.lowerPositionLimit), np.array(self._pm.upperPositionLimit)
        for b in self._blocks:
            sl = slice(b.iq, b.iq + b.nq)
            if b.kind == "vector":
                lo_b = np.where(np.isfinite(lo[sl]), lo[sl], -np.pi)
                hi_b = np.where(np.isfinite(hi[sl]), hi[sl], np.pi)
                lo_b, hi_b = np.maximum(lo_b, -1e3), np.minimum(hi_b, 1e3)
                q[sl] = gen.uniform(lo_b, hi_b)
            else:
                if b.kind == "freeflyer":
                    q[b.iq : b.iq + 3] = gen.uniform(-1.0, 1.0, 3)
                e = gen.normal(size=4)
                q[_quat_slice(b)] = e / np.linalg.norm(e)
        return q

    def pinocchio_configuration(self, q: ArrayLike) -> FloatArray:
        """q with every quaternion normalized (what Pinocchio is evaluated at), shape (n,)."""
        qn = self._q(q).copy()
        for b in self._blocks:
            if b.kind != "vector":
                sl = _quat_slice(b)
                nrm = float(np.linalg.norm(qn[sl]))
                if nrm == 0.0 or not np.isfinite(nrm):
                    raise InputError(f"q: quaternion of joint {b.joint!r} must be non-zero")
                qn[sl] /= nrm
        return qn

    def _velocity_map(self, q: FloatArray, qd: FloatArray | None) -> tuple[FloatArray, FloatArray]:
        nv, n = self._pm.nv, self.n
        T = np.zeros((nv, n))
        Td = np.zeros((nv, n))
        for b in self._blocks:
            if b.kind == "vector":
                T[b.iv : b.iv + b.nv, b.iq : b.iq + b.nq] = np.eye(b.nv)
                continue
            qs = _quat_slice(b)
            eps = q[qs]
            s2 = float(eps @ eps)
            G = _quat_G(eps)
            ivw = b.iv + (3 if b.kind == "freeflyer" else 0)
            T[ivw : ivw + 3, qs] = 2.0 * G / s2
            if qd is not None:
                ed = qd[qs]
                Td[ivw : ivw + 3, qs] = 2.0 * _quat_G(ed) / s2 - 4.0 * float(eps @ ed) / s2**2 * G
            if b.kind == "freeflyer":
                R = _quat_rot(eps)
                T[b.iv : b.iv + 3, b.iq : b.iq + 3] = R.T
                if qd is not None:
                    w = 2.0 * G @ qd[qs] / s2
                    Td[b.iv : b.iv + 3, b.iq : b.iq + 3] = -_skew(w) @ R.T
        return T, Td

    def velocity_map(self, q: ArrayLike) -> FloatArray:
        """``T(q)`` with Pinocchio's velocity ``v = T qd``, shape (nv, n)."""
        return self._velocity_map(self._q(q), None)[0]

    def to_pinocchio_velocity(self, q: ArrayLike, qd: ArrayLike) -> FloatArray:
        """Pinocchio's ``v = T(q) qd``, shape (nv,)."""
        return self.velocity_map(q) @ self._q(qd, "qd")

    def from_pinocchio_velocity(self, q: ArrayLike, v: ArrayLike) -> FloatArray:
        """``qd = dq/dt`` for Pinocchio's velocity v (tangent to the unit quaternions), shape (n,)."""
        vv = np.asarray(v, dtype=float)
        if vv.shape != (self.nv,):
            raise ShapeError(f"v must have shape ({self.nv},), got shape {vv.shape}")
        qn = self.pinocchio_configuration(q)
        return np.array(pin.tangentMap(self._pm, qn)) @ vv

    def to_pinocchio_acceleration(self, q: ArrayLike, qd: ArrayLike, qdd: ArrayLike) -> FloatArray:
        """Pinocchio's ``a = dv/dt = T qdd + Ṫ qd``, shape (nv,)."""
        qv, v = self._q(q), self._q(qd, "qd")
        T, Td = self._velocity_map(qv, v)
        return T @ self._q(qdd, "qdd") + Td @ v

    def from_mujoco_qpos(self, qpos: ArrayLike) -> FloatArray:
        """nonmin coordinates from a MuJoCo ``qpos`` (quaternions ``w,x,y,z`` → ``x,y,z,w``)."""
        q = self._q(qpos, "qpos").copy()
        for b in self._blocks:
            if b.kind != "vector":
                sl = _quat_slice(b)
                q[sl] = np.roll(q[sl], -1)
        return q

    def to_mujoco_qpos(self, q: ArrayLike) -> FloatArray:
        """MuJoCo ``qpos`` from nonmin coordinates (quaternions ``x,y,z,w`` → ``w,x,y,z``)."""
        qpos = self._q(q).copy()
        for b in self._blocks:
            if b.kind != "vector":
                sl = _quat_slice(b)
                qpos[sl] = np.roll(qpos[sl], 1)
        return qpos

    # ------------------------------------------------------------------ the compiled engine
    def engine_program(self) -> Any | None:
        """The compiled engine's ``TreeProgram`` of this robot (``nonmin._engine.Program``).

        Built once with the model (:mod:`nonmin.model.robots._tree`); it evaluates M, h, f_p,
        B, the constraint rows and the energy (``engine/include/nonmin/rbd``) for a mask of
        the active constraints (one entry per constraint of :attr:`constraints`; the
        structural unit-quaternion rows must be active). None when the tree has a joint type
        the engine does not evaluate; the model then evaluates through Pinocchio.
        """
        return self._program

    def _active_rows(self, act: frozenset[str]) -> tuple[Any, Any]:
        """Engine mask of the active constraints and their rows (None: every row)."""
        hit = self._row_cache.get(act)
        if hit is None:
            mask = np.array([c.name in act for c in self.constraints], dtype=np.uint8)
            rows = [np.arange(r, r + d) for (_, _, r, d), on in
                    zip(self._program.constraints, mask) if on]
            idx = np.concatenate(rows) if rows else np.zeros(0, dtype=np.intp)
            hit = (mask, None if idx.size == self._program.m_all else idx)
            self._row_cache[act] = hit
        return hit

    def _engine(
        self, t: float, q: ArrayLike, qd: ArrayLike | None, act: frozenset[str], need: int
    ) -> tuple[Any, ...]:
        """One engine evaluation: (M, h, f_p, B, A, γ, φ, A qd, kinetic, potential).

        Entries not asked for by ``need`` (``_engine.NEED_*`` bits) are None; constraint
        arrays hold the active rows only.
        """
        prog = self._program
        n, m = self.n, prog.m_all
        qv = np.ascontiguousarray(self._q(q))
        v = np.zeros(n) if qd is None else np.ascontiguousarray(self._q(qd, "qd"))
        mask, rows = self._active_rows(act)
        M = np.empty((n, n)) if need & _NEED_M else _NONE
        h = np.empty(n) if need & _NEED_H else _NONE
        fp = np.empty(n) if need & _NEED_H else _NONE
        B = np.empty((n, prog.k)) if need & _NEED_B else _NONE
        A = np.empty((m, n)) if need & _NEED_A else _NONE
        g = np.empty(m) if need & _NEED_GAMMA else _NONE
        p = np.empty(m) if need & _NEED_PHI else _NONE
        vel = np.empty(m) if need & _NEED_VELOCITY else _NONE
        terms, ws = self._scratch
        status, kin, pot = prog.evaluate_arrays(
            terms, ws, float(t), qv, v, mask, need, M, h, fp, B, A, g, p, vel
        )
        if status:
            self.pinocchio_configuration(qv)  # names the joint of a zero quaternion
            raise NonFiniteError(f"q and qd must be finite (robot {self.name!r})")
        if rows is not None:
            A = A[rows] if need & _NEED_A else A
            g = g[rows] if need & _NEED_GAMMA else g
            p = p[rows] if need & _NEED_PHI else p
            vel = vel[rows] if need & _NEED_VELOCITY else vel
        return (
            M if need & _NEED_M else None,
            h if need & _NEED_H else None,
            fp if need & _NEED_H else None,
            B if need & _NEED_B else None,
            A if need & _NEED_A else None,
            g if need & _NEED_GAMMA else None,
            p if need & _NEED_PHI else None,
            vel if need & _NEED_VELOCITY else None,
            kin,
            pot,
        )

    # ------------------------------------------------------------------ dynamics
    def mass_matrix(self, q: ArrayLike) -> FloatArray:
        """``M = Tᵀ M_v T`` (CRBA incl. armature, symmetrized), shape (n, n)."""
        if self._program is None:
            k = _Kin(self, self._q(q), np.zeros(self.n), dynamics=True)
            return k.T.T @ k.Mv @ k.T
        M: FloatArray = self._engine(0.0, q, None, self._structural, _NEED_M)[0]
        return M

    def coriolis_matrix(self, q: ArrayLike, qd: ArrayLike) -> FloatArray:
        """``C = Tᵀ C_v T + Tᵀ M_v Ṫ`` with the Christoffel-consistent ``C_v``, shape (n, n).

        Not needed by the dynamics (which use ``h``); for controllers (the tracking law). The
        engine computes ``C_v = Σ_i J_iᵀ (I_i J̇_i + B_i J_i)`` over composite subtrees (equal
        to Pinocchio's ``computeCoriolisMatrix``).
        """
        if self._program is None:
            return self._coriolis_matrix_pinocchio(q, qd)
        qv = np.ascontiguousarray(self._q(q))
        v = np.ascontiguousarray(self._q(qd, "qd"))
        try:
            C: FloatArray = self._program.coriolis_matrix(qv, v)
        except NonFiniteError:
            self.pinocchio_configuration(qv)  # names the joint of a zero quaternion
            raise
        return C

    def _coriolis_matrix_pinocchio(self, q: ArrayLike, qd: ArrayLike) -> FloatArray:
        """:meth:`coriolis_matrix` from Pinocchio's ``computeCoriolisMatrix`` (oracle)."""
        k = _Kin(self, self._q(q), self._q(qd, "qd"), dynamics=True)
        return k.T.T @ k.Cv @ k.T + k.T.T @ k.Mv @ k.Tdot

    def conservative_force(self, q: ArrayLike) -> FloatArray:
        """Gravity ``f_g = −Tᵀ g_v`` (RNEA at zero velocity), shape (n,)."""
        if self._program is None:
            k = _Kin(self, self._q(q), np.zeros(self.n), dynamics=True)
            return -k.T.T @ k.gv
        h: FloatArray = self._engine(0.0, q, None, self._structural, _NEED_H)[1]
        return h

    def potential_energy(self, q: ArrayLike) -> float:
        """Gravitational potential energy ``−Σ m_i gᵀ c_i`` (Pinocchio's convention)."""
        if self._program is None:
            qn = self.pinocchio_configuration(q)
            return float(pin.computePotentialEnergy(self._pm, self._pm.createData(), qn))
        return float(self._engine(0.0, q, None, self._structural, _NEED_ENERGY)[9])

    def kinetic_energy(self, q: ArrayLike, qd: ArrayLike) -> float:
        """``T = ½ qdᵀ M qd``."""
        if self._program is None:
            return super().kinetic_energy(q, qd)
        return float(self._engine(0.0, q, qd, self._structural, _NEED_ENERGY)[8])

    def energy(self, q: ArrayLike, qd: ArrayLike) -> float:
        """Total mechanical energy ``T + V``."""
        if self._program is None:
            return super().energy(q, qd)
        out = self._engine(0.0, q, qd, self._structural, _NEED_ENERGY)
        return float(out[8] + out[9])

    def passive_force(self, t: float, q: ArrayLike, qd: ArrayLike) -> FloatArray:
        """Joint damping ``−Tᵀ (d ⊙ T qd)``, shape (n,)."""
        if not self._damp.any():
            return np.zeros(self.n)
        T = self.velocity_map(q)
        return -T.T @ (self._damp * (T @ self._q(qd, "qd")))

    def input_matrix(self, q: ArrayLike) -> FloatArray:
        """``B = Tᵀ S`` (S selects the actuated velocity components), shape (n, k)."""
        T = self.velocity_map(q)
        return T[list(self._act_v), :].T.copy()

    # ------------------------------------------------------------------ constraints
    def _constraint_rows(
        self, kin: _Kin, q: FloatArray, qd: FloatArray, act: frozenset[str], t: float = 0.0
    ) -> tuple[ConstraintTerms, FloatArray | None]:
        """Stacked constraint terms and, when ``kin`` has Jacobian derivatives, the matrix Ȧ."""
        n = self.n
        phit: list[float] = []
        As: list[FloatArray] = []
        gs: list[FloatArray] = []
        ps: list[FloatArray] = []
        Ads: list[FloatArray] = []
        for b in self._blocks:
            nm = f"{b.joint}.unit_quaternion"
            if b.kind == "vector" or nm not in act:
                continue
            sl = _quat_slice(b)
            row = np.zeros((1, n))
            row[0, sl] = q[sl]
            As.append(row)
            phit.append(0.0)
            gs.append(np.array([qd[sl] @ qd[sl]]))
            ps.append(np.array([0.5 * (q[sl] @ q[sl] - 1.0)]))
            rowd = np.zeros((1, n))
            rowd[0, sl] = qd[sl]
            Ads.append(rowd)
        for c in self.robot_constraints:
            if c.name not in act:
                continue
            Ad: FloatArray | None
            pt = [0.0] * c.dim
            if isinstance(c, JointLimit):
                A, g, p, Ad = self._limit_rows(c, q)
            elif isinstance(c, JointDriver):
                A = np.zeros((1, n))
                i = self._jq[c.joint]
                A[0, i] = 1.0
                f, fd, fdd = (float(x) for x in c.motion(float(t)))
                g, p, Ad, pt = np.array([-fdd]), np.array([q[i] - f]), np.zeros((1, n)), [-fd]
            elif isinstance(c, JointCoupling):
                A, g, p, Ad = self._coupling_rows(c, q, qd)
            elif isinstance(c, PathDriver | DistanceDriver):
                Av, gv, p, Adv, pt = self._driver_rows(c, kin, qd, float(t))
                A = Av @ kin.T
                g = gv + Av @ (kin.Tdot @ qd)
                Ad = None if Adv is None else Adv @ kin.T + Av @ kin.Tdot
            else:
                Av, gv, p, Adv = self._frame_rows(c, kin)
                A = Av @ kin.T
                g = gv + Av @ (kin.Tdot @ qd)
                Ad = None if Adv is None else Adv @ kin.T + Av @ kin.Tdot
            As.append(A)
            gs.append(g)
            ps.append(p)
            phit += pt
            if Ad is not None:
                Ads.append(Ad)
        if not As:
            empty = ConstraintTerms(
                np.zeros((0, n)), np.zeros(0), np.zeros(0), np.zeros(0), np.zeros(0, dtype=bool)
            )
            return empty, np.zeros((0, n))
        A = np.vstack(As)
        terms = ConstraintTerms(
            A, np.concatenate(gs), np.concatenate(ps), A @ qd + np.array(phit), np.ones(A.shape[0], dtype=bool)
        )
        return terms, (np.vstack(Ads) if kin.jdot else None)

    def _limit_rows(
        self, c: JointLimit, q: FloatArray
    ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """Gap ``s (q_i − bound)``, ``A = s eᵢᵀ``, ``γ = 0``, ``Ȧ = 0`` of a joint limit."""
        A = np.zeros((1, self.n))
        i = self._jq[c.joint]
        A[0, i] = c.sign
        return A, np.zeros(1), np.array([c.sign * (q[i] - c.bound)]), np.zeros((1, self.n))

    def _coupling_rows(
        self, c: JointCoupling, q: FloatArray, qd: FloatArray
    ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        A = np.zeros((1, self.n))
        Ad = np.zeros((1, self.n))
        i1 = self._jq[c.joint1]
        A[0, i1] = 1.0
        phi = q[i1] - c.reference1 - c.polycoef[0]
        gamma = 0.0
        if c.joint2 is not None:
            i2 = self._jq[c.joint2]
            x = q[i2] - c.reference2
            a = c.polycoef
            poly = a[1] * x + a[2] * x**2 + a[3] * x**3 + a[4] * x**4
            d1 = a[1] + 2 * a[2] * x + 3 * a[3] * x**2 + 4 * a[4] * x**3
            d2 = 2 * a[2] + 6 * a[3] * x + 12 * a[4] * x**2
            phi -= poly
            A[0, i2] -= d1
            Ad[0, i2] = -d2 * qd[i2]
            gamma = -d2 * qd[i2] ** 2
        return A, np.array([gamma]), np.array([phi]), Ad

    def _driver_rows(
        self, c: PathDriver | DistanceDriver, kin: _Kin, qd: FloatArray, t: float
    ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray | None, list[float]]:
        """Rows of a path or distance driver in velocity space: A_v, γ_v, φ, Ȧ_v, φ_t."""
        fa, fb = self._fids[c.name]
        pa, _, Jpa, _, vpa, _, apa, _ = kin.frame(fa)
        pb, _, Jpb, _, vpb, _, apb, _ = kin.frame(fb)
        jd = kin.jdot
        Jdpa, _ = kin.frame_dot(fa) if jd else (Jpa, None)
        Jdpb, _ = kin.frame_dot(fb) if jd else (Jpb, None)
        if isinstance(c, PathDriver):
            f = np.array([[float(x) for x in m(t)] for m in c.motions])  # (dim, 3)
            ax = list(c.axes)
            return (
                (Jpb - Jpa)[ax],
                (apb - apa)[ax] - f[:, 2],
                (pb - pa)[ax] - f[:, 0],
                (Jdpb - Jdpa)[ax] if jd else None,
                list(-f[:, 1]),
            )
        L = c.reference
        d, dd = pb - pa, vpb - vpa
        f0, f1, f2 = (float(x) for x in c.motion(t))
        return (
            (d @ (Jpb - Jpa))[None, :] / L,
            np.array([(dd @ dd + d @ (apb - apa) - f1 * f1 - f0 * f2) / L]),
            np.array([(d @ d - f0 * f0) / (2.0 * L)]),
            ((dd @ (Jpb - Jpa) + d @ (Jdpb - Jdpa)) / L)[None, :] if jd else None,
            [-f0 * f1 / L],
        )

    def _frame_rows(
        self, c: FrameConstraint, kin: _Kin
    ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray | None]:
        """Rows in Pinocchio velocity space: A_v (d, nv), γ_v = J̇ v terms (d,), φ (d,), Ȧ_v.

        ``Ȧ_v`` (the time derivative of A_v, from Pinocchio's LOCAL_WORLD_ALIGNED
        ``getFrameJacobianTimeVariation``) is None unless ``kin`` computed Jacobian derivatives.
        """
        fa, fb = self._fids[c.name]
        pa, Ra, Jpa, Jwa, vpa, wa, apa, ala = kin.frame(fa)
        pb, Rb, Jpb, Jwb, vpb, wb, apb, alb = kin.frame(fb)
        jd = kin.jdot
        Jdpa, Jdwa = kin.frame_dot(fa) if jd else (Jpa, Jwa)
        Jdpb, Jdwb = kin.frame_dot(fb) if jd else (Jpb, Jwb)
        t = c.type
        if t in ("point", "weld", "hinge"):
            A_pos, g_pos, p_pos, Ad_pos = Jpa - Jpb, apa - apb, pa - pb, Jdpa - Jdpb
            if t == "point":
                return A_pos, g_pos, p_pos, Ad_pos if jd else None
            if t == "weld":
                A_rot = Jwa - Jwb
                g_rot = ala - alb
                p_rot = np.array(pin.log3(Ra @ Rb.T))
                return (
                    np.vstack([A_pos, A_rot]),
                    np.concatenate([g_pos, g_rot]),
                    np.concatenate([p_pos, p_rot]),
                    np.vstack([Ad_pos, Jdwa - Jdwb]) if jd else None,
                )
            # hinge: φ_i = (R_a u_i)·(R_b k)
            u1, u2 = complete_basis(c.axis)
            Kb = Rb @ c.axis
            rows, gam, phi, drows = [], [], [], []
            dw, dal = wa - wb, ala - alb
            for u in (u1, u2):
                U = Ra @ u
                r = np.cross(U, Kb)
                rdot = np.cross(np.cross(wa, U), Kb) + np.cross(U, np.cross(wb, Kb))
                rows.append(r @ (Jwa - Jwb))
                gam.append(rdot @ dw + r @ dal)
                phi.append(U @ Kb)
                drows.append(rdot @ (Jwa - Jwb) + r @ (Jdwa - Jdwb))
            return (
                np.vstack([A_pos, np.array(rows)]),
                np.concatenate([g_pos, gam]),
                np.concatenate([p_pos, phi]),
                np.vstack([Ad_pos, np.array(drows)]) if jd else None,
            )
        if t in ("planar_point", "planar_weld"):
            e1, e2 = complete_basis(c.axis)
            E = np.vstack([e1, e2])
            A_pos, g_pos, p_pos = E @ (Jpa - Jpb), E @ (apa - apb), E @ (pa - pb)
            Ad_pos = E @ (Jdpa - Jdpb)
            if t == "planar_point":
                return A_pos, g_pos, p_pos, Ad_pos if jd else None
            nrm = c.axis
            A_rot = nrm @ (Jwa - Jwb)
            g_rot = nrm @ (ala - alb)
            p_rot = nrm @ np.array(pin.log3(Ra @ Rb.T))
            return (
                np.vstack([A_pos, A_rot[None, :]]),
                np.concatenate([g_pos, [g_rot]]),
                np.concatenate([p_pos, [p_rot]]),
                np.vstack([Ad_pos, (nrm @ (Jdwa - Jdwb))[None, :]]) if jd else None,
            )
        # point_on_plane / contact: φ = N·(p_b − p_a), N = R_a k
        N = Ra @ c.axis
        dvec = pb - pa
        dv = vpb - vpa
        Nd = np.cross(wa, N)
        A_row = np.cross(N, dvec) @ Jwa + N @ (Jpb - Jpa)
        gamma = (
            ala @ np.cross(N, dvec)
            + wa @ (np.cross(Nd, dvec) + np.cross(N, dv))
            + Nd @ dv
            + N @ (apb - apa)
        )
        Ad_row = (
            (np.cross(Nd, dvec) + np.cross(N, dv)) @ Jwa
            + np.cross(N, dvec) @ Jdwa
            + Nd @ (Jpb - Jpa)
            + N @ (Jdpb - Jdpa)
        )
        return (
            A_row[None, :],
            np.array([gamma]),
            np.array([N @ dvec]),
            Ad_row[None, :] if jd else None,
        )

    def constraint_terms(
        self,
        t: float,
        q: ArrayLike,
        qd: ArrayLike,
        active: Iterable[str] | None = None,
    ) -> ConstraintTerms:
        """Stacked ``A``, ``γ`` (``A qdd + γ = 0``), φ and ``A qd`` of the active constraints.

        Rows follow :attr:`constraints` (structural unit-quaternion rows first).
        """
        act = self.resolve_active(active)
        if self._program is None:
            return self._constraint_terms_pinocchio(t, q, qd, act)
        out = self._engine(t, q, qd, act, _NEED_CONSTRAINTS)
        return ConstraintTerms(out[4], out[5], out[6], out[7], np.ones(out[4].shape[0], dtype=bool))

    def _constraint_terms_pinocchio(
        self, t: float, q: ArrayLike, qd: ArrayLike, act: frozenset[str]
    ) -> ConstraintTerms:
        """:meth:`constraint_terms` from Pinocchio's frame kinematics (fallback and oracle)."""
        qv, v = self._q(q), self._q(qd, "qd")
        kin = _Kin(self, qv, v, dynamics=False)
        return self._constraint_rows(kin, qv, v, act, t)[0]

    def constraint_jacobian_dot(
        self, t: float, q: ArrayLike, qd: ArrayLike, active: Iterable[str] | None = None
    ) -> FloatArray:
        """Exact ``Ȧ = dA/dt`` along ``qd``, shape (m, n).

        ``Ȧ = Ȧ_v T + A_v Ṫ`` with the frame Jacobians' time derivatives (``J̇_k = ν_j × J_k``
        in world axes; equal to Pinocchio's ``getFrameJacobianTimeVariation``); satisfies
        ``Ȧ qd = γ``.
        """
        act = self.resolve_active(active)
        if self._program is None:
            return self._constraint_jacobian_dot_pinocchio(t, q, qd, act)
        qv = np.ascontiguousarray(self._q(q))
        v = np.ascontiguousarray(self._q(qd, "qd"))
        mask, rows = self._active_rows(act)
        try:
            Ad: FloatArray = self._program.jacobian_dot(qv, v, mask)
        except NonFiniteError:
            self.pinocchio_configuration(qv)  # names the joint of a zero quaternion
            raise
        return Ad if rows is None else Ad[rows]

    def _constraint_jacobian_dot_pinocchio(
        self, t: float, q: ArrayLike, qd: ArrayLike, act: frozenset[str]
    ) -> FloatArray:
        """:meth:`constraint_jacobian_dot` from Pinocchio's Jacobian time variations (oracle)."""
        qv, v = self._q(q), self._q(qd, "qd")
        kin = _Kin(self, qv, v, dynamics=False, jdot=True)
        Ad = self._constraint_rows(kin, qv, v, act, t)[1]
        assert Ad is not None
        return Ad

    def evaluate(
        self,
        t: float,
        q: ArrayLike,
        qd: ArrayLike,
        active: Iterable[str] | None = None,
    ) -> ModelTerms:
        """All terms in one engine call: M, h = f_g − C qd, f_p, B and the constraints.

        The compiled engine's ``TreeProgram`` (:meth:`engine_program`) evaluates them from the
        tree description extracted at load time; Pinocchio is not called.
        """
        act = self.resolve_active(active)
        if self._program is None:
            return self._evaluate_pinocchio(t, q, qd, act)
        M, h, fp, B, A, g, p, vel, _, _ = self._engine(t, q, qd, act, _NEED_EVALUATE)
        cons = ConstraintTerms(A, g, p, vel, np.ones(A.shape[0], dtype=bool))
        return ModelTerms(M=M, h=h, f_passive=fp, B=B, constraints=cons)

    def _evaluate_pinocchio(
        self, t: float, q: ArrayLike, qd: ArrayLike, act: frozenset[str]
    ) -> ModelTerms:
        """:meth:`evaluate` through Pinocchio's algorithms (fallback and test oracle)."""
        qv, v = self._q(q), self._q(qd, "qd")
        kin = _Kin(self, qv, v, dynamics=True)
        T = kin.T
        M = T.T @ kin.Mv @ T
        Cqd = T.T @ (kin.Cv @ kin.v + kin.Mv @ (kin.Tdot @ v))
        h = -T.T @ kin.gv - Cqd
        fp = -T.T @ (self._damp * kin.v) if self._damp.any() else np.zeros(self.n)
        B = T[list(self._act_v), :].T.copy()
        cons = self._constraint_rows(kin, qv, v, act, t)[0]
        return ModelTerms(M=M, h=h, f_passive=fp, B=B, constraints=cons)

    # ------------------------------------------------------------------ kinematics / geometry
    def frame_placement(self, q: ArrayLike, frame: str) -> FloatArray:
        """World placement of a frame as a 4×4 homogeneous transform."""
        fid = self.frame_id(frame)
        if self._program is not None:
            placements: FloatArray = self._program.placements(
                np.ascontiguousarray(self.pinocchio_configuration(q))
            )[1]
            return placements[fid]
        d = self._pm.createData()
        pin.framesForwardKinematics(self._pm, d, self.pinocchio_configuration(q))
        return np.array(d.oMf[fid].homogeneous)

    def geometry(self, q: ArrayLike) -> Geometry:
        """Mesh-free geometry (dim 3): joint origins, parent→child links, constraint points.

        Segments join each joint origin to its parent's and each constraint frame to its
        supporting joint; points are the joint origins followed by the constraint frame
        origins; frames are the joint frames (origin, then the three axis unit vectors).
        """
        pm = self._pm
        d = pm.createData()
        pin.framesForwardKinematics(pm, d, self.pinocchio_configuration(q))
        origins = np.array([np.array(d.oMi[j].translation) for j in range(pm.njoints)])
        segs = [
            (origins[pm.parents[j]], origins[j])
            for j in range(1, pm.njoints)
            if not np.allclose(origins[pm.parents[j]], origins[j])
        ]
        labels = [pm.names[j] for j in range(1, pm.njoints)]
        pts = list(origins[1:])
        for c in self.robot_constraints:
            if c.name not in self._fids:
                continue
            for side, fid in zip("ab", self._fids[c.name]):
                p = np.array(d.oMf[fid].translation)
                parent = origins[pm.frames[fid].parentJoint]
                if not np.allclose(parent, p):
                    segs.append((parent, p))
                pts.append(p)
                labels.append(f"{c.name}:{side}")
        frames = np.array(
            [
                np.vstack([np.array(d.oMi[j].translation), np.array(d.oMi[j].rotation).T])
                for j in range(1, pm.njoints)
            ]
        ).reshape(-1, 4, 3)
        return Geometry(
            dim=3,
            segments=np.array(segs, dtype=float).reshape(-1, 2, 3),
            points=np.array(pts, dtype=float).reshape(-1, 3),
            frames=frames,
            labels=tuple(labels),
        )


def _rebuild(cls: type[RobotModel], init: dict[str, Any]) -> RobotModel:
    """Unpickle a :class:`RobotModel` (see ``RobotModel.__reduce__``)."""
    return cls(**init)
