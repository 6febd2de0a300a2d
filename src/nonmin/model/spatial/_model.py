"""Spatial multibody model in absolute coordinates with unit quaternions.

Coordinates: 7 per body, ``q_i = (x, y, z, e0, e1, e2, e3)``: the world position of the centre
of mass and the quaternion ``ε`` (scalar first) that rotates body-frame vectors into the world
frame (see :mod:`nonmin.model.spatial._quaternion` for the convention). Every body has a
holonomic norm constraint ``"<body>.norm"``: ``φ = ½(εᵀε − 1)``, ``A = [0, εᵀ]``,
``γ = ε̇ᵀε̇``.

Dynamics (per body, block-diagonal)::

    M = blockdiag(m I₃, 4 Gᵀ J G),    C = blockdiag(0, 4 G(ε̇)ᵀ J G + 4 H(J G ε̇)),
    f_g = (m g, 0),                    V = −m gᵀ r,

plus point-to-point springs (``V = ½ k (ℓ − ℓ₀)²``) and their dampers (passive force).
``M`` is singular along ``ε`` (``M_ε ε = 0``), which is harmless: the norm constraint removes
that direction, so ``M̄ = PMP + μQ`` is positive definite.

Joints are built from three primitives with closed-form ``A``, ``Ȧ`` and ``γ = Ȧ q̇``:
coincident points (3 rows), perpendicular body vectors ``(R_a u)·(R_b v) = 0`` and a body
vector perpendicular to the joint offset ``(R_a u)·(p_b − p_a) = 0``. For a point with local
offset ``s``, ``p = r + R(ε) s = r + [εᵀQ_a(s)ε]_a``, ``∂p/∂ε = 2 Q(s) ε`` and
``d/dt ∂p/∂ε = 2 Q(s) ε̇`` exactly.
"""

from __future__ import annotations

import weakref
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any, Literal, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ...errors import ModelError, UnknownNameError
from .._protocol import (
    ConstraintSpec,
    ConstraintTerms,
    FloatArray,
    FrictionContact,
    Geometry,
    Model,
    _as_vector,
)
from ._inertia import check_inertia  # validates replace(bodies=...) variants too
from ._quaternion import E_matrix, G_matrix, H_matrix, point_tensor, rotation_matrix

__all__ = [
    "GROUND",
    "JOINT_KINDS",
    "Actuator",
    "Body",
    "Joint",
    "JointKind",
    "OutputPoint",
    "SpatialModel",
    "Spring",
]

#: Reserved body name of the fixed world frame.
GROUND = "ground"

JointKind = Literal[
    "spherical", "revolute", "prismatic", "cylindrical", "universal", "weld", "point_on_plane",
    "coordinate_driver", "path_driver", "distance_driver", "angle_driver", "slide_driver",
    "contact", "contact_tangent", "angle_limit", "slide_limit",
]
#: The joint kinds of the spatial builder.
JOINT_KINDS: tuple[str, ...] = (
    "spherical", "revolute", "prismatic", "cylindrical", "universal", "weld", "point_on_plane"
)
#: Driver kinds (rheonomic): a prescribed COM coordinate, point path, distance, joint angle.
DRIVER_KINDS: tuple[str, ...] = (
    "coordinate_driver", "path_driver", "distance_driver", "angle_driver", "slide_driver"
)
_JOINT_ROWS = {
    "spherical": 3,
    "revolute": 5,
    "prismatic": 5,
    "cylindrical": 4,
    "universal": 4,
    "weld": 6,
    "point_on_plane": 1,
    "coordinate_driver": 1,
    "path_driver": 3,
    "distance_driver": 1,
    "angle_driver": 1,
    "slide_driver": 1,
    "contact": 1,  # unilateral n_a·(p_b − p_a) ≥ 0 (SpatialBuilder.add_contact)
    "contact_tangent": 2,  # its tangential rows t_i·(p_b − p_a), velocity = the slip velocity
    "angle_limit": 1,  # unilateral sin(s (θ − bound)) ≥ 0, s = +1 lower / −1 upper
    "slide_limit": 1,  # unilateral s ((R_a u)·(p_b − p_a) − bound) ≥ 0
}


@dataclass(frozen=True, eq=False)
class Body:
    """A rigid body.

    Attributes
    ----------
    name : str
    mass : float
        Mass (> 0).
    inertia : ndarray, shape (3, 3)
        Inertia tensor about the centre of mass in the body frame (SPD, triangle inequality).
    position : ndarray, shape (3,)
        Reference (initial) position of the centre of mass in the world frame.
    quaternion : ndarray, shape (4,)
        Reference (initial) orientation, unit quaternion ``(w, x, y, z)``.
    """

    name: str
    mass: float
    inertia: FloatArray
    position: FloatArray
    quaternion: FloatArray


