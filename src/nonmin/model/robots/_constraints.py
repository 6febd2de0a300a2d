"""Constraints between robot frames, as plain values (no Pinocchio import here).

Every constraint names two frames of the robot (``frame_a``, ``frame_b``; ``"universe"`` is the
world) and optional placements ``placement_a``/``placement_b`` (4×4 homogeneous transforms,
relative to the named frames) of the two constraint points/frames ``a`` and ``b``. Conventions
(all vectors in world-aligned axes; ``p`` origin, ``R`` orientation, ``ω`` angular velocity of
the world-aligned frame, ``Jp``/``Jω`` the LOCAL_WORLD_ALIGNED frame Jacobians):

=================  ====  ==================================================  =================
type               rows  residual φ                                          holonomic exact?
=================  ====  ==================================================  =================
``point``          3     ``p_a − p_b``                                       yes
``weld``           6     ``[p_a − p_b, log3(R_a R_bᵀ)]``                     position rows yes;
                                                                             rotation rows:
                                                                             A = ∂φ/∂q on φ=0
``hinge``          5     ``[p_a − p_b, (R_a u₁)·(R_b k), (R_a u₂)·(R_b k)]`` yes
``planar_point``   2     ``E (p_a − p_b)`` (E: 2 axes ⊥ world normal)        yes
``planar_weld``    3     ``[E (p_a − p_b), n·log3(R_a R_bᵀ)]``               yes for planar
                                                                             motion about n
``point_on_plane`` 1     ``(R_a k)·(p_b − p_a)`` (plane through a, normal k  yes
                         in frame a; point b)
``contact``        1     gap ``(R_a k)·(p_b − p_a) ≥ 0`` (unilateral;        yes
                         default plane = world ``z = 0``)
``joint``          1     ``q₁ − r₁ − c₀ − Σₖ cₖ (q₂ − r₂)ᵏ`` (MJCF           yes
                         ``<equality joint>``; q₂ term absent if no joint2)
``joint_limit``    1     gap ``q − lower ≥ 0`` or ``upper − q ≥ 0``          yes
                         (unilateral; URDF/MJCF position limits)
``joint_driver``   1     ``q − f(t)`` (rheonomic: a driven joint; f a time   yes
                         function, see :class:`JointDriver`)
``path_driver``    1–3   ``e_i·(p_b − p_a) − f_i(t)`` for each given world   yes
                         axis i (rheonomic: a frame point on a path, see
                         :class:`PathDriver`)
``distance_driver`` 1    ``(dᵀd − f(t)²)/(2L)``, ``d = p_b − p_a``, L =       yes
                         ``f(0)`` (rheonomic, see :class:`DistanceDriver`)
=================  ====  ==================================================  =================

``k`` is the hinge axis / plane normal *in frame a*; ``u₁, u₂`` complete it to an orthonormal
basis. The rotation rows of ``weld`` and ``planar_weld`` use the relative angular velocity
``ω_a − ω_b`` (the same rows as Pinocchio's 6D constraint, up to a rotation), so
``A qdd + γ = 0`` is exact at every configuration while ``A = ∂φ/∂q`` holds on ``φ = 0``
(``A = Jlog3⁻¹ ∂φ/∂q`` elsewhere); Newton-type position corrections with A still converge.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike

from ..._validation import as_float_array
from ...errors import FileFormatError, InputError, NonFiniteError, ShapeError
from .._protocol import ConstraintKind, FloatArray

__all__ = [
    "FRAME_CONSTRAINT_TYPES", "DistanceDriver", "FrameConstraint", "JointCoupling", "JointDriver", "JointLimit",
    "PathDriver", "RobotConstraint",
]

FrameConstraintType = Literal[
    "point", "weld", "hinge", "planar_point", "planar_weld", "point_on_plane", "contact"
]
#: Frame-constraint type -> number of rows (see the table above).
FRAME_CONSTRAINT_TYPES: dict[str, int] = {
    "point": 3,
    "weld": 6,
    "hinge": 5,
    "planar_point": 2,
    "planar_weld": 3,
    "point_on_plane": 1,
    "contact": 1,
}

WORLD = "universe"


def _placement(x: ArrayLike | None, name: str) -> FloatArray:
    if x is None:
        return np.eye(4)
    arr = as_float_array(x, name)
    if not np.isfinite(arr).all():
        raise NonFiniteError(f"{name} must be finite, got {arr.tolist()}")
    if arr.shape == (3,):
        out = np.eye(4)
        out[:3, 3] = arr
        return out
    if arr.shape != (4, 4):
        raise ShapeError(f"{name} must be a translation (3,) or a 4x4 transform, got shape {arr.shape}")
    R = arr[:3, :3]
    if not np.allclose(R.T @ R, np.eye(3), atol=1e-9) or np.linalg.det(R) <= 0:
        raise InputError(f"{name}: the rotation block is not a proper rotation matrix")
    return arr.copy()


def _unit(x: ArrayLike, name: str) -> FloatArray:
    v = as_float_array(x, name)
    if v.shape != (3,):
        raise ShapeError(f"{name} must have shape (3,), got shape {v.shape}")
    nrm = float(np.linalg.norm(v))
    if not np.isfinite(nrm) or nrm == 0.0:
        raise InputError(f"{name} must be a finite non-zero vector, got {v.tolist()}")
    return v / nrm


def complete_basis(k: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Two unit vectors ``u₁, u₂`` with ``(u₁, u₂, k)`` a right-handed orthonormal basis."""
    helper = np.array([1.0, 0.0, 0.0]) if abs(k[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u1 = helper - (helper @ k) * k
    u1 /= np.linalg.norm(u1)
    u2 = np.cross(k, u1)
    return u1, u2


@dataclass(frozen=True, eq=False)
class FrameConstraint:
    """A named constraint between two frames of a robot. Build it with the named constructors.

    Attributes
    ----------
    name : str
    type : str
        One of :data:`FRAME_CONSTRAINT_TYPES` (see the module table).
    frame_a, frame_b : str
        Frame names of the robot (``"universe"`` is the world).
    placement_a, placement_b : ndarray, shape (4, 4)
        Placements of the constraint frames relative to ``frame_a`` / ``frame_b``.
    axis : ndarray, shape (3,)
        Hinge axis / plane normal in frame a (``hinge``, ``point_on_plane``, ``contact``), or
        the world plane normal (``planar_point``, ``planar_weld``).
    """

    name: str
    type: FrameConstraintType
    frame_a: str
    frame_b: str = WORLD
    placement_a: FloatArray = field(default_factory=lambda: np.eye(4))
    placement_b: FloatArray = field(default_factory=lambda: np.eye(4))
    axis: FloatArray = field(default_factory=lambda: np.array([0.0, 0.0, 1.0]))

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name:
            raise InputError(f"constraint name must be a non-empty string, got {self.name!r}")
        if self.type not in FRAME_CONSTRAINT_TYPES:
            raise InputError(
                f"constraint {self.name!r}: type must be one of {list(FRAME_CONSTRAINT_TYPES)}, "
                f"got {self.type!r}"
            )
        for nm in ("frame_a", "frame_b"):
            if not isinstance(getattr(self, nm), str):
                raise InputError(f"constraint {self.name!r}: {nm} must be a frame name (str)")
        object.__setattr__(self, "placement_a", _placement(self.placement_a, "placement_a"))
        object.__setattr__(self, "placement_b", _placement(self.placement_b, "placement_b"))
        object.__setattr__(self, "axis", _unit(self.axis, "axis"))

    @property
    def dim(self) -> int:
        """Number of rows."""
        return FRAME_CONSTRAINT_TYPES[self.type]

    @property
    def kind(self) -> ConstraintKind:
        """``"unilateral"`` for contacts, ``"holonomic"`` otherwise."""
        return "unilateral" if self.type == "contact" else "holonomic"

    @property
    def description(self) -> str:
        return f"{self.type} between frames {self.frame_a!r} and {self.frame_b!r}"

    # ------------------------------------------------------------------ named constructors
    @classmethod
    def point(
        cls,
        name: str,
        frame_a: str,
        frame_b: str = WORLD,
        *,
        placement_a: ArrayLike | None = None,
        placement_b: ArrayLike | None = None,
    ) -> FrameConstraint:
        """3D point coincidence (spherical joint / loop closure): ``p_a = p_b``."""
        return cls(name, "point", frame_a, frame_b, _placement(placement_a, "placement_a"),
                   _placement(placement_b, "placement_b"))

    @classmethod
    def weld(
        cls,
        name: str,
        frame_a: str,
        frame_b: str = WORLD,
        *,
        placement_a: ArrayLike | None = None,
        placement_b: ArrayLike | None = None,
    ) -> FrameConstraint:
        """6D weld: frames a and b coincide (position and orientation)."""
        return cls(name, "weld", frame_a, frame_b, _placement(placement_a, "placement_a"),
                   _placement(placement_b, "placement_b"))

    @classmethod
    def hinge(
        cls,
        name: str,
        frame_a: str,
        frame_b: str = WORLD,
        *,
        axis: ArrayLike = (0.0, 0.0, 1.0),
        placement_a: ArrayLike | None = None,
        placement_b: ArrayLike | None = None,
    ) -> FrameConstraint:
        """5D revolute joint: points coincide and axis ``k`` (in a) is aligned with ``k`` in b."""
        return cls(name, "hinge", frame_a, frame_b, _placement(placement_a, "placement_a"),
                   _placement(placement_b, "placement_b"), _unit(axis, "axis"))

    @classmethod
    def planar_point(
        cls,
        name: str,
        frame_a: str,
        frame_b: str = WORLD,
        *,
        normal: ArrayLike = (0.0, 1.0, 0.0),
        placement_a: ArrayLike | None = None,
        placement_b: ArrayLike | None = None,
    ) -> FrameConstraint:
        """2D point coincidence in the world plane with normal ``normal`` (planar loops)."""
        return cls(name, "planar_point", frame_a, frame_b, _placement(placement_a, "placement_a"),
                   _placement(placement_b, "placement_b"), _unit(normal, "normal"))

    @classmethod
    def planar_weld(
        cls,
        name: str,
        frame_a: str,
        frame_b: str = WORLD,
        *,
        normal: ArrayLike = (0.0, 1.0, 0.0),
        placement_a: ArrayLike | None = None,
        placement_b: ArrayLike | None = None,
    ) -> FrameConstraint:
        """2D point coincidence plus the relative rotation about the world ``normal``."""
        return cls(name, "planar_weld", frame_a, frame_b, _placement(placement_a, "placement_a"),
                   _placement(placement_b, "placement_b"), _unit(normal, "normal"))

    @classmethod
    def point_on_plane(
        cls,
        name: str,
        plane_frame: str,
        point_frame: str,
        *,
        normal: ArrayLike = (0.0, 0.0, 1.0),
        plane_placement: ArrayLike | None = None,
        point_placement: ArrayLike | None = None,
    ) -> FrameConstraint:
        """Point b stays on the plane through a with normal ``normal`` (in frame a)."""
        return cls(name, "point_on_plane", plane_frame, point_frame,
                   _placement(plane_placement, "plane_placement"),
                   _placement(point_placement, "point_placement"), _unit(normal, "normal"))

    @classmethod
    def contact(
        cls,
        name: str,
        point_frame: str,
        *,
        point_placement: ArrayLike | None = None,
        plane_frame: str = WORLD,
        plane_placement: ArrayLike | None = None,
        normal: ArrayLike = (0.0, 0.0, 1.0),
    ) -> FrameConstraint:
        """Unilateral point contact: gap = signed distance of the point to the plane ≥ 0.

        The plane passes through the origin of ``plane_placement`` (relative to
        ``plane_frame``, default the world) with normal ``normal`` in that frame; the default
        is the ground ``z = 0``.
        """
        return cls(name, "contact", plane_frame, point_frame,
                   _placement(plane_placement, "plane_placement"),
                   _placement(point_placement, "point_placement"), _unit(normal, "normal"))


@dataclass(frozen=True, eq=False)
class JointCoupling:
    """Polynomial coupling of two scalar joints (MJCF ``<equality joint polycoef=...>``).

    ``φ = (q₁ − r₁) − c₀ − Σ_{k=1..4} c_k (q₂ − r₂)^k`` (just ``q₁ − r₁ − c₀`` without joint2),
    with ``r₁, r₂`` the reference positions (MuJoCo's ``qpos0``).
    """

    name: str
    joint1: str
    joint2: str | None = None
    polycoef: tuple[float, ...] = (0.0, 1.0, 0.0, 0.0, 0.0)
    reference1: float = 0.0
    reference2: float = 0.0

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name:
            raise InputError(f"constraint name must be a non-empty string, got {self.name!r}")
        c = tuple(float(x) for x in self.polycoef)
        if not 1 <= len(c) <= 5 or not np.all(np.isfinite(c)):
            raise InputError(
                f"constraint {self.name!r}: polycoef must hold 1 to 5 finite numbers, got {c}"
            )
        object.__setattr__(self, "polycoef", c + (0.0,) * (5 - len(c)))

    @property
    def dim(self) -> int:
        return 1

    @property
    def kind(self) -> ConstraintKind:
        return "holonomic"

    @property
    def description(self) -> str:
        return f"joint coupling {self.joint1!r} = poly({self.joint2!r})"


@dataclass(frozen=True, eq=False)
class JointLimit:
    """One side of a scalar joint's position limit, as a unilateral constraint.

    Gap ``φ = s (q − bound) ≥ 0`` with ``s = +1`` for ``side="lower"`` and ``s = −1`` for
    ``side="upper"``; ``A = s eᵢᵀ`` (i the joint's coordinate), ``γ = 0``. Like a contact it is
    inactive until the gap closes; ``simulate`` then applies the impact law (eq. (impact),
    restitution from its ``restitution=`` dict) and keeps it active while the joint pushes
    into the stop. :meth:`RobotModel.from_urdf` (and ``from_mjcf``, ``from_pinocchio``) make
    two per limited revolute/prismatic joint, named ``"<joint>.lower"`` and ``"<joint>.upper"``.
    """

    name: str
    joint: str
    bound: float
    side: Literal["lower", "upper"]

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name:
            raise InputError(f"constraint name must be a non-empty string, got {self.name!r}")
        if not isinstance(self.joint, str) or not self.joint:
            raise InputError(f"constraint {self.name!r}: joint must be a joint name (str), got {self.joint!r}")
        if self.side not in ("lower", "upper"):
            raise InputError(f"constraint {self.name!r}: side must be 'lower' or 'upper', got {self.side!r}")
        try:
            b = float(self.bound)
        except (TypeError, ValueError):
            raise InputError(f"constraint {self.name!r}: bound must be a finite number, got {self.bound!r}") from None
        if not np.isfinite(b):
            raise InputError(f"constraint {self.name!r}: bound must be a finite number, got {self.bound!r}")
        object.__setattr__(self, "bound", b)

    @property
    def sign(self) -> float:
        """``+1`` for a lower limit, ``−1`` for an upper limit."""
        return 1.0 if self.side == "lower" else -1.0

    @property
    def dim(self) -> int:
        return 1

    @property
    def kind(self) -> ConstraintKind:
        return "unilateral"

    @property
    def description(self) -> str:
        rel = ">=" if self.side == "lower" else "<="
        return f"joint limit {self.joint!r} {rel} {self.bound:g}"


@dataclass(frozen=True, eq=False)
class JointDriver:
    """A driven scalar joint: rheonomic ``φ = q − f(t)`` (``A = eᵢᵀ``, ``φ_t = −ḟ``,
    ``γ = −f̈``); the driver's reaction is the joint torque (force) that imposes the motion.

    ``motion`` is a number, a time function (:class:`~nonmin.model.Polynomial`,
    :class:`~nonmin.model.Spline`, :class:`~nonmin.model.Sampled`,
    :class:`~nonmin.model.Expression`, evaluated by the engine) or a callable
    ``t -> (f, ḟ, f̈)`` (called back).
    """

    name: str
    joint: str
    motion: Any

    def __post_init__(self) -> None:
        from .._timefn import as_time_function

        if not isinstance(self.name, str) or not self.name:
            raise InputError(f"constraint name must be a non-empty string, got {self.name!r}")
        if not isinstance(self.joint, str) or not self.joint:
            raise InputError(f"constraint {self.name!r}: joint must be a joint name (str), got {self.joint!r}")
        object.__setattr__(self, "motion", as_time_function(self.motion, f"driver {self.name!r}"))

    @property
    def dim(self) -> int:
        return 1

    @property
    def kind(self) -> ConstraintKind:
        return "rheonomic"

    @property
    def description(self) -> str:
        return f"driver of joint {self.joint!r}"


@dataclass(frozen=True, eq=False)
class PathDriver:
    """A frame point on a prescribed path: rheonomic rows ``e_i·(p_b − p_a) − f_i(t) = 0``
    for each world axis ``i`` whose motion is given (``x``, ``y``, ``z``; None leaves that
    axis free), ``A_i = e_i·(J_b − J_a)`` (position Jacobians, world-aligned),
    ``φ_t = −ḟ_i``, ``γ_i = e_i·(a_b − a_a) − f̈_i`` (``a`` the point's acceleration at
    ``q̈ = 0``).

    Point b is ``frame`` (with ``point``: a translation or 4×4 placement in it); point a is
    ``reference`` (default the world origin) with ``reference_point``. Each motion is a number,
    a time function (:class:`~nonmin.model.Polynomial`, :class:`~nonmin.model.Spline`,
    :class:`~nonmin.model.Sampled`, :class:`~nonmin.model.Expression`: evaluated by the engine)
    or a callable ``t -> (f, ḟ, f̈)`` (called back). The reaction's multipliers are the world
    force components on point b that impose the path (the force on a is their opposite).
    """

    name: str
    frame: str
    x: Any = None
    y: Any = None
    z: Any = None
    point: ArrayLike | None = None
    reference: str = WORLD
    reference_point: ArrayLike | None = None
    frame_a: str = field(init=False)
    frame_b: str = field(init=False)
    placement_a: FloatArray = field(init=False)
    placement_b: FloatArray = field(init=False)
    motions: tuple[Any, ...] = field(init=False)
    axes: tuple[int, ...] = field(init=False)

    def __post_init__(self) -> None:
        from .._timefn import as_time_function

        if not isinstance(self.name, str) or not self.name:
            raise InputError(f"constraint name must be a non-empty string, got {self.name!r}")
        for nm in ("frame", "reference"):
            if not isinstance(getattr(self, nm), str) or not getattr(self, nm):
                raise InputError(f"constraint {self.name!r}: {nm} must be a frame name (str)")
        s = object.__setattr__
        axes, motions = [], []
        for i, ax in enumerate("xyz"):
            m = getattr(self, ax)
            if m is not None:
                axes.append(i)
                motions.append(as_time_function(m, f"driver {self.name!r} ({ax})"))
        if not axes:
            raise InputError(f"constraint {self.name!r}: give the motion of at least one of x, y, z")
        s(self, "axes", tuple(axes))
        s(self, "motions", tuple(motions))
        s(self, "frame_a", self.reference)
        s(self, "frame_b", self.frame)
        s(self, "placement_a", _placement(self.reference_point, "reference_point"))
        s(self, "placement_b", _placement(self.point, "point"))

    @property
    def dim(self) -> int:
        return len(self.axes)

    @property
    def kind(self) -> ConstraintKind:
        return "rheonomic"

    @property
    def description(self) -> str:
        return f"path driver of a point of frame {self.frame!r} ({''.join('xyz'[i] for i in self.axes)})"


@dataclass(frozen=True, eq=False)
class DistanceDriver:
    """A prescribed distance between two frame points, ``|p_b − p_a| = f(t)``: one rheonomic
    row ``φ = (dᵀd − f²)/(2L)`` (``d = p_b − p_a``, L = ``|f(0)|``, as a rod of length L:
    ``A = dᵀ(J_b − J_a)/L``), ``φ_t = −f ḟ/L``, ``γ = (ḋᵀḋ + dᵀ(a_b − a_a) − ḟ² − f f̈)/L``
    — a linear actuator prescribing its length. ``motion`` as in :class:`PathDriver`.
    """

    name: str
    frame_a: str
    frame_b: str
    motion: Any
    placement_a: FloatArray = field(default_factory=lambda: np.eye(4))
    placement_b: FloatArray = field(default_factory=lambda: np.eye(4))
    reference: float = field(init=False)

    def __post_init__(self) -> None:
        from .._timefn import as_time_function

        if not isinstance(self.name, str) or not self.name:
            raise InputError(f"constraint name must be a non-empty string, got {self.name!r}")
        for nm in ("frame_a", "frame_b"):
            if not isinstance(getattr(self, nm), str) or not getattr(self, nm):
                raise InputError(f"constraint {self.name!r}: {nm} must be a frame name (str)")
        s = object.__setattr__
        fn = as_time_function(self.motion, f"driver {self.name!r}")
        s(self, "motion", fn)
        s(self, "placement_a", _placement(self.placement_a, "placement_a"))
        s(self, "placement_b", _placement(self.placement_b, "placement_b"))
        L = abs(float(fn(0.0)[0]))
        if not L > 0.0:
            raise InputError(f"constraint {self.name!r}: the prescribed distance at t = 0 must be > 0, got {L}")
        s(self, "reference", L)

    @property
    def dim(self) -> int:
        return 1

    @property
    def kind(self) -> ConstraintKind:
        return "rheonomic"

    @property
    def description(self) -> str:
        return f"distance driver between frames {self.frame_a!r} and {self.frame_b!r}"


RobotConstraint = FrameConstraint | JointCoupling | JointLimit | JointDriver | PathDriver | DistanceDriver


def _joint_limits_option(joint_limits: Any) -> bool | str:
    """Validate ``joint_limits``: True (enforce), False / "warn" (warn, not enforced), "ignore"."""
    if joint_limits is True or joint_limits is False:
        return bool(joint_limits)
    if joint_limits == "warn":
        return False
    if joint_limits == "ignore":
        return "ignore"
    raise InputError(
        f"joint_limits must be True (enforce as unilateral constraints), False or 'warn' "
        f"(not enforced, a JointLimitWarning names them) or 'ignore', got {joint_limits!r}"
    )


def _robot_file(path: Any, kind: str) -> Path:
    """``path`` as a Path to an existing file, else a FileFormatError naming ``kind`` ("URDF",
    "MJCF") and whether a folder or nothing is there (the loaders' one check)."""
    p = Path(path)
    if not p.is_file():
        raise FileFormatError(
            f"path: expected a {kind} file, got "
            + (f"the folder {str(p)!r}" if p.is_dir() else f"{str(p)!r}, which does not exist")
        )
    return p
