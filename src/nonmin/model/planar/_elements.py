"""Elements of a planar multibody model in absolute coordinates: bodies, points, joints, forces.

Body ``i`` has coordinates ``(x_i, y_i, θ_i)`` (a rigid body, centre of mass at the body
origin) or ``(x_i, y_i)`` (a point mass). A body-fixed point with local coordinates ``s`` is at
``p = r + R(θ) s`` with Jacobian ``∂p/∂(r, θ) = [I, (R s)^⊥]`` (``v^⊥ = (−v_y, v_x)``),
velocity ``ṗ = ṙ + θ̇ (R s)^⊥`` and acceleration ``p̈ = r̈ + θ̈ (R s)^⊥ − θ̇² R s``. Every
joint below is written in terms of these point kinematics, which gives φ, ``A = ∂φ/∂q``, the
matrix ``Ȧ`` and ``γ = Ȧ qd`` in closed form (no finite differences).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Literal, Protocol

import numpy as np

from ...errors import InputError, ModelError
from .._protocol import FloatArray
from .._timefn import PiecewisePolynomial, Polynomial

__all__ = [
    "GROUND",
    "AngleDriver",
    "AngleLimit",
    "Body",
    "ConstantSpeed",
    "ContactTangent",
    "CoordinateDriver",
    "DistanceDriver",
    "Gear",
    "Joint",
    "JointActuator",
    "PathDriver",
    "Point",
    "PointForce",
    "PointOnLine",
    "Prismatic",
    "Revolute",
    "Rod",
    "RotationalSpring",
    "SlideDriver",
    "Spring",
    "Torque",
    "Weld",
]

#: Name of the fixed frame. Points on it are given in global coordinates.
GROUND = "ground"

Vec2 = tuple[float, float]


def _vec2(v: object, what: str) -> Vec2:
    try:
        arr = np.asarray(v, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"{what} must be a 2-vector of numbers (x, y), got {v!r}") from None
    if arr.shape != (2,):
        raise InputError(f"{what} must be a 2-vector (x, y), got shape {arr.shape}")
    if not np.isfinite(arr).all():
        raise InputError(f"{what} must be finite, got {arr.tolist()}")
    return (float(arr[0]), float(arr[1]))


def _unit(v: object, what: str) -> Vec2:
    x, y = _vec2(v, what)
    nrm = math.hypot(x, y)
    if not nrm > 1e-12:
        raise ModelError(f"{what} must be a non-zero direction, got ({x}, {y}) of length {nrm:g}")
    return (x / nrm, y / nrm)


def _finite(x: object, what: str) -> float:
    try:
        v = float(x)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise InputError(f"{what} must be a real number, got {x!r}") from None
    if not math.isfinite(v):
        raise InputError(f"{what} must be finite, got {v}")
    return v


@dataclass(frozen=True)
class Body:
    """A rigid body (``inertia`` given) or a point mass (``inertia=None``).

    Attributes
    ----------
    name : str
    mass : float
        Mass (kg), > 0.
    inertia : float or None
        Moment of inertia about the centre of mass (kg·m²), > 0; ``None`` for a point mass,
        which has only the two coordinates (x, y).
    """

    name: str
    mass: float
    inertia: float | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name or self.name == GROUND:
            raise InputError(f"body name must be a non-empty string other than {GROUND!r}, got {self.name!r}")
        m = _finite(self.mass, f"body {self.name!r}: mass")
        if not m > 0.0:
            raise ModelError(f"body {self.name!r}: mass must be > 0 kg, got {m}")
        object.__setattr__(self, "mass", m)
        if self.inertia is not None:
            inertia = _finite(self.inertia, f"body {self.name!r}: inertia")
            if not inertia > 0.0:
                raise ModelError(
                    f"body {self.name!r}: inertia about the centre of mass must be > 0 kg·m², "
                    f"got {inertia} (use inertia=None for a point mass)"
                )
            object.__setattr__(self, "inertia", inertia)

    @property
    def is_point_mass(self) -> bool:
        """True for a point mass (coordinates x, y only)."""
        return self.inertia is None

    @property
    def ncoords(self) -> int:
        """Number of coordinates: 3 for a rigid body, 2 for a point mass."""
        return 2 if self.inertia is None else 3


@dataclass(frozen=True)
class Point:
    """A body-fixed point: body name and local coordinates (global ones on the ground)."""

    body: str
    local: Vec2 = (0.0, 0.0)

    def __post_init__(self) -> None:
        object.__setattr__(self, "local", _vec2(self.local, f"point on {self.body!r}: local"))


# ----------------------------------------------------------------------------- joints
@dataclass(frozen=True)
class Joint:
    """Base of all joints (constraints). ``kind`` is holonomic, rheonomic or unilateral."""

    name: str

    @property
    def kind(self) -> Literal["holonomic", "rheonomic", "nonholonomic", "unilateral"]:
        return "holonomic"

    @property
    def dim(self) -> int:
        raise NotImplementedError

    @property
    def bodies(self) -> tuple[str, ...]:
        raise NotImplementedError

    def describe(self) -> str:
        return f"{type(self).__name__.lower()} {' – '.join(self.bodies)}"

    def needs_angle(self) -> tuple[str, ...]:
        """Bodies whose rotation this joint uses (must not be point masses)."""
        return ()

    def terms(self, kin: _Kin, t: float) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
        """``(φ, A, Ȧ, γ, φ_t)`` with shapes ``(d,), (d, n), (d, n), (d,), (d,)``."""
        raise NotImplementedError


@dataclass(frozen=True)
class Revolute(Joint):
    """Pin joint: point ``a`` on one body coincides with point ``b`` on another (2 rows).

    ``φ = p_a − p_b``, ``A = J_a − J_b``, ``Ȧ = J̇_a − J̇_b``, ``γ = −θ̇_a² R_a s_a + θ̇_b² R_b s_b``.
    """

    a: Point
    b: Point

    @property
    def dim(self) -> int:
        return 2

    @property
    def bodies(self) -> tuple[str, ...]:
        return (self.a.body, self.b.body)

    def terms(self, kin: _Kin, t: float) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
        n = kin.n
        A = np.zeros((2, n))
        Ad = np.zeros((2, n))
        pa, rsa, _, oma = kin.point(self.a)
        pb, rsb, _, omb = kin.point(self.b)
        kin.add_jac(A, self.a.body, rsa, 1.0)
        kin.add_jac(A, self.b.body, rsb, -1.0)
        kin.add_jacdot(Ad, self.a.body, rsa, oma, 1.0)
        kin.add_jacdot(Ad, self.b.body, rsb, omb, -1.0)
        gamma = -(oma * oma) * rsa + (omb * omb) * rsb
        return pa - pb, A, Ad, gamma, np.zeros(2)


def _angle_rows(kin: _Kin, a: str, b: str, A: FloatArray, row: int) -> tuple[float, float]:
    """Fill row ``row`` of A with ∂(θ_b − θ_a)/∂q; return (θ_b − θ_a, θ̇_b − θ̇_a)."""
    tha, oma = kin.angle(a)
    thb, omb = kin.angle(b)
    kin.add_angle(A, row, b, 1.0)
    kin.add_angle(A, row, a, -1.0)
    return thb - tha, omb - oma


@dataclass(frozen=True)
class Weld(Joint):
    """Rigid connection: a revolute pin plus a fixed relative angle ``θ_b − θ_a = angle`` (3 rows)."""

    a: Point
    b: Point
    angle: float = 0.0

    @property
    def dim(self) -> int:
        return 3

    @property
    def bodies(self) -> tuple[str, ...]:
        return (self.a.body, self.b.body)

    def needs_angle(self) -> tuple[str, ...]:
        return self.bodies

    def terms(self, kin: _Kin, t: float) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
        phi2, A2, Ad2, g2, _ = Revolute(self.name, self.a, self.b).terms(kin, t)
        A = np.zeros((3, kin.n))
        A[:2] = A2
        Ad = np.zeros((3, kin.n))
        Ad[:2] = Ad2
        rel, _ = _angle_rows(kin, self.a.body, self.b.body, A, 2)
        phi = np.array([phi2[0], phi2[1], rel - self.angle])
        return phi, A, Ad, np.array([g2[0], g2[1], 0.0]), np.zeros(3)


def _line_row(
    kin: _Kin, a: Point, axis: Vec2, b: Point, A: FloatArray, Ad: FloatArray, row: int
) -> tuple[float, float]:
    """Signed distance of point b from the line through a along axis (body a), left positive.

    ``φ = n·d`` with ``n = R_a u^⊥``, ``d = p_b − p_a``; ``∂n/∂θ_a = n^⊥``, ``ṅ = θ̇_a n^⊥``.
    Fills ``A[row]``, ``Ȧ[row]`` and returns ``(φ, γ)``.
    """
    pa, rsa, va, oma = kin.point(a)
    pb, rsb, vb, omb = kin.point(b)
    nrm = kin.rotate(a.body, (-axis[1], axis[0]))
    nperp = np.array([-nrm[1], nrm[0]])
    d = pb - pa
    dd = vb - va
    ndot = oma * nperp
    # A = nᵀ(J_b − J_a) + (d·n^⊥) e_θa
    D = np.zeros((2, kin.n))
    kin.add_jac(D, b.body, rsb, 1.0)
    kin.add_jac(D, a.body, rsa, -1.0)
    Dd = np.zeros((2, kin.n))
    kin.add_jacdot(Dd, b.body, rsb, omb, 1.0)
    kin.add_jacdot(Dd, a.body, rsa, oma, -1.0)
    A[row] = nrm @ D
    kin.add_angle(A, row, a.body, float(d @ nperp))
    # Ȧ = ṅᵀD + nᵀḊ + (ḋ·n^⊥ + d·ṅ^⊥) e_θa,  ṅ^⊥ = −θ̇_a n
    Ad[row] = ndot @ D + nrm @ Dd
    kin.add_angle(Ad, row, a.body, float(dd @ nperp - oma * (d @ nrm)))
    gamma = float(Ad[row] @ kin.qd)
    return float(nrm @ d), gamma


@dataclass(frozen=True)
class PointOnLine(Joint):
    """Point ``b`` slides on the line through point ``a`` along ``axis`` (body-fixed on a's body).

    ``φ = n·(p_b − p_a)`` with ``n = R_a u^⊥`` the left normal of the unit axis ``u``: the
    signed distance, positive on the left of the axis. As a unilateral contact the gap is
    this signed distance (``gap ≥ 0`` on the left side).
    """

    a: Point
    axis: Vec2
    b: Point
    unilateral: bool = False

    @property
    def kind(self) -> Literal["holonomic", "rheonomic", "nonholonomic", "unilateral"]:
        return "unilateral" if self.unilateral else "holonomic"

    @property
    def dim(self) -> int:
        return 1

    @property
    def bodies(self) -> tuple[str, ...]:
        return (self.a.body, self.b.body)

    def needs_angle(self) -> tuple[str, ...]:
        return ()

    def terms(self, kin: _Kin, t: float) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
        A = np.zeros((1, kin.n))
        Ad = np.zeros((1, kin.n))
        phi, gamma = _line_row(kin, self.a, self.axis, self.b, A, Ad, 0)
        return np.array([phi]), A, Ad, np.array([gamma]), np.zeros(1)


@dataclass(frozen=True)
class ContactTangent(Joint):
    """The tangential (sticking) row of a frictional contact (nonholonomic, inactive by default).

    Its velocity is the slip velocity of the contact ``normal`` (a unilateral
    :class:`PointOnLine` through the same line point ``a`` and axis): with ``u = R_a axis``,

    ``v_t = u·(ṗ_b − ṗ_a) + (θ̇_a (R_a axis^⊥))·(p_b − p_a) + roll (θ̇_b − θ̇_a)``

    — the row of ``ψ = u·(p_b − p_a) + roll (θ_b − θ_a)`` — where ``roll`` is the radius of a disk
    centred at ``b`` touching the line (0: a point contact). Active: the contact sticks (a
    bilateral constraint); inactive while it slips, when the simulator applies the Coulomb force
    ``−μ s N`` along this row (:mod:`nonmin.sim`, ``docs/theory.md`` "Coulomb friction").
    """

    a: Point
    axis: Vec2
    b: Point
    normal: str = ""
    mu: float = 0.0
    roll: float = 0.0

    @property
    def kind(self) -> Literal["holonomic", "rheonomic", "nonholonomic", "unilateral"]:
        return "nonholonomic"

    @property
    def dim(self) -> int:
        return 1

    @property
    def bodies(self) -> tuple[str, ...]:
        return (self.a.body, self.b.body)

    def needs_angle(self) -> tuple[str, ...]:
        return (self.b.body,) if self.roll != 0.0 else ()

    def terms(self, kin: _Kin, t: float) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
        A = np.zeros((1, kin.n))
        Ad = np.zeros((1, kin.n))
        # a line whose left normal is u: axis' = (u_y, −u_x), since (axis')^⊥ = axis
        psi, gamma = _line_row(kin, self.a, (self.axis[1], -self.axis[0]), self.b, A, Ad, 0)
        if self.roll != 0.0:
            R = np.zeros((1, kin.n))
            rel, _ = _angle_rows(kin, self.a.body, self.b.body, R, 0)
            A += self.roll * R
            psi += self.roll * rel
        return np.array([psi]), A, Ad, np.array([gamma]), np.zeros(1)


@dataclass(frozen=True)
class Prismatic(Joint):
    """Slider: fixed relative angle ``θ_b − θ_a = angle`` and point b on the axis line of a (2 rows)."""

    a: Point
    axis: Vec2
    b: Point
    angle: float = 0.0

    @property
    def dim(self) -> int:
        return 2

    @property
    def bodies(self) -> tuple[str, ...]:
        return (self.a.body, self.b.body)

    def needs_angle(self) -> tuple[str, ...]:
        return self.bodies

    def terms(self, kin: _Kin, t: float) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
        A = np.zeros((2, kin.n))
        Ad = np.zeros((2, kin.n))
        rel, _ = _angle_rows(kin, self.a.body, self.b.body, A, 0)
        phi1, gamma1 = _line_row(kin, self.a, self.axis, self.b, A, Ad, 1)
        return np.array([rel - self.angle, phi1]), A, Ad, np.array([0.0, gamma1]), np.zeros(2)

    def slide(self, kin: _Kin) -> tuple[float, float]:
        """Joint displacement ``u·(p_b − p_a)`` along the axis and its rate."""
        pa, _, va, oma = kin.point(self.a)
        pb, _, vb, _ = kin.point(self.b)
        u = kin.rotate(self.a.body, self.axis)
        d = pb - pa
        return float(u @ d), float(u @ (vb - va) + oma * (np.array([-u[1], u[0]]) @ d))


@dataclass(frozen=True)
class Rod(Joint):
    """Distance constraint ``|p_b − p_a| = length`` (massless rod), 1 row.

    ``φ = (dᵀd − L²)/(2L)`` (a length; ``A = dᵀD/L``, ``γ = (ḋᵀḋ + dᵀḊ qd)/L``). Declared
    unilateral it is a rope/tether: ``gap = −φ ≥ 0`` (distance at most L).
    """

    a: Point
    b: Point
    length: float
    unilateral: bool = False

    @property
    def kind(self) -> Literal["holonomic", "rheonomic", "nonholonomic", "unilateral"]:
        return "unilateral" if self.unilateral else "holonomic"

    @property
    def dim(self) -> int:
        return 1

    @property
    def bodies(self) -> tuple[str, ...]:
        return (self.a.body, self.b.body)

    def terms(self, kin: _Kin, t: float) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
        s = -1.0 if self.unilateral else 1.0
        phi, A, Ad, gamma, phit = _distance_terms(kin, self.a, self.b, self.length, (self.length, 0.0, 0.0))
        return s * phi, s * A, s * Ad, s * gamma, phit


def _distance_terms(
    kin: _Kin, a: Point, b: Point, L: float, f: tuple[float, float, float]
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    """The distance row of two points, ``φ = (dᵀd − f²)/(2L)`` with ``d = p_b − p_a`` and the
    prescribed distance ``f = (f, ḟ, f̈)`` (a rod: ``(L, 0, 0)``): ``A = dᵀD/L`` (D the relative
    point Jacobian), ``Ȧ = (ḋᵀD + dᵀḊ)/L``, ``γ = (ḋᵀḋ + dᵀḊq̇ − ḟ² − f f̈)/L``, ``φ_t = −f ḟ/L``."""
    pa, rsa, va, oma = kin.point(a)
    pb, rsb, vb, omb = kin.point(b)
    d = pb - pa
    dd = vb - va
    D = np.zeros((2, kin.n))
    kin.add_jac(D, b.body, rsb, 1.0)
    kin.add_jac(D, a.body, rsa, -1.0)
    Dd = np.zeros((2, kin.n))
    kin.add_jacdot(Dd, b.body, rsb, omb, 1.0)
    kin.add_jacdot(Dd, a.body, rsa, oma, -1.0)
    f0, f1, f2 = f
    A = (d @ D)[None, :] / L
    Ad = (dd @ D + d @ Dd)[None, :] / L
    gamma = (dd @ dd + d @ (Dd @ kin.qd) - f1 * f1 - f0 * f2) / L
    phi = (d @ d - f0 * f0) / (2.0 * L)
    return np.array([phi]), A, Ad, np.array([gamma]), np.array([-f0 * f1 / L])


@dataclass(frozen=True)
class AngleLimit(Joint):
    """One side of a relative angle's range, a unilateral constraint (1 row): gap
    ``s (θ_b − θ_a − bound) ≥ 0`` with ``s = +1`` (``side="lower"``) or ``−1`` (``"upper"``);
    ``A = s ∂(θ_b − θ_a)/∂q`` (constant), ``γ = 0``. Like a contact, inactive until the gap
    closes; ``simulate`` then applies the impact law at the stop."""

    body_a: str
    body_b: str
    bound: float
    side: Literal["lower", "upper"]

    @property
    def kind(self) -> Literal["holonomic", "rheonomic", "nonholonomic", "unilateral"]:
        return "unilateral"

    @property
    def sign(self) -> float:
        return 1.0 if self.side == "lower" else -1.0

    @property
    def dim(self) -> int:
        return 1

    @property
    def bodies(self) -> tuple[str, ...]:
        return (self.body_a, self.body_b)

    def needs_angle(self) -> tuple[str, ...]:
        return self.bodies

    def describe(self) -> str:
        rel = ">=" if self.side == "lower" else "<="
        return f"angle limit θ_{self.body_b} − θ_{self.body_a} {rel} {self.bound:g}"

    def terms(self, kin: _Kin, t: float) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
        A = np.zeros((1, kin.n))
        rel, _ = _angle_rows(kin, self.body_a, self.body_b, A, 0)
        s = self.sign
        return np.array([s * (rel - self.bound)]), s * A, np.zeros((1, kin.n)), np.zeros(1), np.zeros(1)


@dataclass(frozen=True)
class Gear(Joint):
    """Gear / coupler: ``(θ_b − θ_c) − ratio (θ_a − θ_c) = offset`` with carrier c (1 row, linear)."""

    body_a: str
    body_b: str
    ratio: float
    offset: float = 0.0
    carrier: str = GROUND

    @property
    def dim(self) -> int:
        return 1

    @property
    def bodies(self) -> tuple[str, ...]:
        return (self.body_a, self.body_b, self.carrier)

    def needs_angle(self) -> tuple[str, ...]:
        return self.bodies

    def terms(self, kin: _Kin, t: float) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
        A = np.zeros((1, kin.n))
        tha, _ = kin.angle(self.body_a)
        thb, _ = kin.angle(self.body_b)
        thc, _ = kin.angle(self.carrier)
        kin.add_angle(A, 0, self.body_b, 1.0)
        kin.add_angle(A, 0, self.carrier, -1.0 + self.ratio)
        kin.add_angle(A, 0, self.body_a, -self.ratio)
        phi = (thb - thc) - self.ratio * (tha - thc) - self.offset
        return np.array([phi]), A, np.zeros((1, kin.n)), np.zeros(1), np.zeros(1)


#: A prescribed motion: ``t -> (value, first derivative, second derivative)``.
Profile = Callable[[float], tuple[float, float, float]]


def ConstantSpeed(start: float, speed: float) -> PiecewisePolynomial:
    """The profile ``f(t) = start + speed·t`` (a crank turned at constant speed): the time
    function ``Polynomial([start, speed])`` of :mod:`nonmin.model._timefn`."""
    return Polynomial([float(start), float(speed)])


@dataclass(frozen=True)
class AngleDriver(Joint):
    """Rheonomic driving constraint ``θ_b − θ_a − f(t) = 0`` (1 row).

    ``φ_t = −ḟ``, ``γ = −f̈`` (``A`` is constant, so ``Ȧ = 0``).
    """

    body_a: str
    body_b: str
    profile: Profile

    @property
    def kind(self) -> Literal["holonomic", "rheonomic", "nonholonomic", "unilateral"]:
        return "rheonomic"

    @property
    def dim(self) -> int:
        return 1

    @property
    def bodies(self) -> tuple[str, ...]:
        return (self.body_a, self.body_b)

    def needs_angle(self) -> tuple[str, ...]:
        return self.bodies

    def terms(self, kin: _Kin, t: float) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
        A = np.zeros((1, kin.n))
        rel, _ = _angle_rows(kin, self.body_a, self.body_b, A, 0)
        f, fd, fdd = (float(v) for v in self.profile(float(t)))
        return np.array([rel - f]), A, np.zeros((1, kin.n)), np.array([-fdd]), np.array([-fd])


@dataclass(frozen=True)
class CoordinateDriver(Joint):
    """Prescribed coordinate ``q_i − f(t) = 0`` of one body (``x``, ``y`` or ``theta``), 1 row.

    ``A = e_iᵀ`` (constant, ``Ȧ = 0``), ``φ_t = −ḟ``, ``γ = −f̈``.
    """

    body: str
    coordinate: Literal["x", "y", "theta"]
    profile: Profile

    @property
    def kind(self) -> Literal["holonomic", "rheonomic", "nonholonomic", "unilateral"]:
        return "rheonomic"

    @property
    def dim(self) -> int:
        return 1

    @property
    def bodies(self) -> tuple[str, ...]:
        return (self.body,)

    def needs_angle(self) -> tuple[str, ...]:
        return (self.body,) if self.coordinate == "theta" else ()

    def describe(self) -> str:
        return f"coordinate driver {self.body}.{self.coordinate}"

    def terms(self, kin: _Kin, t: float) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
        i = kin.model._index[self.body][("x", "y", "theta").index(self.coordinate)]
        A = np.zeros((1, kin.n))
        A[0, i] = 1.0
        f, fd, fdd = (float(v) for v in self.profile(float(t)))
        return np.array([kin.q[i] - f]), A, np.zeros((1, kin.n)), np.array([-fdd]), np.array([-fd])


@dataclass(frozen=True)
class DistanceDriver(Joint):
    """Prescribed distance ``|p_b − p_a| = f(t)``, 1 row: ``φ = (dᵀd − f²)/(2 L)`` with the
    constant reference length ``L`` (``A = dᵀD/L`` as a rod of length L), ``φ_t = −f ḟ/L``,
    ``γ = (ḋᵀḋ + dᵀḊ q̇ − ḟ² − f f̈)/L``."""

    a: Point
    b: Point
    profile: Profile
    reference: float = 1.0

    @property
    def kind(self) -> Literal["holonomic", "rheonomic", "nonholonomic", "unilateral"]:
        return "rheonomic"

    @property
    def dim(self) -> int:
        return 1

    @property
    def bodies(self) -> tuple[str, ...]:
        return (self.a.body, self.b.body)

    def terms(self, kin: _Kin, t: float) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
        f0, f1, f2 = (float(v) for v in self.profile(float(t)))
        return _distance_terms(kin, self.a, self.b, self.reference, (f0, f1, f2))


@dataclass(frozen=True)
class PathDriver(Joint):
    """A body point on a prescribed path: ``p_a − c(t) = 0`` (2 rows, world coordinates),
    ``A = J_a``, ``Ȧ = J̇_a``, ``γ = −θ̇_a² R_a s_a − c̈``, ``φ_t = −ċ``."""

    a: Point
    x: Profile
    y: Profile

    @property
    def kind(self) -> Literal["holonomic", "rheonomic", "nonholonomic", "unilateral"]:
        return "rheonomic"

    @property
    def dim(self) -> int:
        return 2

    @property
    def bodies(self) -> tuple[str, ...]:
        return (self.a.body, GROUND)

    def describe(self) -> str:
        return f"path driver of a point of {self.a.body}"

    def terms(self, kin: _Kin, t: float) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
        A = np.zeros((2, kin.n))
        Ad = np.zeros((2, kin.n))
        pa, rsa, _, oma = kin.point(self.a)
        kin.add_jac(A, self.a.body, rsa, 1.0)
        kin.add_jacdot(Ad, self.a.body, rsa, oma, 1.0)
        fx = tuple(float(v) for v in self.x(float(t)))
        fy = tuple(float(v) for v in self.y(float(t)))
        gamma = -(oma * oma) * rsa - np.array([fx[2], fy[2]])
        return pa - np.array([fx[0], fy[0]]), A, Ad, gamma, -np.array([fx[1], fy[1]])


@dataclass(frozen=True)
class SlideDriver(Joint):
    """Prescribed slide of point b along the axis ``u`` through point a (on a's body), 1 row:
    ``φ = (R_a u)·(p_b − p_a) − f(t)`` (a driven prismatic joint). It is the line row of
    :class:`PointOnLine` with the axis turned by −90° (its normal is ``R_a u``), minus f:
    ``φ_t = −ḟ``, ``γ = γ_line − f̈``."""

    a: Point
    axis: Vec2
    b: Point
    profile: Profile

    @property
    def kind(self) -> Literal["holonomic", "rheonomic", "nonholonomic", "unilateral"]:
        return "rheonomic"

    @property
    def dim(self) -> int:
        return 1

    @property
    def bodies(self) -> tuple[str, ...]:
        return (self.a.body, self.b.body)

    @property
    def line_axis(self) -> Vec2:
        """The axis whose left normal is ``u``: ``(u_y, −u_x)``."""
        return (self.axis[1], -self.axis[0])

    def terms(self, kin: _Kin, t: float) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
        A = np.zeros((1, kin.n))
        Ad = np.zeros((1, kin.n))
        phi, gamma = _line_row(kin, self.a, self.line_axis, self.b, A, Ad, 0)
        f, fd, fdd = (float(v) for v in self.profile(float(t)))
        return np.array([phi - f]), A, Ad, np.array([gamma - fdd]), np.array([-fd])


# ----------------------------------------------------------------------------- forces
@dataclass(frozen=True)
class Spring:
    """Translational spring–damper between points a and b.

    Force on b along ``e = (p_b − p_a)/ℓ``: ``−k(ℓ − ℓ0) − c ℓ̇`` (and the opposite on a);
    potential ``k (ℓ − ℓ0)²/2``.
    """

    name: str
    a: Point
    b: Point
    stiffness: float = 0.0
    rest_length: float = 0.0
    damping: float = 0.0


@dataclass(frozen=True)
class RotationalSpring:
    """Rotational spring–damper: torque ``−k(θ_b − θ_a − θ0) − c(θ̇_b − θ̇_a)`` on b (opposite on a)."""

    name: str
    body_a: str
    body_b: str
    stiffness: float = 0.0
    rest_angle: float = 0.0
    damping: float = 0.0


# ----------------------------------------------------------------------------- actuators
@dataclass(frozen=True)
class JointActuator:
    """One column of B: a torque at a revolute joint, or a force along a prismatic joint.

    Revolute: torque ``u`` on body b and ``−u`` on body a. Prismatic: force ``u`` along the
    axis ``R_a u`` on body b at its joint point, and the reaction on body a at the same point.
    """

    name: str
    joint: str


@dataclass(frozen=True)
class PointForce:
    """One column of B: a force of magnitude ``u`` along a fixed global direction at a point."""

    name: str
    point: Point
    direction: Vec2


@dataclass(frozen=True)
class Torque:
    """One column of B: a torque ``u`` on body b and ``−u`` on body a (a may be the ground)."""

    name: str
    body_a: str
    body_b: str


# --------------------------------------------------------------------------- kinematics


class _Indexed(Protocol):
    """What :class:`_Kin` reads of a planar model: its coordinate count and, per body name,
    the indices ``(ix, iy, iθ)`` of its coordinates (``iθ = −1`` for a point mass)."""

    @property
    def _index(self) -> Mapping[str, tuple[int, int, int]]: ...

    @property
    def n(self) -> int: ...


class _Kin:
    """Per-evaluation kinematics of all bodies (positions, angles, rates, rotation matrices)."""

    __slots__ = ("_cache", "model", "n", "q", "qd")

    def __init__(self, model: _Indexed, q: FloatArray, qd: FloatArray) -> None:
        self.model = model
        self.q = q
        self.qd = qd
        self.n = model.n
        self._cache: dict[str, tuple[float, float, float, float, float, float, float]] = {}

    def _body(self, name: str) -> tuple[float, float, float, float, float, float, float]:
        """``(x, y, θ, ẋ, ẏ, θ̇, ·)`` of a body (zeros for the ground / θ of a point mass)."""
        c = self._cache.get(name)
        if c is not None:
            return c
        if name == GROUND:
            out = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        else:
            ix, iy, ith = self.model._index[name]
            th = float(self.q[ith]) if ith >= 0 else 0.0
            om = float(self.qd[ith]) if ith >= 0 else 0.0
            out = (float(self.q[ix]), float(self.q[iy]), th, float(self.qd[ix]), float(self.qd[iy]), om, 0.0)
        self._cache[name] = out
        return out

    def rotate(self, body: str, v: tuple[float, float]) -> FloatArray:
        """Global components of the body-fixed vector v."""
        th = self._body(body)[2]
        c, s = math.cos(th), math.sin(th)
        return np.array([c * v[0] - s * v[1], s * v[0] + c * v[1]])

    def point(self, p: Point) -> tuple[FloatArray, FloatArray, FloatArray, float]:
        """``(p, R s, ṗ, θ̇)`` of a body-fixed point."""
        x, y, th, xd, yd, om, _ = self._body(p.body)
        c, s = math.cos(th), math.sin(th)
        sx, sy = p.local
        rs = np.array([c * sx - s * sy, s * sx + c * sy])
        pos = np.array([x + rs[0], y + rs[1]])
        vel = np.array([xd - om * rs[1], yd + om * rs[0]])
        return pos, rs, vel, om

    def angle(self, body: str) -> tuple[float, float]:
        b = self._body(body)
        return b[2], b[5]

    def add_jac(self, rows: FloatArray, body: str, rs: FloatArray, sign: float) -> None:
        """``rows += sign·[I, (R s)^⊥]`` in the columns of ``body`` (rows: shape (2, n))."""
        if body == GROUND:
            return
        ix, iy, ith = self.model._index[body]
        rows[0, ix] += sign
        rows[1, iy] += sign
        if ith >= 0:
            rows[0, ith] -= sign * rs[1]
            rows[1, ith] += sign * rs[0]

    def add_jacdot(self, rows: FloatArray, body: str, rs: FloatArray, om: float, sign: float) -> None:
        """``rows += sign·d/dt [I, (R s)^⊥] = sign·[0, −θ̇ R s]``."""
        if body == GROUND:
            return
        ith = self.model._index[body][2]
        if ith >= 0:
            rows[0, ith] -= sign * om * rs[0]
            rows[1, ith] -= sign * om * rs[1]

    def add_angle(self, A: FloatArray, row: int, body: str, coef: float) -> None:
        if body == GROUND:
            return
        ith = self.model._index[body][2]
        if ith < 0:
            raise ModelError(f"body {body!r} is a point mass and has no rotation coordinate")
        A[row, ith] += coef