@dataclass(frozen=True, eq=False)
class Joint:
    """A joint between bodies ``body_a`` and ``body_b`` (either may be :data:`GROUND`).

    Build joints with :class:`~nonmin.model.spatial.SpatialBuilder`, which converts the
    world-frame point and axes given at the reference configuration into the body-frame
    quantities stored here.

    Attributes
    ----------
    name : str
    kind : str
        One of :data:`JOINT_KINDS`.
    body_a, body_b : str
    point_a, point_b : ndarray, shape (3,)
        The joint point in the frame of a and of b (world frame for ground), relative to the
        centre of mass.
    vectors_a, vectors_b : ndarray, shape (k, 3)
        Body-frame unit vectors used by the joint's rows (world frame for ground):
        revolute/prismatic/cylindrical ``(u, f, g)`` with axis u and ``f, g ⊥ u``;
        universal ``(u_a,)`` / ``(u_b,)``; weld the world basis; point-on-plane the normal
        on a.
    point, axis : ndarray, shape (3,)
        World-frame point and (unit) axis at the reference configuration (for descriptions).
    motions : tuple of TimeFunction
        Drivers only: the prescribed motions of the rows (coordinate: 1, path: 3 (x, y, z),
        distance: 1). A coordinate driver has ``vectors_a[0]`` the world axis of the coordinate.
    reference : float
        Distance driver: the constant reference length L of ``φ = (|d|² − f²)/(2L)``. Angle
        and slide limits: the side s (+1 lower, −1 upper; their motion is the constant s·bound).
    """

    name: str
    kind: JointKind
    body_a: str
    body_b: str
    point_a: FloatArray
    point_b: FloatArray
    vectors_a: FloatArray
    vectors_b: FloatArray
    point: FloatArray
    axis: FloatArray
    motions: tuple[Any, ...] = ()
    reference: float = 1.0
    mu: float = 0.0  # contact_tangent: Coulomb's coefficient
    contact: str = ""  # contact_tangent: the name of its unilateral normal constraint

    @property
    def dim(self) -> int:
        """Number of constraint rows."""
        return _JOINT_ROWS[self.kind]


def _spec_kind(kind: str) -> Literal["holonomic", "rheonomic", "nonholonomic", "unilateral"]:
    """The constraint kind of a joint kind: contacts unilateral, their tangential rows
    nonholonomic, drivers rheonomic, the others holonomic."""
    if kind in ("contact", "angle_limit", "slide_limit"):
        return "unilateral"
    if kind == "contact_tangent":
        return "nonholonomic"
    return "rheonomic" if kind in DRIVER_KINDS else "holonomic"


@dataclass(frozen=True, eq=False)
class Spring:
    """A point-to-point spring-damper: ``V = ½ k (ℓ − ℓ₀)²``, force ``−c ℓ̇`` along the line.

    Attributes
    ----------
    name : str
    body_a, body_b : str
    point_a, point_b : ndarray, shape (3,)
        Attachment points in the body frames (world frame for ground), relative to the COM.
    stiffness, rest_length, damping : float
    """

    name: str
    body_a: str
    point_a: FloatArray
    body_b: str
    point_b: FloatArray
    stiffness: float
    rest_length: float
    damping: float = 0.0


@dataclass(frozen=True)
class Actuator:
    """A joint actuator (one column of B): a torque about, or a force along, a joint's axis.

    ``dof="rotation"`` (revolute, cylindrical): torque ``u`` on b about the axis, ``−u`` on a.
    ``dof="translation"`` (prismatic, cylindrical): force ``u`` along the axis; the column is
    the gradient of the slide ``s = (R_a u)·(p_b − p_a)``, so its power is ``u ṡ``.
    """

    name: str
    joint: str
    dof: Literal["rotation", "translation"]


@dataclass(frozen=True, eq=False)
class OutputPoint:
    """A named body point reported by :meth:`SpatialModel.outputs` (position and velocity)."""

    name: str
    body: str
    point: FloatArray


class _Kin(NamedTuple):
    """A world-frame 3-vector quantity x(q): value, Jacobian ∂x/∂q and its time derivative."""

    val: FloatArray  # (3,)
    J: FloatArray  # (3, n)
    Jd: FloatArray  # (3, n)


def _diff(x: _Kin, y: _Kin) -> _Kin:
    return _Kin(x.val - y.val, x.J - y.J, x.Jd - y.Jd)


def _dot(x: _Kin, y: _Kin, qd: FloatArray) -> tuple[float, FloatArray, FloatArray]:
    """φ = x·y, A = ∂φ/∂q and Ȧ (exact)."""
    xd = x.J @ qd
    yd = y.J @ qd
    A = y.val @ x.J + x.val @ y.J
    Ad = yd @ x.J + y.val @ x.Jd + xd @ y.J + x.val @ y.Jd
    return float(x.val @ y.val), A, Ad


