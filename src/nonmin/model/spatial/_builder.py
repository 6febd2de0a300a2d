"""Builder of :class:`SpatialModel`: bodies, joints, springs, actuators, output points.

Joints, springs and output points are given in **world coordinates at the reference
configuration** (the body poses passed to :meth:`SpatialBuilder.add_body`); the builder
converts them into body-frame offsets and directions once. Every joint is therefore satisfied
at the reference configuration, which :meth:`SpatialModel.reference_configuration` returns.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from numpy.typing import ArrayLike

from ...errors import InputError, ModelError, UnknownNameError
from .._protocol import FloatArray
from ._inertia import INERTIA_RTOL as INERTIA_RTOL
from ._inertia import check_inertia
from ._model import (
    GROUND,
    Actuator,
    Body,
    Joint,
    JointKind,
    OutputPoint,
    SpatialModel,
    Spring,
)
from ._quaternion import rotation_matrix

__all__ = ["SpatialBuilder", "check_inertia"]

def _vec3(x: ArrayLike, name: str) -> FloatArray:
    try:
        v = np.asarray(x, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a 3-vector of numbers, got {x!r}") from None
    if v.shape != (3,):
        raise InputError(f"{name} must have shape (3,), got shape {v.shape}")
    if not np.isfinite(v).all():
        raise InputError(f"{name} must be finite, got {v.tolist()}")
    return v


def _unit(x: ArrayLike, name: str) -> FloatArray:
    v = _vec3(x, name)
    nv = float(np.linalg.norm(v))
    if nv == 0.0:
        raise ModelError(f"{name} must be a non-zero direction, got a zero-length vector {v.tolist()}")
    return v / nv


def _perpendicular_pair(u: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Unit vectors f, g with (u, f, g) right-handed orthonormal."""
    trial = np.eye(3)[int(np.argmin(np.abs(u)))]
    f = trial - (trial @ u) * u
    f /= np.linalg.norm(f)
    return f, np.cross(u, f)


