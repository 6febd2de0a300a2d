"""A small mutable builder that produces an immutable :class:`PlanarModel`."""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any

from ...errors import InputError, ModelError, UnknownNameError
from .._timefn import Callback, TimeFunction, as_time_function
from ._elements import (
    GROUND,
    AngleDriver,
    AngleLimit,
    Body,
    ConstantSpeed,
    ContactTangent,
    CoordinateDriver,
    DistanceDriver,
    Gear,
    Joint,
    JointActuator,
    PathDriver,
    Point,
    PointForce,
    PointOnLine,
    Prismatic,
    Profile,
    Revolute,
    Rod,
    RotationalSpring,
    SlideDriver,
    Spring,
    Torque,
    Weld,
    _finite,
    _unit,
    _vec2,
)
from ._model import Actuator, ForceElement, OutputsFn, PlanarModel

__all__ = ["PlanarBuilder", "PointRef"]

#: A point: the name of a named point, or ``(body, (x_local, y_local))``
#: (global coordinates on the ground, e.g. ``("ground", (2.0, 0.0))``).
PointRef = str | tuple[str, Any]


class PlanarBuilder:
    """Describe a planar mechanism step by step, then :meth:`build` an immutable model.

    Bodies get coordinates ``(x, y, θ)`` in the order they are added (point masses ``(x, y)``).
    Points are referenced by name (see :meth:`point`) or as ``(body, (x, y))`` with local
    coordinates (global ones on ``"ground"``). Every joint takes ``active=`` (is it in the
    default active set) and one-row joints take ``unilateral=``.

    Examples
    --------
    A pendulum: a bar of 1 m pinned to the ground at its end.

    >>> from nonmin.model.planar import PlanarBuilder
    >>> b = PlanarBuilder("pendulum")
    >>> b.body("bar", mass=1.0, inertia=1 / 12, points={"tip": (0.5, 0.0)})
    'bar'
    >>> b.revolute("pivot", ("ground", (0.0, 0.0)), ("bar", (-0.5, 0.0)))
    'pivot'
    >>> model = b.build()
    >>> model.n, model.constraint_names
    (3, ('pivot',))
    """

    def __init__(self, name: str, *, gravity: Iterable[float] = (0.0, -9.81), description: str = "") -> None:
        self.name = str(name)
        self.gravity = _vec2(gravity, "gravity")
        self.description = description
        self._bodies: list[Body] = []
        self._points: dict[str, Point] = {}
        self._joints: list[Joint] = []
        self._inactive: set[str] = set()
        self._active_unilateral: set[str] = set()
        self._forces: list[ForceElement] = []
        self._actuators: list[Actuator] = []
        self._outputs: list[str] = []

    # ------------------------------------------------------------------ bodies and points
    def _body_known(self, name: str, where: str) -> None:
        if name != GROUND and name not in {b.name for b in self._bodies}:
            raise UnknownNameError(
                f"{where}: unknown body {name!r}; known bodies: {[GROUND] + [b.name for b in self._bodies]}"
            )

    def body(
        self,
        name: str,
        *,
        mass: float,
        inertia: float,
        points: Mapping[str, Iterable[float]] | None = None,
    ) -> str:
        """Add a rigid body (COM at its origin) with optional named points (local coordinates)."""
        if inertia is None:
            raise ModelError(f"body {name!r}: inertia is required (use point_mass() for a point mass)")
        return self._add_body(Body(name, mass, inertia), points)

    def point_mass(self, name: str, *, mass: float, points: Iterable[str] = ()) -> str:
        """Add a point mass (coordinates x, y); ``points`` names points located at it."""
        return self._add_body(Body(name, mass, None), {p: (0.0, 0.0) for p in points})

    def _add_body(self, body: Body, points: Mapping[str, Iterable[float]] | None) -> str:
        if any(b.name == body.name for b in self._bodies):
            raise ModelError(f"duplicate body name {body.name!r}")
        self._bodies.append(body)
        for pname, loc in (points or {}).items():
            self.point(pname, body.name, loc)
        return body.name

    def point(self, name: str, body: str, local: Iterable[float] = (0.0, 0.0)) -> str:
        """Name a body-fixed point (global coordinates when ``body="ground"``)."""
        if name in self._points:
            raise ModelError(f"duplicate point name {name!r}")
        self._body_known(body, f"point {name!r}")
        self._points[name] = Point(body, _vec2(local, f"point {name!r}: local"))
        return name

    def ground_point(self, name: str, position: Iterable[float]) -> str:
        """Name a fixed point of the ground (global coordinates)."""
        return self.point(name, GROUND, position)

    def _ref(self, ref: PointRef, where: str) -> Point:
        if isinstance(ref, str):
            if ref not in self._points:
                raise UnknownNameError(f"{where}: unknown point {ref!r}; known: {sorted(self._points)}")
            return self._points[ref]
        if isinstance(ref, Point):
            self._body_known(ref.body, where)
            return ref
        try:
            body, loc = ref
        except (TypeError, ValueError):
            raise InputError(
                f"{where}: a point must be a point name or (body, (x, y)), got {ref!r}"
            ) from None
        self._body_known(str(body), where)
        return Point(str(body), _vec2(loc, f"{where}: local point"))

    # ------------------------------------------------------------------ joints
    def _add_joint(self, joint: Joint, active: bool) -> str:
        if any(j.name == joint.name for j in self._joints):
            raise ModelError(f"duplicate joint name {joint.name!r}")
        if not isinstance(joint.name, str) or not joint.name:
            raise InputError(f"joint name must be a non-empty string, got {joint.name!r}")
        for body in joint.bodies:
            self._body_known(body, f"joint {joint.name!r}")
        for body in joint.needs_angle():
            if body != GROUND and next(b for b in self._bodies if b.name == body).is_point_mass:
                raise ModelError(
                    f"joint {joint.name!r} ({type(joint).__name__}) needs the rotation of body "
                    f"{body!r}, which is a point mass"
                )
        self._joints.append(joint)
        if joint.kind == "unilateral":
            if active:
                self._active_unilateral.add(joint.name)
        elif not active:
            self._inactive.add(joint.name)
        return joint.name

    def revolute(self, name: str, a: PointRef, b: PointRef, *, active: bool = True) -> str:
        """Pin joint: point a (on its body) coincides with point b (2 rows)."""
        w = f"revolute {name!r}"
        return self._add_joint(Revolute(name, self._ref(a, w), self._ref(b, w)), active)

    def weld(self, name: str, a: PointRef, b: PointRef, *, angle: float = 0.0, active: bool = True) -> str:
        """Rigid connection: pin plus ``θ_b − θ_a = angle`` (3 rows)."""
        w = f"weld {name!r}"
        return self._add_joint(
            Weld(name, self._ref(a, w), self._ref(b, w), _finite(angle, f"{w}: angle")), active
        )

    def prismatic(
        self,
        name: str,
        a: PointRef,
        b: PointRef,
        *,
        axis: Iterable[float],
        angle: float = 0.0,
        active: bool = True,
    ) -> str:
        """Slider: b moves along the line through a with direction ``axis`` (fixed on a's body)."""
        w = f"prismatic {name!r}"
        return self._add_joint(
            Prismatic(name, self._ref(a, w), _unit(axis, f"{w}: axis"), self._ref(b, w), _finite(angle, f"{w}: angle")),
            active,
        )

    def point_on_line(
        self,
        name: str,
        a: PointRef,
        b: PointRef,
        *,
        axis: Iterable[float],
        unilateral: bool = False,
        active: bool | None = None,
    ) -> str:
        """Point b on the line through a along ``axis`` (on a's body); signed distance, left > 0.

        With ``unilateral=True`` this is a contact ``gap = n·(p_b − p_a) ≥ 0`` with ``n`` the
        left normal of the axis, inactive by default.
        """
        w = f"point_on_line {name!r}"
        act = (not unilateral) if active is None else bool(active)
        return self._add_joint(
            PointOnLine(name, self._ref(a, w), _unit(axis, f"{w}: axis"), self._ref(b, w), bool(unilateral)),
            act,
        )

    def contact(
        self,
        name: str,
        a: PointRef,
        b: PointRef,
        *,
        axis: Iterable[float],
        friction: float,
        radius: float = 0.0,
        active: bool = False,
    ) -> str:
        """A point contact with Coulomb friction: b on the left of the line through a along
        ``axis`` (on a's body), friction coefficient ``friction`` (μ_f ≥ 0).

        Two constraints: the unilateral ``name`` (``gap = n·(p_b − p_a) − radius ≥ 0``, ``n``
        the axis's left normal) and its tangential row ``"<name>.stick"``
        (:class:`ContactTangent`, active while the contact sticks). ``radius > 0`` is a disk
        of that radius centred at b (b's body must be rigid): the contact point is
        ``p_b − radius n`` and the slip velocity includes ``radius (θ̇_b − θ̇_a)``.
        ``active=True`` starts with the contact closed; whether it sticks or slips at the
        start is decided by :func:`~nonmin.simulate` (sticks when the tangential velocity is
        zero and the sticking force lies in the friction cone).

        Raises
        ------
        InputError
            ``friction`` or ``radius`` negative or not finite (the message names them).
        """
        w = f"contact {name!r}"
        mu = _finite(friction, f"{w}: friction")
        if mu < 0.0:
            raise InputError(f"{w}: friction must be >= 0, got {mu!r}")
        rad = _finite(radius, f"{w}: radius")
        if rad < 0.0:
            raise InputError(f"{w}: radius must be >= 0, got {rad!r}")
        u = _unit(axis, f"{w}: axis")
        pa = self._ref(a, w)
        pb = self._ref(b, w)
        if rad > 0.0:  # the line through the disk's centre height: a + radius·axis^⊥ (a's frame)
            pa = Point(pa.body, (pa.local[0] - rad * u[1], pa.local[1] + rad * u[0]))
        self._add_joint(PointOnLine(name, pa, u, pb, True), bool(active))
        self._add_joint(ContactTangent(f"{name}.stick", pa, u, pb, name, mu, rad), False)
        return name

    def rod(
        self,
        name: str,
        a: PointRef,
        b: PointRef,
        *,
        length: float,
        unilateral: bool = False,
        active: bool | None = None,
    ) -> str:
        """Distance ``|p_b − p_a| = length``; unilateral: a rope, ``length − |p_b − p_a| ≥ 0``."""
        w = f"rod {name!r}"
        L = _finite(length, f"{w}: length")
        if not L > 0.0:
            raise ModelError(f"{w}: length must be > 0, got {L}")
        act = (not unilateral) if active is None else bool(active)
        return self._add_joint(Rod(name, self._ref(a, w), self._ref(b, w), L, bool(unilateral)), act)

    def gear(
        self,
        name: str,
        body_a: str,
        body_b: str,
        *,
        ratio: float,
        offset: float = 0.0,
        carrier: str = GROUND,
        active: bool = True,
    ) -> str:
        """Gear / coupler: ``(θ_b − θ_c) = ratio (θ_a − θ_c) + offset`` (c: carrier, default ground)."""
        w = f"gear {name!r}"
        return self._add_joint(
            Gear(name, body_a, body_b, _finite(ratio, f"{w}: ratio"), _finite(offset, f"{w}: offset"), carrier),
            active,
        )

    def angle_limit(
        self,
        name: str,
        body_b: str,
        *,
        body_a: str = GROUND,
        lower: float | None = None,
        upper: float | None = None,
    ) -> tuple[str, ...]:
        """Joint limits on the relative angle ``θ_b − θ_a``: unilateral constraints
        ``"<name>.lower"`` (gap ``θ_b − θ_a − lower``) and ``"<name>.upper"`` (gap
        ``upper − (θ_b − θ_a)``), inactive until the stop is reached; ``simulate`` then applies
        the impact law (restitution from its ``restitution=`` dict, by these names).
        Returns the names added."""
        w = f"angle_limit {name!r}"
        if lower is None and upper is None:
            raise InputError(f"{w}: give lower, upper or both")
        lo = None if lower is None else _finite(lower, f"{w}: lower")
        hi = None if upper is None else _finite(upper, f"{w}: upper")
        if lo is not None and hi is not None and not lo < hi:
            raise ModelError(f"{w}: lower must be < upper, got {lo} and {hi}")
        out = []
        for side, bound in (("lower", lo), ("upper", hi)):
            if bound is not None:
                out.append(self._add_joint(AngleLimit(f"{name}.{side}", body_a, body_b, bound, side), False))  # type: ignore[arg-type]
        return tuple(out)

    def drive_angle(
        self,
        name: str,
        body_b: str,
        *,
        body_a: str = GROUND,
        profile: Profile | None = None,
        start: float = 0.0,
        speed: float = 0.0,
        active: bool = True,
    ) -> str:
        """Rheonomic driver ``θ_b − θ_a = f(t)``; default ``f(t) = start + speed·t``.

        ``profile`` is a time function (:class:`~nonmin.model.Polynomial`,
        :class:`~nonmin.model.Spline`, :class:`~nonmin.model.Sampled`,
        :class:`~nonmin.model.Expression`: evaluated by the engine) or a callable
        ``t -> (f, ḟ, f̈)`` (called back) for other prescribed motions.
        """
        prof: Profile = (
            ConstantSpeed(_finite(start, "start"), _finite(speed, "speed")) if profile is None else profile
        )
        if not callable(prof) and isinstance(prof, int | float | str | list | tuple):
            prof = as_time_function(prof, f"driver {name!r}")  # a constant, polynomial or expression
        if not callable(prof):
            raise InputError(f"drive_angle {name!r}: profile must be callable t -> (f, fd, fdd)")
        if not isinstance(prof, TimeFunction):
            prof = Callback(prof, f"driver {name!r}")  # its failures name the driver and the time
        return self._add_joint(AngleDriver(name, body_a, body_b, prof), active)

    def drive_coordinate(self, name: str, coordinate: str, motion: Any, *, active: bool = True) -> str:
        """Rheonomic driver of one coordinate, ``q_i = f(t)``: ``coordinate`` is
        ``"<body>.x"``, ``"<body>.y"`` or ``"<body>.theta"``.

        ``motion`` is a number, a time function (:class:`~nonmin.model.Polynomial`,
        :class:`~nonmin.model.Spline`, :class:`~nonmin.model.Sampled`,
        :class:`~nonmin.model.Expression`) or a callable ``t -> (f, ḟ, f̈)``.
        """
        w = f"drive_coordinate {name!r}"
        body, _, coord = str(coordinate).rpartition(".")
        if coord not in ("x", "y", "theta") or not body:
            raise InputError(f"{w}: coordinate must be '<body>.x', '<body>.y' or '<body>.theta', got {coordinate!r}")
        self._body_known(body, w)
        if body == GROUND:
            raise ModelError(f"{w}: the ground has no coordinates")
        prof = as_time_function(motion, f"driver {name!r}")
        return self._add_joint(CoordinateDriver(name, body, coord, prof), active)  # type: ignore[arg-type]

    def drive_distance(self, name: str, a: PointRef, b: PointRef, motion: Any, *, active: bool = True) -> str:
        """Rheonomic driver of the distance between two points, ``|p_b − p_a| = f(t)`` (a
        linear actuator prescribing its length; ``motion`` as in :meth:`drive_coordinate`)."""
        w = f"drive_distance {name!r}"
        prof = as_time_function(motion, f"driver {name!r}")
        f0 = abs(float(prof(0.0)[0]))
        if not f0 > 0.0:
            raise ModelError(f"{w}: the prescribed distance at t = 0 must be > 0, got {f0}")
        return self._add_joint(DistanceDriver(name, self._ref(a, w), self._ref(b, w), prof, f0), active)

    def drive_slide(self, name: str, joint: str, motion: Any, *, active: bool = True) -> str:
        """Rheonomic driver of a prismatic joint's slide ``s = (R_a u)·(p_b − p_a) = f(t)`` (the
        joint's own points and axis; ``motion`` as in :meth:`drive_coordinate`)."""
        jt = next((j for j in self._joints if j.name == joint), None)
        if jt is None:
            raise UnknownNameError(f"drive_slide {name!r}: unknown joint {joint!r}; known: {[j.name for j in self._joints]}")
        if not isinstance(jt, Prismatic):
            raise ModelError(f"drive_slide {name!r}: joint {joint!r} must be prismatic, got {type(jt).__name__}")
        prof = as_time_function(motion, f"driver {name!r}")
        return self._add_joint(SlideDriver(name, jt.a, jt.axis, jt.b, prof), active)

    def drive_path(self, name: str, point: PointRef, x: Any, y: Any, *, active: bool = True) -> str:
        """Rheonomic driver of a point along a path, ``p = (x(t), y(t))`` in world coordinates
        (two motions as in :meth:`drive_coordinate`)."""
        w = f"drive_path {name!r}"
        px = as_time_function(x, f"driver {name!r} (x)")
        py = as_time_function(y, f"driver {name!r} (y)")
        return self._add_joint(PathDriver(name, self._ref(point, w), px, py), active)

    # ------------------------------------------------------------------ forces and actuators
    def _unique_force_name(self, name: str) -> None:
        if any(f.name == name for f in self._forces):
            raise ModelError(f"duplicate force element name {name!r}")

    def spring(
        self,
        name: str,
        a: PointRef,
        b: PointRef,
        *,
        stiffness: float = 0.0,
        rest_length: float = 0.0,
        damping: float = 0.0,
    ) -> str:
        """Translational spring–damper between two points (``stiffness`` N/m, ``damping`` N·s/m)."""
        w = f"spring {name!r}"
        self._unique_force_name(name)
        k = _finite(stiffness, f"{w}: stiffness")
        c = _finite(damping, f"{w}: damping")
        l0 = _finite(rest_length, f"{w}: rest_length")
        if k < 0 or c < 0 or l0 < 0:
            raise ModelError(f"{w}: stiffness, damping and rest_length must be ≥ 0, got {k}, {c}, {l0}")
        self._forces.append(Spring(name, self._ref(a, w), self._ref(b, w), k, l0, c))
        return name

    def rotational_spring(
        self,
        name: str,
        body_a: str,
        body_b: str,
        *,
        stiffness: float = 0.0,
        rest_angle: float = 0.0,
        damping: float = 0.0,
    ) -> str:
        """Rotational spring–damper on ``θ_b − θ_a`` (N·m/rad, N·m·s/rad)."""
        w = f"rotational_spring {name!r}"
        self._unique_force_name(name)
        for body in (body_a, body_b):
            self._body_known(body, w)
        k = _finite(stiffness, f"{w}: stiffness")
        c = _finite(damping, f"{w}: damping")
        if k < 0 or c < 0:
            raise ModelError(f"{w}: stiffness and damping must be ≥ 0, got {k}, {c}")
        self._forces.append(RotationalSpring(name, body_a, body_b, k, _finite(rest_angle, f"{w}: rest_angle"), c))
        return name

    def _unique_actuator(self, name: str) -> None:
        if any(a.name == name for a in self._actuators):
            raise ModelError(f"duplicate actuator name {name!r}")

    def actuator(self, name: str, joint: str) -> str:
        """A column of B at a joint: torque at a revolute, force along a prismatic joint."""
        self._unique_actuator(name)
        if not any(j.name == joint for j in self._joints):
            raise UnknownNameError(
                f"actuator {name!r}: unknown joint {joint!r}; known: {[j.name for j in self._joints]}"
            )
        self._actuators.append(JointActuator(name, joint))
        return name

    def torque(self, name: str, body_b: str, *, body_a: str = GROUND) -> str:
        """A column of B: torque on body b (reaction on body a)."""
        self._unique_actuator(name)
        for body in (body_a, body_b):
            self._body_known(body, f"torque {name!r}")
        self._actuators.append(Torque(name, body_a, body_b))
        return name

    def force(self, name: str, at: PointRef, *, direction: Iterable[float]) -> str:
        """A column of B: force along a fixed global ``direction`` (unit) at a point."""
        self._unique_actuator(name)
        w = f"force {name!r}"
        self._actuators.append(PointForce(name, self._ref(at, w), _unit(direction, f"{w}: direction")))
        return name

    def output(self, *points: str) -> None:
        """Report these named points' positions and velocities in ``model.outputs``."""
        for p in points:
            if p not in self._points:
                raise UnknownNameError(f"output: unknown point {p!r}; known: {sorted(self._points)}")
            self._outputs.append(p)

    # ------------------------------------------------------------------ build
    def build(self, *, outputs_fn: OutputsFn | None = None) -> PlanarModel:
        """The immutable :class:`PlanarModel`."""
        default = frozenset(
            j.name
            for j in self._joints
            if (j.kind != "unilateral" and j.name not in self._inactive)
            or j.name in self._active_unilateral
        )
        return PlanarModel(
            name=self.name,
            bodies=tuple(self._bodies),
            joints=tuple(self._joints),
            points=tuple(self._points.items()),
            forces=tuple(self._forces),
            actuators=tuple(self._actuators),
            gravity=self.gravity,
            default_active_names=default,
            output_points=tuple(self._outputs),
            outputs_fn=outputs_fn,
            description=self.description,
        )