@dataclass(frozen=True, eq=False)
class _RowPlan:
    """Every joint row written as ``φ = X·Y`` with ``X = Σ SX[r, k] x_k``, ``Y = Σ SY[r, k] x_k``
    over world-frame attachment quantities ``x_k`` (body points ``r + R s``, body vectors
    ``R s`` or constants), so that φ, A and Ȧ of all rows are evaluated at once:
    ``A_r = Σ_k (SX[r,k] Y_r + SY[r,k] X_r)ᵀ ∂x_k/∂q`` and ``Ȧ_r`` by the product rule.
    Coincident points are ``e_cᵀ (p_b − p_a)`` with constant unit vectors ``e_c``."""

    att_body: NDArray[np.intp]  # (K,) body index, nb for ground/constants
    att_Q: FloatArray  # (K, 3, 4, 4) point tensors (zero for ground)
    att_const: FloatArray  # (K, 3) world value of ground attachments
    att_point: FloatArray  # (K,) 1.0 for points of moving bodies
    SX: FloatArray  # (Rj, K)
    SY: FloatArray  # (Rj, K)
    term_row: NDArray[np.intp]  # (T,) row of each (row, attachment) term
    term_att: NDArray[np.intp]  # (T,) its attachment
    term_sign: FloatArray  # (T,) its coefficient
    term_side_x: NDArray[np.bool_]  # (T,) True when the attachment is in X (partner Y)
    term_index: NDArray[np.intp]  # (T * 7,) flat indices into a (Rj, 7 (nb + 1)) array
    row_driver: NDArray[np.intp]  # (Rj,) index into motions, −1: none
    row_square: FloatArray  # (Rj,) 0: g = f, else g = square·f²
    motions: tuple[Any, ...]  # prescribed motions (TimeFunction) of the driver rows
    n_main: int  # rows of the joints; angle drivers' auxiliary rows follow
    angle_rows: tuple[tuple[int, int, int, int], ...]  # (row, aux 1, aux 2, motion index)

    def driver_terms(self, t: float) -> tuple[FloatArray, FloatArray, FloatArray]:
        """``(g, ġ, g̈)`` subtracted from (φ, A q̇ + φ_t, γ) of every joint row, shape (Rj,)."""
        rj = self.n_main
        g = np.zeros((3, rj))
        for r in np.flatnonzero(self.row_driver >= 0):
            f, fd, fdd = (float(x) for x in self.motions[int(self.row_driver[r])](float(t)))
            sq = float(self.row_square[r])
            g[:, r] = (f, fd, fdd) if sq == 0.0 else (sq * f * f, 2 * sq * f * fd, 2 * sq * (fd * fd + f * fdd))
        return g[0], g[1], g[2]

    @classmethod
    def build(cls, model: SpatialModel) -> _RowPlan:
        nb = len(model.bodies)
        bodies: list[int] = []
        Qs: list[FloatArray] = []
        consts: list[FloatArray] = []
        points: list[float] = []

        def att(body: str, local: ArrayLike, point: bool) -> int:
            i = model.body_index(body)
            loc = np.asarray(local, dtype=float)
            bodies.append(nb if i < 0 else i)
            Qs.append(np.zeros((3, 4, 4)) if i < 0 else point_tensor(loc))
            consts.append(loc if i < 0 else np.zeros(3))
            points.append(1.0 if (point and i >= 0) else 0.0)
            return len(bodies) - 1

        rows: list[tuple[list[tuple[int, float]], list[tuple[int, float]]]] = []
        drivers: list[tuple[int, float]] = []  # per row: (motion index or −1, square)
        motions: list[Any] = []
        angles: list[Any] = []  # (row, motion index, aux row 1 terms, aux row 2 terms)
        for j in model.joints:
            pa = att(j.body_a, j.point_a, True)
            pb = att(j.body_b, j.point_b, True)
            d = [(pb, 1.0), (pa, -1.0)]
            va: dict[int, int] = {}
            vb: dict[int, int] = {}

            def A_(r: int, j: Joint = j, va: dict[int, int] = va) -> list[tuple[int, float]]:
                if r not in va:
                    va[r] = att(j.body_a, j.vectors_a[r], False)
                return [(va[r], 1.0)]

            def B_(r: int, j: Joint = j, vb: dict[int, int] = vb) -> list[tuple[int, float]]:
                if r not in vb:
                    vb[r] = att(j.body_b, j.vectors_b[r], False)
                return [(vb[r], 1.0)]

            kind = j.kind
            if kind in ("spherical", "revolute", "universal", "weld"):
                for c in range(3):
                    rows.append(([(att(GROUND, np.eye(3)[c], False), 1.0)], d))
            if kind in ("revolute", "cylindrical", "prismatic"):
                rows.append((A_(1), B_(0)))
                rows.append((A_(2), B_(0)))
            if kind in ("cylindrical", "prismatic"):
                rows.append((A_(1), d))
                rows.append((A_(2), d))
            if kind == "prismatic":
                rows.append((A_(1), B_(2)))
            if kind == "universal":
                rows.append((A_(0), B_(0)))
            if kind == "weld":
                rows.append((A_(0), B_(1)))
                rows.append((A_(1), B_(2)))
                rows.append((A_(2), B_(0)))
            if kind in ("point_on_plane", "contact"):
                rows.append((A_(0), d))
            if kind == "contact_tangent":  # t_i·(p_b − p_a): its rate is t_i·(slip velocity)
                rows.append((A_(0), d))
                rows.append((A_(1), d))
            if kind in ("path_driver", "coordinate_driver"):
                axes = np.eye(3) if kind == "path_driver" else j.vectors_a[:1]
                for c, ax in enumerate(axes):
                    rows.append(([(att(GROUND, ax, False), 1.0)], d))
                    drivers.append((len(motions), 0.0))
                    motions.append(j.motions[c])
            if kind in ("slide_driver", "slide_limit"):  # s (R_a u)·(p_b − p_a) − f(t)
                s = j.reference if kind == "slide_limit" else 1.0
                rows.append(([(A_(0)[0][0], s)], d))
                drivers.append((len(motions), 0.0))
                motions.append(j.motions[0])
            if kind in ("angle_driver", "angle_limit"):
                # φ = sin(θ − f) = cos f·P2 − sin f·P1 with P1 = (R_a f_a)·(R_b f_b) = cos θ and
                # P2 = (R_a g_a)·(R_b f_b) = sin θ: two auxiliary rows evaluated after the others.
                # A limit's side s = −1 flips P2 (θ → −θ) with f = −bound: sin(bound − θ).
                s = j.reference if kind == "angle_limit" else 1.0
                rows.append(([], []))
                drivers.append((-1, 0.0))
                angles.append((len(rows) - 1, len(motions), (A_(0), B_(0)), ([(A_(1)[0][0], s)], B_(0))))
                motions.append(j.motions[0])
            if kind == "distance_driver":
                half = 0.5 / j.reference
                rows.append(([(pb, half), (pa, -half)], d))
                drivers.append((len(motions), half))
                motions.append(j.motions[0])
            while len(drivers) < len(rows):
                drivers.append((-1, 0.0))
        n_main = len(rows)
        angle_rows: list[tuple[int, int, int, int]] = []
        for r_main, k_mot, aux1, aux2 in angles:
            rows.append(aux1)
            rows.append(aux2)
            drivers += [(-1, 0.0), (-1, 0.0)]
            angle_rows.append((r_main, len(rows) - 2, len(rows) - 1, k_mot))
        K = len(bodies)
        SX = np.zeros((len(rows), K))
        SY = np.zeros((len(rows), K))
        for r, (xs, ys) in enumerate(rows):
            for k, sgn in xs:
                SX[r, k] += sgn
            for k, sgn in ys:
                SY[r, k] += sgn
        body_arr = np.array(bodies, dtype=np.intp)
        t_row: list[int] = []
        t_att: list[int] = []
        t_sign: list[float] = []
        t_x: list[bool] = []
        for r, (xs, ys) in enumerate(rows):
            for terms, is_x in ((xs, True), (ys, False)):
                for k, sgn in terms:
                    t_row.append(r)
                    t_att.append(k)
                    t_sign.append(sgn)
                    t_x.append(is_x)
        term_row = np.array(t_row, dtype=np.intp)
        term_att = np.array(t_att, dtype=np.intp)
        base = term_row * (7 * (nb + 1)) + 7 * body_arr[term_att]
        return cls(
            att_body=body_arr,
            att_Q=np.array(Qs).reshape(K, 3, 4, 4),
            att_const=np.array(consts).reshape(K, 3),
            att_point=np.array(points),
            SX=SX,
            SY=SY,
            term_row=term_row,
            term_att=term_att,
            term_sign=np.array(t_sign, dtype=float),
            term_side_x=np.array(t_x, dtype=bool),
            term_index=(base[:, None] + np.arange(7)).ravel(),
            row_driver=np.array([dv for dv, _ in drivers], dtype=np.intp).reshape(len(rows)),
            row_square=np.array([sq for _, sq in drivers], dtype=float).reshape(len(rows)),
            motions=tuple(motions),
            n_main=n_main,
            angle_rows=tuple(angle_rows),
        )

    @staticmethod
    def active_rows(specs: tuple[ConstraintSpec, ...], act: frozenset[str]) -> NDArray[np.intp]:
        out: list[NDArray[np.intp]] = []
        r = 0
        for s in specs:
            if s.name in act:
                out.append(np.arange(r, r + s.dim))
            r += s.dim
        return np.concatenate(out) if out else np.zeros(0, dtype=np.intp)