class SpatialBuilder:
    """Assemble a :class:`SpatialModel` step by step (the builder is mutable, the model is not).

    Parameters
    ----------
    name : str
        Model name.
    gravity : array_like, shape (3,)
        Gravitational acceleration in the world frame (default ``(0, 0, −9.81)``).

    Examples
    --------
    A heavy body hanging from a spherical joint at the origin:

    >>> from nonmin.model.spatial import SpatialBuilder
    >>> b = SpatialBuilder("pendulum")
    >>> _ = b.add_body("bob", mass=1.0, inertia=[0.01, 0.01, 0.01], position=[0, 0, -1])
    >>> _ = b.add_spherical("pivot", "ground", "bob", point=[0, 0, 0])
    >>> model = b.build()
    >>> model.n, model.constraint_names
    (7, ('bob.norm', 'pivot'))
    """

    def __init__(self, name: str, *, gravity: ArrayLike = (0.0, 0.0, -9.81)) -> None:
        self.name = str(name)
        g = _vec3(gravity, "gravity")
        self.gravity: tuple[float, float, float] = (float(g[0]), float(g[1]), float(g[2]))
        self._bodies: dict[str, Body] = {}
        self._joints: list[Joint] = []
        self._springs: list[Spring] = []
        self._actuators: list[Actuator] = []
        self._outputs: list[OutputPoint] = []
        self._inactive: set[str] = set()

    # ------------------------------------------------------------------ bodies
    def add_body(
        self,
        name: str,
        *,
        mass: float,
        inertia: ArrayLike,
        position: ArrayLike = (0.0, 0.0, 0.0),
        quaternion: ArrayLike = (1.0, 0.0, 0.0, 0.0),
    ) -> SpatialBuilder:
        """Add a rigid body.

        Parameters
        ----------
        name : str
            Unique name (not ``"ground"``).
        mass : float
            Mass, > 0.
        inertia : array_like, shape (3, 3) or (3,)
            Inertia about the centre of mass in the body frame (a 3-vector is the diagonal).
        position : array_like, shape (3,)
            Reference position of the centre of mass (world frame).
        quaternion : array_like, shape (4,)
            Reference orientation ``(w, x, y, z)``; normalized.

        Raises
        ------
        ModelError
            Duplicate or reserved name, non-positive mass, non-physical inertia, zero quaternion.
        """
        if not isinstance(name, str) or not name:
            raise InputError(f"body name must be a non-empty string, got {name!r}")
        if name == GROUND:
            raise ModelError(f"body name {GROUND!r} is reserved for the fixed world frame")
        if name in self._bodies:
            raise ModelError(f"duplicate body name {name!r}")
        m = float(mass)
        if not np.isfinite(m) or m <= 0.0:
            raise ModelError(f"body {name!r}: mass must be a finite number > 0, got {mass!r}")
        J = check_inertia(inertia, f"body {name!r}: inertia")
        e = np.asarray(quaternion, dtype=float)
        if e.shape != (4,) or not np.isfinite(e).all() or np.linalg.norm(e) == 0.0:
            raise ModelError(
                f"body {name!r}: quaternion must be a finite non-zero 4-vector (w, x, y, z), "
                f"got {quaternion!r}"
            )
        self._bodies[name] = Body(
            name=name,
            mass=m,
            inertia=J,
            position=_vec3(position, f"body {name!r}: position"),
            quaternion=e / np.linalg.norm(e),
        )
        return self

    def _ref(self, body: str) -> tuple[FloatArray, FloatArray]:
        """Reference (position, rotation) of a body; ground is the identity."""
        if body == GROUND:
            return np.zeros(3), np.eye(3)
        try:
            b = self._bodies[body]
        except KeyError:
            raise UnknownNameError(
                f"unknown body {body!r}; known: {[GROUND, *self._bodies]}"
            ) from None
        return b.position, rotation_matrix(b.quaternion)

    def _local_point(self, body: str, point: FloatArray) -> FloatArray:
        r, R = self._ref(body)
        return R.T @ (point - r)

    def _local_vecs(self, body: str, vecs: list[FloatArray]) -> FloatArray:
        _, R = self._ref(body)
        return np.array([R.T @ v for v in vecs]).reshape(-1, 3)

    def _check_name(self, name: str) -> None:
        if not isinstance(name, str) or not name:
            raise InputError(f"name must be a non-empty string, got {name!r}")
        taken = {j.name for j in self._joints} | {s.name for s in self._springs}
        taken |= {f"{b}.norm" for b in self._bodies}
        if name in taken:
            raise ModelError(f"duplicate joint/spring name {name!r}")

    def _add_joint(
        self,
        kind: JointKind,
        name: str,
        body_a: str,
        body_b: str,
        point: ArrayLike,
        vecs_a: list[FloatArray],
        vecs_b: list[FloatArray],
        axis: FloatArray,
        active: bool = True,
    ) -> SpatialBuilder:
        self._check_name(name)
        if not active:
            self._inactive.add(name)
        self._ref(body_a)
        self._ref(body_b)
        if body_a == body_b:
            raise ModelError(f"joint {name!r} connects body {body_a!r} to itself")
        p = _vec3(point, f"joint {name!r}: point")
        self._joints.append(
            Joint(
                name=name,
                kind=kind,
                body_a=body_a,
                body_b=body_b,
                point_a=self._local_point(body_a, p),
                point_b=self._local_point(body_b, p),
                vectors_a=self._local_vecs(body_a, vecs_a),
                vectors_b=self._local_vecs(body_b, vecs_b),
                point=p,
                axis=axis,
            )
        )
        return self

    # ------------------------------------------------------------------ joints
    # Every joint takes ``active=``: whether it is in the model's default active set.
    def add_spherical(
        self, name: str, body_a: str, body_b: str, *, point: ArrayLike, active: bool = True
    ) -> SpatialBuilder:
        """Ball joint: the point of a and the point of b coincide (3 rows, ``φ = p_b − p_a``)."""
        return self._add_joint(
            "spherical", name, body_a, body_b, point, [], [], np.zeros(3), active
        )

    def add_revolute(
        self,
        name: str,
        body_a: str,
        body_b: str,
        *,
        point: ArrayLike,
        axis: ArrayLike,
        active: bool = True,
    ) -> SpatialBuilder:
        """Hinge about ``axis`` through ``point`` (5 rows: points coincide, axes parallel)."""
        u = _unit(axis, f"joint {name!r}: axis")
        f, g = _perpendicular_pair(u)
        return self._add_joint(
            "revolute", name, body_a, body_b, point, [u, f, g], [u, f, g], u, active
        )

    def add_cylindrical(
        self,
        name: str,
        body_a: str,
        body_b: str,
        *,
        point: ArrayLike,
        axis: ArrayLike,
        active: bool = True,
    ) -> SpatialBuilder:
        """Slide along and turn about ``axis`` (4 rows: axes parallel, b's point on a's axis)."""
        u = _unit(axis, f"joint {name!r}: axis")
        f, g = _perpendicular_pair(u)
        return self._add_joint(
            "cylindrical", name, body_a, body_b, point, [u, f, g], [u, f, g], u, active
        )

    def add_prismatic(
        self,
        name: str,
        body_a: str,
        body_b: str,
        *,
        point: ArrayLike,
        axis: ArrayLike,
        active: bool = True,
    ) -> SpatialBuilder:
        """Slide along ``axis`` without relative rotation (5 rows)."""
        u = _unit(axis, f"joint {name!r}: axis")
        f, g = _perpendicular_pair(u)
        return self._add_joint(
            "prismatic", name, body_a, body_b, point, [u, f, g], [u, f, g], u, active
        )

    def add_universal(
        self,
        name: str,
        body_a: str,
        body_b: str,
        *,
        point: ArrayLike,
        axis_a: ArrayLike,
        axis_b: ArrayLike,
        active: bool = True,
    ) -> SpatialBuilder:
        """Hooke joint: points coincide, ``axis_a`` (on a) stays ⊥ ``axis_b`` (on b) (4 rows).

        Raises
        ------
        ModelError
            Zero-length axes, or axes not perpendicular at the reference configuration.
        """
        ua = _unit(axis_a, f"joint {name!r}: axis_a")
        ub = _unit(axis_b, f"joint {name!r}: axis_b")
        if abs(float(ua @ ub)) > 1e-9:
            raise ModelError(
                f"joint {name!r}: axis_a and axis_b must be perpendicular, got cos = {ua @ ub:.3g}"
            )
        return self._add_joint("universal", name, body_a, body_b, point, [ua], [ub], ua, active)

    def add_weld(
        self, name: str, body_a: str, body_b: str, *, point: ArrayLike, active: bool = True
    ) -> SpatialBuilder:
        """Rigid connection (6 rows)."""
        E = list(np.eye(3))
        return self._add_joint("weld", name, body_a, body_b, point, E, E, np.zeros(3), active)

    def add_point_on_plane(
        self,
        name: str,
        body_a: str,
        body_b: str,
        *,
        point: ArrayLike,
        normal: ArrayLike,
        active: bool = True,
    ) -> SpatialBuilder:
        """b's point (``point`` at the reference) stays in the plane of a through ``point``
        with normal ``normal`` (1 row, ``φ = n_a·(p_b − p_a)``)."""
        nvec = _unit(normal, f"joint {name!r}: normal")
        return self._add_joint(
            "point_on_plane", name, body_a, body_b, point, [nvec], [], nvec, active
        )

    def add_contact(
        self,
        name: str,
        body_a: str,
        body_b: str,
        *,
        point: ArrayLike,
        normal: ArrayLike,
        friction: float,
        active: bool = False,
    ) -> SpatialBuilder:
        """A point contact with Coulomb friction: b's point (``point`` at the reference) stays
        on the side of a's plane through ``point`` that ``normal`` points to, with friction
        coefficient ``friction`` (μ_f ≥ 0, an exact isotropic cone).

        Two constraints: the unilateral ``name`` (``gap = n_a·(p_b − p_a) ≥ 0``) and the
        two-row tangential ``"<name>.stick"`` (``t_i·(p_b − p_a)``, ``t_1, t_2 ⊥ n`` on a; its
        velocity is the slip velocity of b's point), active while the contact sticks; while
        it slips the force ``−μ_f N v_t/|v_t|`` acts along those rows (:func:`~nonmin.simulate`,
        ``docs/theory.md`` "Coulomb friction").

        Raises
        ------
        InputError
            ``friction`` negative or not finite (the message names it).
        """
        from dataclasses import replace

        w = f"contact {name!r}"
        try:
            mu = float(friction)
        except (TypeError, ValueError):
            raise InputError(f"{w}: friction must be a real number, got {friction!r}") from None
        if not (np.isfinite(mu) and mu >= 0.0):
            raise InputError(f"{w}: friction must be a finite number >= 0, got {mu!r}")
        nvec = _unit(normal, f"{w}: normal")
        helper = np.array([1.0, 0.0, 0.0]) if abs(nvec[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        t1 = np.cross(nvec, helper)
        t1 /= np.linalg.norm(t1)
        t2 = np.cross(nvec, t1)
        self._add_joint("contact", name, body_a, body_b, point, [nvec], [], nvec, active)
        self._add_joint("contact_tangent", f"{name}.stick", body_a, body_b, point, [t1, t2], [], nvec, False)
        self._joints[-1] = replace(self._joints[-1], mu=mu, contact=name)
        return self

    # ------------------------------------------------------------------ drivers
    # Drivers are rheonomic constraints that prescribe a motion: ``motion`` is a number, a time
    # function (nonmin.model.Polynomial, Spline, Sampled, Expression: evaluated by the engine)
    # or a callable t -> (f, ḟ, f̈) (called back). Positions are world coordinates.
    def _add_driver(
        self, kind: JointKind, name: str, body_a: str, body_b: str, pa: FloatArray, pb: FloatArray,
        vecs_a: list[FloatArray], motions: tuple[object, ...], reference: float, active: bool,
    ) -> SpatialBuilder:
        from dataclasses import replace

        from .._timefn import as_time_function

        fns = tuple(as_time_function(m, f"driver {name!r}") for m in motions)
        self._add_joint(kind, name, body_a, body_b, pa, vecs_a, [], np.zeros(3), active)
        j = self._joints[-1]
        self._joints[-1] = replace(
            j, point_a=self._local_point(body_a, pa), point_b=self._local_point(body_b, pb),
            motions=fns, reference=float(reference),
        )
        return self

    def add_coordinate_driver(
        self, name: str, body: str, coordinate: str, motion: object, *, active: bool = True
    ) -> SpatialBuilder:
        """Prescribed world coordinate ``"x"``, ``"y"`` or ``"z"`` of a body's centre of mass:
        ``e·r − f(t) = 0`` (1 row)."""
        axes = {"x": 0, "y": 1, "z": 2}
        if coordinate not in axes:
            raise InputError(f"driver {name!r}: coordinate must be 'x', 'y' or 'z', got {coordinate!r}")
        r, _ = self._ref(body)
        e = np.eye(3)[axes[coordinate]]
        return self._add_driver("coordinate_driver", name, GROUND, body, np.zeros(3), r, [e], (motion,), 1.0, active)

    def add_path_driver(
        self, name: str, body: str, *, point: ArrayLike, x: object, y: object, z: object, active: bool = True
    ) -> SpatialBuilder:
        """A body point (``point``: world coordinates at the reference configuration) on a
        prescribed path ``p = (x(t), y(t), z(t))`` in the world frame (3 rows)."""
        p = _vec3(point, f"driver {name!r}: point")
        self._ref(body)
        return self._add_driver("path_driver", name, GROUND, body, np.zeros(3), p, [], (x, y, z), 1.0, active)

    def add_angle_driver(self, name: str, joint: str, motion: object, *, active: bool = True) -> SpatialBuilder:
        """Prescribed relative angle θ(t) of a revolute or cylindrical joint (1 row): the
        rotation of ``body_b`` relative to ``body_a`` about the joint axis, right-handed, zero at
        the reference configuration. ``φ = sin(θ − f(t))`` (two perpendicular-vector products,
        exact γ with the time-dependent row)."""
        from dataclasses import replace

        from .._timefn import as_time_function

        j = next((x for x in self._joints if x.name == joint), None)
        if j is None:
            raise UnknownNameError(f"driver {name!r}: unknown joint {joint!r}; known: {[x.name for x in self._joints]}")
        if j.kind not in ("revolute", "cylindrical"):
            raise ModelError(f"driver {name!r}: joint {joint!r} must be revolute or cylindrical, got {j.kind}")
        fn = as_time_function(motion, f"driver {name!r}")
        self._add_joint("angle_driver", name, j.body_a, j.body_b, j.point, [], [], j.axis, active)
        self._joints[-1] = replace(
            self._joints[-1], vectors_a=j.vectors_a[1:3].copy(), vectors_b=j.vectors_b[1:2].copy(), motions=(fn,)
        )
        return self

    def add_slide_driver(self, name: str, joint: str, motion: object, *, active: bool = True) -> SpatialBuilder:
        """Prescribed slide ``s(t)`` of a prismatic or cylindrical joint along its axis (1 row):
        ``φ = (R_a u)·(p_b − p_a) − f(t)``, zero at the reference configuration."""
        from dataclasses import replace

        from .._timefn import as_time_function

        j = next((x for x in self._joints if x.name == joint), None)
        if j is None:
            raise UnknownNameError(f"driver {name!r}: unknown joint {joint!r}; known: {[x.name for x in self._joints]}")
        if j.kind not in ("prismatic", "cylindrical"):
            raise ModelError(f"driver {name!r}: joint {joint!r} must be prismatic or cylindrical, got {j.kind}")
        fn = as_time_function(motion, f"driver {name!r}")
        self._add_joint("slide_driver", name, j.body_a, j.body_b, j.point, [], [], j.axis, active)
        self._joints[-1] = replace(
            self._joints[-1], point_a=j.point_a.copy(), point_b=j.point_b.copy(),
            vectors_a=j.vectors_a[:1].copy(), motions=(fn,),
        )
        return self

    def add_distance_driver(
        self, name: str, body_a: str, body_b: str, *, point_a: ArrayLike, point_b: ArrayLike, motion: object,
        active: bool = True,
    ) -> SpatialBuilder:
        """Prescribed distance between two body points (world coordinates at the reference
        configuration): ``|p_b − p_a| = f(t)`` (1 row, ``φ = (|d|² − f²)/(2L)`` with L the
        reference distance)."""
        pa = _vec3(point_a, f"driver {name!r}: point_a")
        pb = _vec3(point_b, f"driver {name!r}: point_b")
        L = float(np.linalg.norm(pb - pa))
        if not L > 0.0:
            raise ModelError(f"driver {name!r}: the two points coincide at the reference configuration")
        return self._add_driver("distance_driver", name, body_a, body_b, pa, pb, [], (motion,), L, active)

    # ------------------------------------------------------------------ joint limits
    def _add_limits(
        self, name: str, joint: str, lower: float | None, upper: float | None, kinds: tuple[str, ...],
        kind: JointKind, what: str,
    ) -> tuple[str, ...]:
        from dataclasses import replace

        from .._timefn import as_time_function

        w = f"{what} {name!r}"
        j = next((x for x in self._joints if x.name == joint), None)
        if j is None:
            raise UnknownNameError(f"{w}: unknown joint {joint!r}; known: {[x.name for x in self._joints]}")
        if j.kind not in kinds:
            raise ModelError(f"{w}: joint {joint!r} must be {' or '.join(kinds)}, got {j.kind}")
        if lower is None and upper is None:
            raise InputError(f"{w}: give lower, upper or both")
        bounds: dict[str, float] = {}
        for side, v in (("lower", lower), ("upper", upper)):
            if v is None:
                continue
            try:
                x = float(v)
            except (TypeError, ValueError):
                raise InputError(f"{w}: {side} must be a real number, got {v!r}") from None
            if not np.isfinite(x):
                raise InputError(f"{w}: {side} must be finite, got {x!r}")
            bounds[side] = x
        if len(bounds) == 2 and not bounds["lower"] < bounds["upper"]:
            raise ModelError(f"{w}: lower must be < upper, got {bounds['lower']} and {bounds['upper']}")
        if kind == "angle_limit" and len(bounds) == 2 and not bounds["upper"] - bounds["lower"] < np.pi:
            raise ModelError(
                f"{w}: upper − lower must be < π (each stop's gap is sin of the angle to it), got "
                f"{bounds['upper'] - bounds['lower']:.6g}"
            )
        for n in (f"{name}.{side}" for side in bounds):
            self._check_name(n)
        out = []
        for side, x in bounds.items():
            s = 1.0 if side == "lower" else -1.0
            n = f"{name}.{side}"
            self._add_joint(kind, n, j.body_a, j.body_b, j.point, [], [], j.axis, False)
            vecs_a = j.vectors_a[1:3] if kind == "angle_limit" else j.vectors_a[:1]
            vecs_b = j.vectors_b[1:2] if kind == "angle_limit" else j.vectors_b[:0]
            self._joints[-1] = replace(
                self._joints[-1], point_a=j.point_a.copy(), point_b=j.point_b.copy(),
                vectors_a=vecs_a.copy(), vectors_b=vecs_b.copy(),
                motions=(as_time_function(s * x, w),), reference=s,
            )
            out.append(n)
        return tuple(out)

    def add_angle_limit(
        self, name: str, joint: str, *, lower: float | None = None, upper: float | None = None
    ) -> tuple[str, ...]:
        """Joint limits on the relative angle θ of a revolute or cylindrical joint (the rotation
        of ``body_b`` relative to ``body_a`` about the joint axis, right-handed, zero at the
        reference configuration, as in :meth:`add_angle_driver`): unilateral constraints
        ``"<name>.lower"`` (gap ``sin(θ − lower) ≥ 0``) and ``"<name>.upper"`` (gap
        ``sin(upper − θ) ≥ 0``), inactive until the stop is reached; :func:`~nonmin.simulate`
        then applies the impact law with the restitution of its ``EventSet``, by these names.
        The sine gap is exact at the stop and keeps its sign within π of it, hence
        ``upper − lower < π``. Returns the names added.

        Raises
        ------
        UnknownNameError, ModelError
            ``joint`` unknown or not revolute/cylindrical; ``lower ≥ upper``; ``upper − lower ≥ π``.
        InputError
            Neither bound given, or a bound not a finite number.
        """
        return self._add_limits(name, joint, lower, upper, ("revolute", "cylindrical"), "angle_limit", "angle limit")

    def add_slide_limit(
        self, name: str, joint: str, *, lower: float | None = None, upper: float | None = None
    ) -> tuple[str, ...]:
        """Joint limits on the slide s of a prismatic or cylindrical joint along its axis (as in
        :meth:`add_slide_driver`, zero at the reference configuration): unilateral constraints
        ``"<name>.lower"`` (gap ``s − lower ≥ 0``) and ``"<name>.upper"`` (gap
        ``upper − s ≥ 0``), inactive until the stop is reached. Returns the names added.

        Raises
        ------
        UnknownNameError, ModelError
            ``joint`` unknown or not prismatic/cylindrical; ``lower ≥ upper``.
        InputError
            Neither bound given, or a bound not a finite number.
        """
        return self._add_limits(name, joint, lower, upper, ("prismatic", "cylindrical"), "slide_limit", "slide limit")

    # ------------------------------------------------------------------ forces, outputs
    def add_spring(
        self,
        name: str,
        body_a: str,
        point_a: ArrayLike,
        body_b: str,
        point_b: ArrayLike,
        *,
        stiffness: float,
        rest_length: float | None = None,
        damping: float = 0.0,
    ) -> SpatialBuilder:
        """Point-to-point spring(-damper) between world points given at the reference.

        ``rest_length`` defaults to the reference distance.
        """
        self._check_name(name)
        pa = _vec3(point_a, f"spring {name!r}: point_a")
        pb = _vec3(point_b, f"spring {name!r}: point_b")
        self._ref(body_a)
        self._ref(body_b)
        k = float(stiffness)
        c = float(damping)
        L = float(np.linalg.norm(pb - pa)) if rest_length is None else float(rest_length)
        for val, what in ((k, "stiffness"), (c, "damping"), (L, "rest_length")):
            if not np.isfinite(val) or val < 0.0:
                raise ModelError(f"spring {name!r}: {what} must be finite and ≥ 0, got {val!r}")
        self._springs.append(
            Spring(
                name=name,
                body_a=body_a,
                point_a=self._local_point(body_a, pa),
                body_b=body_b,
                point_b=self._local_point(body_b, pb),
                stiffness=k,
                rest_length=L,
                damping=c,
            )
        )
        return self

    def add_actuator(
        self, name: str, joint: str, *, dof: Literal["rotation", "translation"] = "rotation"
    ) -> SpatialBuilder:
        """A joint torque (``dof="rotation"``) or force (``"translation"``): one column of B.

        Raises
        ------
        UnknownNameError
            If the joint does not exist.
        ModelError
            If the joint has no such degree of freedom.
        """
        kinds = {j.name: j.kind for j in self._joints}
        if joint not in kinds:
            raise UnknownNameError(f"actuator {name!r}: unknown joint {joint!r}; known: {list(kinds)}")
        ok = {"rotation": ("revolute", "cylindrical"), "translation": ("prismatic", "cylindrical")}
        if dof not in ok:
            raise InputError(f"actuator {name!r}: dof must be 'rotation' or 'translation', got {dof!r}")
        if kinds[joint] not in ok[dof]:
            raise ModelError(
                f"actuator {name!r}: a {kinds[joint]} joint has no actuated {dof}; "
                f"{dof} actuators need one of {ok[dof]}"
            )
        if name in {a.name for a in self._actuators}:
            raise ModelError(f"duplicate actuator name {name!r}")
        self._actuators.append(Actuator(name=name, joint=joint, dof=dof))
        return self

    def add_output_point(self, name: str, body: str, *, point: ArrayLike) -> SpatialBuilder:
        """Report the position (``"<name>.position"``) and velocity (``"<name>.velocity"``) of
        a body point given in world coordinates at the reference configuration."""
        p = _vec3(point, f"output {name!r}: point")
        self._ref(body)
        if name in {o.name for o in self._outputs}:
            raise ModelError(f"duplicate output name {name!r}")
        self._outputs.append(OutputPoint(name=name, body=body, point=self._local_point(body, p)))
        return self

    def build(self) -> SpatialModel:
        """The immutable :class:`SpatialModel`.

        Its default active set holds every constraint except the joints added with
        ``active=False``.
        """
        default = None
        if self._inactive:
            names = [f"{b}.norm" for b in self._bodies] + [j.name for j in self._joints]
            default = frozenset(n for n in names if n not in self._inactive)
        return SpatialModel(
            name=self.name,
            bodies=tuple(self._bodies.values()),
            joints=tuple(self._joints),
            springs=tuple(self._springs),
            actuators=tuple(self._actuators),
            output_points=tuple(self._outputs),
            gravity=self.gravity,
            default_active_names=default,
        )