#: Engine programs of live models (built on first use; not part of a model's value or pickle).
_ENGINE_PROGRAMS: weakref.WeakKeyDictionary[SpatialModel, Any] = weakref.WeakKeyDictionary()


@dataclass(frozen=True, eq=False)
class SpatialModel(Model):
    """Spatial multibody model with unit quaternions (build it with ``SpatialBuilder``).

    Parameters
    ----------
    name : str
    bodies : tuple of Body
    joints : tuple of Joint
    springs : tuple of Spring
    actuators : tuple of Actuator
    output_points : tuple of OutputPoint
    gravity : tuple of 3 floats
        Gravitational acceleration in the world frame.
    default_active_names : frozenset of str or None
        Active set of the nominal mode; None means every constraint.

    Notes
    -----
    Coordinate order: body by body, ``(x, y, z, e0, e1, e2, e3)``, named ``"<body>.x"``,
    ``"<body>.e0"`` ... Constraint order: the norm constraints ``"<body>.norm"`` (one row per
    body), then the joints in declaration order (all holonomic).
    """

    name: str
    bodies: tuple[Body, ...]
    joints: tuple[Joint, ...] = ()
    springs: tuple[Spring, ...] = ()
    actuators: tuple[Actuator, ...] = ()
    output_points: tuple[OutputPoint, ...] = ()
    gravity: tuple[float, float, float] = (0.0, 0.0, -9.81)
    default_active_names: frozenset[str] | None = None
    _index: dict[str, int] = field(init=False, repr=False, compare=False)
    _names: tuple[str, ...] = field(init=False, repr=False, compare=False)
    _specs: tuple[ConstraintSpec, ...] = field(init=False, repr=False, compare=False)
    _plan: _RowPlan = field(init=False, repr=False, compare=False)
    _mass: FloatArray = field(init=False, repr=False, compare=False)
    _inertia: FloatArray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        idx = {b.name: i for i, b in enumerate(self.bodies)}
        if len(idx) != len(self.bodies):
            raise ModelError(f"body names must be unique, got {[b.name for b in self.bodies]}")
        if not self.bodies:
            raise ModelError("a spatial model needs at least one body")

        for b in self.bodies:
            if not (np.isfinite(b.mass) and b.mass > 0.0):
                raise ModelError(f"body {b.name!r}: mass must be a finite number > 0, got {b.mass!r}")
            check_inertia(b.inertia, f"body {b.name!r}: inertia")
        object.__setattr__(self, "_index", idx)
        object.__setattr__(
            self,
            "_names",
            tuple(
                f"{b.name}.{c}"
                for b in self.bodies
                for c in ("x", "y", "z", "e0", "e1", "e2", "e3")
            ),
        )
        norms = tuple(
            ConstraintSpec(f"{b.name}.norm", "holonomic", 1, "unit quaternion ½(‖ε‖² − 1)")
            for b in self.bodies
        )
        joints = tuple(ConstraintSpec(j.name, _spec_kind(j.kind), j.dim, f"{j.kind} {j.body_a}–{j.body_b}")
                       for j in self.joints)  # fmt: skip
        object.__setattr__(self, "_specs", norms + joints)
        for j in self.joints:
            self.body_index(j.body_a)
            self.body_index(j.body_b)
        names = self.constraint_names
        if len(set(names)) != len(names):
            raise ModelError(f"constraint names must be unique, got {list(names)}")
        jn = {j.name: j for j in self.joints}
        for a in self.actuators:
            if a.joint not in jn:
                raise UnknownNameError(
                    f"actuator {a.name!r}: unknown joint {a.joint!r}; known: {list(jn)}"
                )
        if self.default_active_names is not None:
            self.resolve_active(self.default_active_names)
        object.__setattr__(self, "_plan", _RowPlan.build(self))
        object.__setattr__(self, "_mass", np.array([b.mass for b in self.bodies], dtype=float))
        object.__setattr__(self, "_inertia", np.array([b.inertia for b in self.bodies], dtype=float))

    # ------------------------------------------------------------------ names and sizes
    @property
    def coordinate_names(self) -> tuple[str, ...]:  # type: ignore[override]
        return self._names

    @property
    def constraints(self) -> tuple[ConstraintSpec, ...]:  # type: ignore[override]
        return self._specs

    @property
    def n(self) -> int:
        return 7 * len(self.bodies)

    @property
    def actuator_names(self) -> tuple[str, ...]:  # type: ignore[override]
        return tuple(a.name for a in self.actuators)

    @property
    def default_active(self) -> frozenset[str]:  # type: ignore[override]
        if self.default_active_names is None:
            return frozenset(self.constraint_names)
        return frozenset(self.default_active_names)

    @property
    def friction_contacts(self) -> tuple[FrictionContact, ...]:
        """The frictional point contacts (:meth:`SpatialBuilder.add_contact`)."""
        return tuple(FrictionContact(j.contact, j.name, j.mu) for j in self.joints if j.kind == "contact_tangent")

    @property
    def body_names(self) -> tuple[str, ...]:
        """Names of the bodies, in coordinate order."""
        return tuple(b.name for b in self.bodies)

    @property
    def has_outputs(self) -> bool:  # type: ignore[override]
        return bool(self.output_points)

    def body_index(self, name: str) -> int:
        """Index of body ``name`` (−1 for :data:`GROUND`).

        Raises
        ------
        UnknownNameError
            If there is no such body.
        """
        if name == GROUND:
            return -1
        try:
            return self._index[name]
        except KeyError:
            raise UnknownNameError(
                f"unknown body {name!r}; known: {[GROUND, *self._index]}"
            ) from None

    def joint(self, name: str) -> Joint:
        """The joint called ``name`` (:class:`UnknownNameError` otherwise)."""
        for j in self.joints:
            if j.name == name:
                return j
        raise UnknownNameError(
            f"model {self.name!r} has no joint {name!r}; known: {[j.name for j in self.joints]}"
        )

    def reference_configuration(self) -> FloatArray:
        """The reference configuration ``q`` (body poses given to the builder), shape (n,).

        Every joint is satisfied there, because joints are defined from it.
        """
        return np.concatenate([np.concatenate((b.position, b.quaternion)) for b in self.bodies])

    # ------------------------------------------------------------------ kinematics
    def _kin(
        self,
        q: FloatArray,
        qd: FloatArray,
        body: str,
        local: FloatArray,
        point: bool,
        Qs: FloatArray | None = None,
    ) -> _Kin:
        """World point ``r + R s`` (point=True) or vector ``R s`` of body ``body``.

        ``Qs`` is the precomputed :func:`point_tensor` of ``local`` (computed if None).
        """
        n = self.n
        i = self.body_index(body)
        J = np.zeros((3, n))
        Jd = np.zeros((3, n))
        if i < 0:
            return _Kin(np.array(local, dtype=float), J, Jd)
        o = 7 * i
        e = q[o + 3 : o + 7]
        ed = qd[o + 3 : o + 7]
        if Qs is None:
            Qs = point_tensor(local)
        Qe = Qs @ e  # (3, 4)
        val = Qe @ e
        if point:
            val = val + q[o : o + 3]
            J[:, o : o + 3] = np.eye(3)
        J[:, o + 3 : o + 7] = 2.0 * Qe
        Jd[:, o + 3 : o + 7] = 2.0 * (Qs @ ed)
        return _Kin(val, J, Jd)

    def point_position(self, q: ArrayLike, body: str, point: ArrayLike) -> FloatArray:
        """World position of the body-frame point ``point`` (relative to the COM), shape (3,)."""
        qv = _as_vector(q, "q", self.n)
        return self._kin(qv, np.zeros(self.n), body, np.asarray(point, float), True).val

    def point_jacobian(self, q: ArrayLike, body: str, point: ArrayLike) -> FloatArray:
        """``∂p/∂q`` of a body point, shape (3, n)."""
        qv = _as_vector(q, "q", self.n)
        return self._kin(qv, np.zeros(self.n), body, np.asarray(point, float), True).J

    def rotation(self, q: ArrayLike, body: str) -> FloatArray:
        """Rotation matrix ``R(ε/‖ε‖)`` of a body, shape (3, 3)."""
        qv = _as_vector(q, "q", self.n)
        i = self.body_index(body)
        if i < 0:
            return np.eye(3)
        e = qv[7 * i + 3 : 7 * i + 7]
        return rotation_matrix(e / np.linalg.norm(e))

    def angular_velocity(self, q: ArrayLike, qd: ArrayLike, body: str, *, frame: str = "body") -> FloatArray:
        """Angular velocity ``ω' = 2 G ε̇`` (``frame="body"``) or ``ω = R ω'`` (``"world"``)."""
        qv = _as_vector(q, "q", self.n)
        v = _as_vector(qd, "qd", self.n)
        i = self.body_index(body)
        if i < 0:
            return np.zeros(3)
        e = qv[7 * i + 3 : 7 * i + 7]
        w = 2.0 * G_matrix(e) @ v[7 * i + 3 : 7 * i + 7]
        if frame == "body":
            return w
        if frame == "world":
            return rotation_matrix(e) @ w
        from ...errors import InputError

        raise InputError(f"frame must be 'body' or 'world', got {frame!r}")

    # ------------------------------------------------------------------ dynamics
    def _G_all(self, E: FloatArray) -> FloatArray:
        """``G(ε_i)`` of every body, shape (nb, 3, 4)."""
        e0, e1, e2, e3 = E.T
        return np.stack(
            [
                np.stack([-e1, e0, e3, -e2], axis=-1),
                np.stack([-e2, -e3, e0, e1], axis=-1),
                np.stack([-e3, e2, -e1, e0], axis=-1),
            ],
            axis=1,
        )

    def mass_matrix(self, q: ArrayLike) -> FloatArray:
        qv = _as_vector(q, "q", self.n)
        nb = len(self.bodies)
        G = self._G_all(qv.reshape(nb, 7)[:, 3:])
        Me = 4.0 * np.matmul(np.swapaxes(G, 1, 2), np.matmul(self._inertia, G))  # (nb, 4, 4)
        M = np.zeros((nb, 7, nb, 7))
        idx = np.arange(nb)
        M[idx, :3, idx, :3] = self._mass[:, None, None] * np.eye(3)
        M[idx, 3:, idx, 3:] = Me
        return M.reshape(self.n, self.n)

    def coriolis_matrix(self, q: ArrayLike, qd: ArrayLike) -> FloatArray:
        qv = _as_vector(q, "q", self.n)
        v = _as_vector(qd, "qd", self.n)
        C = np.zeros((self.n, self.n))
        for i, b in enumerate(self.bodies):
            o = 7 * i
            e = qv[o + 3 : o + 7]
            ed = v[o + 3 : o + 7]
            G = G_matrix(e)
            Cb = 4.0 * G_matrix(ed).T @ b.inertia @ G + 4.0 * H_matrix(b.inertia @ (G @ ed))
            C[o + 3 : o + 7, o + 3 : o + 7] = Cb
        return C

    def coriolis_force(self, q: ArrayLike, qd: ArrayLike) -> FloatArray:
        """``C q̇``; per body ``8 G(ε̇)ᵀ J G(ε) ε̇`` on the quaternion block."""
        qv = _as_vector(q, "q", self.n)
        v = _as_vector(qd, "qd", self.n)
        nb = len(self.bodies)
        G = self._G_all(qv.reshape(nb, 7)[:, 3:])
        Gd = self._G_all(v.reshape(nb, 7)[:, 3:])
        w = np.matmul(G, v.reshape(nb, 7)[:, 3:, None])  # ω'/2, (nb, 3, 1)
        out = np.zeros((nb, 7))
        out[:, 3:] = 8.0 * np.matmul(np.swapaxes(Gd, 1, 2), np.matmul(self._inertia, w))[..., 0]
        return out.reshape(self.n)

    def _spring_line(self, q: FloatArray, qd: FloatArray, s: Spring) -> tuple[_Kin, float]:
        pa = self._kin(q, qd, s.body_a, s.point_a, True)
        pb = self._kin(q, qd, s.body_b, s.point_b, True)
        d = _diff(pb, pa)
        return d, float(np.linalg.norm(d.val))

    def conservative_force(self, q: ArrayLike) -> FloatArray:
        qv = _as_vector(q, "q", self.n)
        f = np.zeros(self.n)
        g = np.asarray(self.gravity)
        for i, b in enumerate(self.bodies):
            f[7 * i : 7 * i + 3] = b.mass * g
        zero = np.zeros(self.n)
        for s in self.springs:
            d, ell = self._spring_line(qv, zero, s)
            if s.rest_length == 0.0:
                f -= s.stiffness * (d.val @ d.J)
            elif ell > 0.0:
                f -= s.stiffness * (ell - s.rest_length) / ell * (d.val @ d.J)
        return f

    def potential_energy(self, q: ArrayLike) -> float:
        qv = _as_vector(q, "q", self.n)
        g = np.asarray(self.gravity)
        V = -sum(b.mass * float(g @ qv[7 * i : 7 * i + 3]) for i, b in enumerate(self.bodies))
        zero = np.zeros(self.n)
        for s in self.springs:
            _, ell = self._spring_line(qv, zero, s)
            V += 0.5 * s.stiffness * (ell - s.rest_length) ** 2
        return float(V)

    def passive_force(self, t: float, q: ArrayLike, qd: ArrayLike) -> FloatArray:
        """Spring dampers: ``−c ℓ̇`` along the line of each spring (zero where ℓ = 0)."""
        qv = _as_vector(q, "q", self.n)
        v = _as_vector(qd, "qd", self.n)
        f = np.zeros(self.n)
        for s in self.springs:
            if s.damping == 0.0:
                continue
            d, ell = self._spring_line(qv, v, s)
            if ell > 0.0:
                u = d.val / ell
                f -= s.damping * float(u @ (d.J @ v)) * (u @ d.J)
        return f

    def input_matrix(self, q: ArrayLike) -> FloatArray:
        qv = _as_vector(q, "q", self.n)
        zero = np.zeros(self.n)
        B = np.zeros((self.n, self.k))
        for c, a in enumerate(self.actuators):
            j = self.joint(a.joint)
            axis = self._kin(qv, zero, j.body_a, j.vectors_a[0], False)
            if a.dof == "rotation":
                # torque τ = u·axis on b, −τ on a; generalized force 2 E(ε)ᵀ τ per body
                # (virtual power τ·ω with ω = 2 E ε̇)
                for body, sign in ((j.body_b, 1.0), (j.body_a, -1.0)):
                    i = self.body_index(body)
                    if i < 0:
                        continue
                    o = 7 * i
                    B[o + 3 : o + 7, c] += sign * 2.0 * E_matrix(qv[o + 3 : o + 7]).T @ axis.val
            else:
                pa = self._kin(qv, zero, j.body_a, j.point_a, True)
                pb = self._kin(qv, zero, j.body_b, j.point_b, True)
                _, grad, _ = _dot(axis, _diff(pb, pa), zero)
                B[:, c] = grad
        return B

    # ------------------------------------------------------------------ constraints
    def _all_rows(
        self, q: FloatArray, qd: FloatArray, act: frozenset[str], t: float = 0.0
    ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """φ, A, Ȧ of the active rows (declaration order), shapes (m,), (m, n), (m, n), and
        the rheonomic additions to ``A q̇`` (φ_t) and to ``Ȧ q̇`` (the rest of γ), shape (2, m).
        Driver rows: φ holds ``− g(t)``; angle drivers' A depends on t, their Ȧ is the total
        derivative."""
        plan = self._plan
        nb = len(self.bodies)
        n = self.n
        Q7 = q.reshape(nb, 7)
        V7 = qd.reshape(nb, 7)
        # pad a zero "ground body" at index nb
        E = np.zeros((nb + 1, 4))
        Ed = np.zeros((nb + 1, 4))
        R = np.zeros((nb + 1, 3))
        Rd = np.zeros((nb + 1, 3))
        E[:nb], Ed[:nb] = Q7[:, 3:], V7[:, 3:]
        R[:nb], Rd[:nb] = Q7[:, :3], V7[:, :3]
        ek = E[plan.att_body]  # (K, 4)
        edk = Ed[plan.att_body]
        Qe = np.matmul(plan.att_Q, ek[:, None, :, None])[..., 0]  # (K, 3, 4)
        Qed = np.matmul(plan.att_Q, edk[:, None, :, None])[..., 0]
        pt = plan.att_point[:, None]
        val = np.matmul(Qe, ek[:, :, None])[..., 0] + pt * R[plan.att_body] + plan.att_const
        vel = 2.0 * np.matmul(Qe, edk[:, :, None])[..., 0] + pt * Rd[plan.att_body]
        K = val.shape[0]
        Jloc = np.zeros((K, 3, 7))
        Jloc[:, :, :3] = plan.att_point[:, None, None] * np.eye(3)
        Jloc[:, :, 3:] = 2.0 * Qe
        Jdloc = np.zeros((K, 3, 7))
        Jdloc[:, :, 3:] = 2.0 * Qed
        X, Y = plan.SX @ val, plan.SY @ val
        Xd, Yd = plan.SX @ vel, plan.SY @ vel
        # per term (row r, attachment k, sign σ, side): partner value and velocity
        side = plan.term_side_x[:, None]
        r = plan.term_row
        c = plan.term_sign[:, None] * np.where(side, Y[r], X[r])  # (T, 3)
        cd = plan.term_sign[:, None] * np.where(side, Yd[r], Xd[r])
        Jt = Jloc[plan.term_att]  # (T, 3, 7)
        Aloc = np.matmul(c[:, None, :], Jt)[:, 0, :]  # (T, 7)
        Adloc = np.matmul(cd[:, None, :], Jt)[:, 0, :] + np.matmul(
            c[:, None, :], Jdloc[plan.term_att]
        )[:, 0, :]
        rj = plan.SX.shape[0]
        width = 7 * (nb + 1)
        size = rj * width
        A_j: FloatArray = np.bincount(plan.term_index, Aloc.ravel(), size).reshape(rj, width)[:, :n]  # type: ignore[assignment]
        Ad_j: FloatArray = np.bincount(plan.term_index, Adloc.ravel(), size).reshape(rj, width)[:, :n]  # type: ignore[assignment]
        phi_j = np.einsum("ra,ra->r", X, Y)
        extra_j = np.zeros((2, plan.n_main))
        if plan.angle_rows:
            phi_j, A_j, Ad_j, extra_j = self._angle_rows(phi_j, A_j, Ad_j, qd, t)
        if plan.motions:
            g, gd, gdd = plan.driver_terms(t)
            phi_j = phi_j - g
            extra_j = extra_j - np.stack((gd, gdd))
        # norm rows
        A_n = np.zeros((nb, n))
        Ad_n = np.zeros((nb, n))
        idx = np.arange(nb)
        for c in range(4):
            A_n[idx, 7 * idx + 3 + c] = Q7[:, 3 + c]
            Ad_n[idx, 7 * idx + 3 + c] = V7[:, 3 + c]
        phi_n = 0.5 * (np.einsum("bj,bj->b", Q7[:, 3:], Q7[:, 3:]) - 1.0)
        phi = np.concatenate((phi_n, phi_j))
        A: FloatArray = np.vstack((A_n, A_j))
        Ad: FloatArray = np.vstack((Ad_n, Ad_j))
        extra = np.concatenate((np.zeros((2, nb)), extra_j), axis=1)
        if len(act) == len(self._specs):
            return phi, A, Ad, extra
        rows = plan.active_rows(self._specs, act)
        return phi[rows], A[rows], Ad[rows], extra[:, rows]

    def _angle_rows(
        self, phi_j: FloatArray, A_j: FloatArray, Ad_j: FloatArray, qd: FloatArray, t: float
    ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """Angle-driver rows from their auxiliary rows; drops the auxiliary rows.

        ``φ = c P2 − s P1`` (c, s = cos f, sin f), ``A = c A2 − s A1``, total
        ``Ȧ = c Ȧ2 − s Ȧ1 − ḟ (s A2 + c A1)``, ``φ_t = −ḟ S`` with ``S = s P2 + c P1`` and the
        rest of γ: ``−f̈ S − ḟ² (c P2 − s P1) − ḟ (s Ṗ2 + c Ṗ1)``.
        """
        plan = self._plan
        nm = plan.n_main
        extra = np.zeros((2, nm))  # velocity, γ additions of the main rows
        phi_j, A_j, Ad_j = phi_j.copy(), A_j.copy(), Ad_j.copy()
        for r, r1, r2, k in plan.angle_rows:
            f, fd, fdd = (float(x) for x in plan.motions[k](float(t)))
            c, s = np.cos(f), np.sin(f)
            P1, P2 = phi_j[r1], phi_j[r2]
            A1, A2 = A_j[r1], A_j[r2]
            v1, v2 = float(A1 @ qd), float(A2 @ qd)
            S = s * P2 + c * P1
            phi_j[r] = c * P2 - s * P1
            A_j[r] = c * A2 - s * A1
            Ad_j[r] = c * Ad_j[r2] - s * Ad_j[r1] - fd * (s * A2 + c * A1)
            extra[0, r] = -fd * S
            extra[1, r] = -fdd * S - fd * fd * (c * P2 - s * P1) - fd * (s * v2 + c * v1)
        return phi_j[:nm], A_j[:nm], Ad_j[:nm], extra

    def constraint_terms(
        self,
        t: float,
        q: ArrayLike,
        qd: ArrayLike,
        active: Iterable[str] | None = None,
    ) -> ConstraintTerms:
        act = self.resolve_active(active)
        qv = _as_vector(q, "q", self.n)
        v = _as_vector(qd, "qd", self.n)
        phi, A, Ad, extra = self._all_rows(qv, v, act, float(t))
        gamma = Ad @ v + extra[1]  # rheonomic rows: + the rest of γ
        vel = A @ v + extra[0]  # + φ_t
        return ConstraintTerms(
            A=A, gamma=gamma, phi=phi, velocity=vel, holonomic=np.ones(phi.shape[0], dtype=bool)
        )

    def constraint_jacobian_dot(
        self, t: float, q: ArrayLike, qd: ArrayLike, active: Iterable[str] | None = None
    ) -> FloatArray:
        """The exact matrix ``Ȧ = dA/dt`` (closed form), shape (m, n)."""
        act = self.resolve_active(active)
        qv = _as_vector(q, "q", self.n)
        v = _as_vector(qd, "qd", self.n)
        return self._all_rows(qv, v, act, float(t))[2]

    def engine_program(self) -> Any:
        """The compiled engine's ``SpatialProgram`` of this model (see
        :meth:`nonmin.model.Model.engine_program`), built once per model and cached."""
        prog = _ENGINE_PROGRAMS.get(self)
        if prog is None:
            from ._program import engine_program

            prog = engine_program(self)
            _ENGINE_PROGRAMS[self] = prog
        return prog

    # ------------------------------------------------------------------ extras
    def outputs(self, t: float, q: ArrayLike, qd: ArrayLike) -> dict[str, FloatArray]:
        """Position ``"<name>.position"`` and velocity ``"<name>.velocity"`` of each output point."""
        qv = _as_vector(q, "q", self.n)
        v = _as_vector(qd, "qd", self.n)
        out: dict[str, FloatArray] = {}
        for p in self.output_points:
            k = self._kin(qv, v, p.body, p.point, True)
            out[f"{p.name}.position"] = k.val
            out[f"{p.name}.velocity"] = k.J @ v
        return out

    def geometry(self, q: ArrayLike) -> Geometry:
        """Segments from each body's COM to its joint/spring/output points; body frames."""
        qv = _as_vector(q, "q", self.n)
        zero = np.zeros(self.n)
        segs: list[FloatArray] = []
        pts: list[FloatArray] = []
        labels: list[str] = []
        com = {b.name: qv[7 * i : 7 * i + 3] for i, b in enumerate(self.bodies)}

        def attach(body: str, local: FloatArray) -> FloatArray:
            p = self._kin(qv, zero, body, local, True).val
            if body != GROUND:
                segs.append(np.stack([com[body], p]))
            return p

        for j in self.joints:
            attach(j.body_a, j.point_a)
            pts.append(attach(j.body_b, j.point_b))
            labels.append(j.name)
        for s in self.springs:
            pa = attach(s.body_a, s.point_a)
            pb = attach(s.body_b, s.point_b)
            segs.append(np.stack([pa, pb]))
        for o in self.output_points:
            pts.append(attach(o.body, o.point))
            labels.append(o.name)
        frames = []
        for b in self.bodies:
            R = self.rotation(qv, b.name)
            frames.append(np.vstack([com[b.name], R.T]))
        return Geometry(
            dim=3,
            segments=np.array(segs).reshape(-1, 2, 3),
            points=np.array(pts).reshape(-1, 3),
            frames=np.array(frames).reshape(-1, 4, 3),
            labels=tuple(labels),
        )

    def replace(self, **changes: Any) -> SpatialModel:
        """A copy with some fields replaced (e.g. ``gravity=``, ``bodies=``); re-validated."""
        import dataclasses

        known = {f.name for f in dataclasses.fields(self) if f.init}
        unknown = set(changes) - known
        if unknown:
            from ...errors import InputError

            raise InputError(f"replace(): unknown field(s) {sorted(unknown)}; known: {sorted(known)}")
        return dataclasses.replace(self, **changes)
