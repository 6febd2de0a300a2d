"""The planar multibody model (an immutable :class:`~nonmin.model.Model`)."""

from __future__ import annotations

import math
import weakref
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from ..._validation import as_float_array
from ...errors import InputError, ModelError, NonFiniteError, ShapeError, UnknownNameError
from .._protocol import (
    ConstraintSpec,
    ConstraintTerms,
    FloatArray,
    FrictionContact,
    Geometry,
    Model,
    ModelTerms,
)
from . import _vectorized
from ._elements import (
    GROUND,
    Body,
    ContactTangent,
    Joint,
    JointActuator,
    Point,
    PointForce,
    Prismatic,
    Revolute,
    RotationalSpring,
    Spring,
    Torque,
    Weld,
    _Kin,
)

__all__ = ["PlanarModel"]

#: Active-set layouts kept per model (cleared when exceeded; a run uses a handful).
_MAX_LAYOUTS = 256

#: Engine programs of live models (built on first use; not part of a model's value or pickle).
_ENGINE_PROGRAMS: weakref.WeakKeyDictionary[PlanarModel, Any] = weakref.WeakKeyDictionary()
_MISSING = object()

Actuator = JointActuator | PointForce | Torque
ForceElement = Spring | RotationalSpring
OutputsFn = Callable[["PlanarModel", float, FloatArray, FloatArray], Mapping[str, ArrayLike]]


def _vec(x: ArrayLike, name: str, n: int) -> FloatArray:
    arr = np.asarray(x, dtype=np.float64)
    if arr.shape != (n,):
        raise ShapeError(f"{name} must have shape ({n},), got shape {arr.shape}")
    if not np.isfinite(arr).all():
        raise NonFiniteError(f"{name} must be finite")
    return arr


@dataclass(frozen=True, eq=False)
class PlanarModel(Model):
    """Planar multibody system in absolute coordinates ``(x, y, θ)`` per body.

    Build it with :class:`~nonmin.model.planar.PlanarBuilder`. ``M = diag(m, m, I)`` per body
    (``diag(m, m)`` for a point mass) is constant, so the Christoffel matrix ``C`` is zero.
    Constraints (joints) are named; each is holonomic, rheonomic (drivers) or unilateral, and
    which of them are active is data (``active`` argument of every evaluation).

    Evaluation is vectorized (:mod:`._vectorized`): the joints are decomposed into row primitives
    with index arrays when the model is built, and the row layout of each active set is cached
    (per frozenset, in a field that is neither compared nor part of the model's value), so
    :meth:`evaluate` and :meth:`constraint_terms` validate the state once and run a handful of
    array operations. Constant
    parts (M, gravity, constant columns of B) are computed once; every call returns new arrays.
    The per-joint formulas of :meth:`Joint.terms` remain the reference (``_reference_*``
    methods; tests demand agreement to 1e-13). The compiled engine evaluates the same model
    from a plain-data description in C++ (:meth:`engine_program`, ``planar/_program.py``),
    agreeing with :meth:`evaluate` to round-off.

    Attributes
    ----------
    name : str
    bodies : tuple of Body
        In coordinate order; body ``i`` owns coordinates ``(x_i, y_i[, θ_i])``.
    joints : tuple of Joint
        Constraints in row order.
    points : tuple of (str, Point)
        Named points (outputs, geometry).
    forces : tuple of Spring or RotationalSpring
    actuators : tuple of JointActuator, PointForce or Torque
        Columns of B, in order.
    gravity : (float, float)
        Gravitational acceleration (m/s²), e.g. ``(0, -9.81)``.
    default_active_names : frozenset of str
    output_points : tuple of str
        Named points whose position and velocity :meth:`outputs` returns
        (keys ``"<point>.position"``, ``"<point>.velocity"``).
    outputs_fn : callable ``(model, t, q, qd) -> dict``, optional
        Extra outputs (merged into :meth:`outputs`).
    description : str
    """

    name: str
    bodies: tuple[Body, ...]
    joints: tuple[Joint, ...] = ()
    points: tuple[tuple[str, Point], ...] = ()
    forces: tuple[ForceElement, ...] = ()
    actuators: tuple[Actuator, ...] = ()
    gravity: tuple[float, float] = (0.0, -9.81)
    default_active_names: frozenset[str] | None = None
    output_points: tuple[str, ...] = ()
    outputs_fn: OutputsFn | None = None
    description: str = ""
    _index: dict[str, tuple[int, int, int]] = field(init=False, repr=False, compare=False)
    _mdiag: FloatArray = field(init=False, repr=False, compare=False)
    _point_map: dict[str, Point] = field(init=False, repr=False, compare=False)
    # compiled evaluation (built once; caches are not compared and hold no state of a run)
    _plan: _vectorized.Plan = field(init=False, repr=False, compare=False)
    _layouts: dict[frozenset[str], _vectorized.Layout] = field(init=False, repr=False, compare=False)
    _constraints: tuple[ConstraintSpec, ...] = field(init=False, repr=False, compare=False)
    _friction_contacts: tuple[FrictionContact, ...] = field(init=False, repr=False, compare=False)
    _coordinate_names: tuple[str, ...] = field(init=False, repr=False, compare=False)
    _M: FloatArray = field(init=False, repr=False, compare=False)
    _fg: FloatArray = field(init=False, repr=False, compare=False)
    _forces_c: _vectorized.Forces = field(init=False, repr=False, compare=False)
    _inputs: _vectorized.Inputs = field(init=False, repr=False, compare=False)
    _stiff: bool = field(init=False, repr=False, compare=False)
    _damped: bool = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        s = object.__setattr__
        if not self.bodies:
            raise ModelError("a planar model needs at least one body")
        index: dict[str, tuple[int, int, int]] = {}
        mdiag: list[float] = []
        off = 0
        for b in self.bodies:
            if not isinstance(b, Body):
                raise InputError(f"bodies must be Body values, got {type(b).__name__}")
            if b.name in index:
                raise ModelError(f"duplicate body name {b.name!r}")
            if b.inertia is None:
                index[b.name] = (off, off + 1, -1)
                mdiag += [b.mass, b.mass]
            else:
                index[b.name] = (off, off + 1, off + 2)
                mdiag += [b.mass, b.mass, b.inertia]
            off += b.ncoords
        s(self, "_index", index)
        s(self, "_mdiag", np.array(mdiag))
        try:
            g = as_float_array(self.gravity, "gravity")
        except InputError:
            g = np.full(1, np.nan)
        if g.shape != (2,) or not np.isfinite(g).all():
            raise InputError(f"gravity must be a finite 2-vector, got {self.gravity!r}")
        s(self, "gravity", (float(g[0]), float(g[1])))

        known = set(index) | {GROUND}

        def check_body(body: str, where: str) -> None:
            if body not in known:
                raise UnknownNameError(
                    f"{where}: unknown body {body!r}; known bodies: {sorted(known)}"
                )

        def check_point(p: Point, where: str) -> None:
            check_body(p.body, where)
            if p.body != GROUND and index[p.body][2] < 0 and p.local != (0.0, 0.0):
                raise ModelError(
                    f"{where}: body {p.body!r} is a point mass; its points must be at its "
                    f"origin (0, 0), got {p.local}"
                )

        names: set[str] = set()
        for j in self.joints:
            if j.name in names:
                raise ModelError(f"duplicate constraint name {j.name!r}")
            names.add(j.name)
            where = f"joint {j.name!r}"
            for attr in ("a", "b"):
                p = getattr(j, attr, None)
                if isinstance(p, Point):
                    check_point(p, where)
            for body in j.bodies:
                check_body(body, where)
            for body in j.needs_angle():
                if body != GROUND and index[body][2] < 0:
                    raise ModelError(
                        f"{where} ({type(j).__name__}) needs the rotation of body {body!r}, "
                        "which is a point mass"
                    )
        pmap: dict[str, Point] = {}
        for pname, p in self.points:
            if pname in pmap:
                raise ModelError(f"duplicate point name {pname!r}")
            check_point(p, f"point {pname!r}")
            pmap[pname] = p
        s(self, "_point_map", pmap)
        for pname in self.output_points:
            if pname not in pmap:
                raise UnknownNameError(f"output_points: unknown point {pname!r}; known: {sorted(pmap)}")
        fnames: set[str] = set()
        for fe in self.forces:
            if fe.name in fnames:
                raise ModelError(f"duplicate force element name {fe.name!r}")
            fnames.add(fe.name)
            if isinstance(fe, Spring):
                check_point(fe.a, f"spring {fe.name!r}")
                check_point(fe.b, f"spring {fe.name!r}")
            else:
                for body in (fe.body_a, fe.body_b):
                    check_body(body, f"rotational spring {fe.name!r}")
                    if body != GROUND and index[body][2] < 0:
                        raise ModelError(f"rotational spring {fe.name!r}: body {body!r} is a point mass")
        anames: set[str] = set()
        jmap = {j.name: j for j in self.joints}
        for act in self.actuators:
            if act.name in anames:
                raise ModelError(f"duplicate actuator name {act.name!r}")
            anames.add(act.name)
            if isinstance(act, JointActuator):
                if act.joint not in jmap:
                    raise UnknownNameError(
                        f"actuator {act.name!r}: unknown joint {act.joint!r}; known: {sorted(jmap)}"
                    )
                jt = jmap[act.joint]
                if not isinstance(jt, Revolute | Prismatic):
                    raise ModelError(
                        f"actuator {act.name!r}: joint {act.joint!r} must be revolute or prismatic, "
                        f"got {type(jt).__name__}"
                    )
                if isinstance(jt, Revolute):
                    for body in jt.bodies:
                        if body != GROUND and index[body][2] < 0:
                            raise ModelError(
                                f"actuator {act.name!r}: a torque needs rotating bodies; "
                                f"{body!r} is a point mass"
                            )
            elif isinstance(act, Torque):
                for body in (act.body_a, act.body_b):
                    check_body(body, f"actuator {act.name!r}")
                    if body != GROUND and index[body][2] < 0:
                        raise ModelError(f"actuator {act.name!r}: body {body!r} is a point mass")
            else:
                check_point(act.point, f"actuator {act.name!r}")
        s(self, "_constraints", tuple(ConstraintSpec(j.name, j.kind, j.dim, j.describe()) for j in self.joints))
        s(self, "_friction_contacts", tuple(
            FrictionContact(j.normal, j.name, j.mu) for j in self.joints if isinstance(j, ContactTangent)
        ))  # fmt: skip
        cnames: list[str] = []
        for b in self.bodies:
            cnames += [f"{b.name}.x", f"{b.name}.y"]
            if b.inertia is not None:
                cnames.append(f"{b.name}.theta")
        s(self, "_coordinate_names", tuple(cnames))
        s(self, "_plan", _vectorized.Plan(self.joints, index, off))
        s(self, "_layouts", {})
        M = np.diag(self._mdiag)
        M.flags.writeable = False
        s(self, "_M", M)
        fg = self._gravity_force()
        fg.flags.writeable = False
        s(self, "_fg", fg)
        s(self, "_stiff", any(fe.stiffness != 0.0 for fe in self.forces))
        s(self, "_damped", any(fe.damping != 0.0 for fe in self.forces))
        s(self, "_forces_c", _vectorized.Forces(
            [fe for fe in self.forces if isinstance(fe, Spring)],
            [fe for fe in self.forces if isinstance(fe, RotationalSpring)],
            index, off,
        ))  # fmt: skip
        s(self, "_inputs", self._compile_inputs())
        if self.default_active_names is None:
            dflt = frozenset(j.name for j in self.joints if j.kind != "unilateral")
            s(self, "default_active_names", dflt)
        else:
            s(self, "default_active_names", frozenset(self.default_active_names))
            self.resolve_active(self.default_active_names)

    # ------------------------------------------------------------------ protocol attributes
    @property
    def coordinate_names(self) -> tuple[str, ...]:  # type: ignore[override]
        return self._coordinate_names

    @property
    def n(self) -> int:
        return int(self._mdiag.shape[0])

    @property
    def constraints(self) -> tuple[ConstraintSpec, ...]:  # type: ignore[override]
        return self._constraints

    @property
    def actuator_names(self) -> tuple[str, ...]:  # type: ignore[override]
        return tuple(a.name for a in self.actuators)

    @property
    def default_active(self) -> frozenset[str]:  # type: ignore[override]
        return self.default_active_names or frozenset()

    @property
    def friction_contacts(self) -> tuple[FrictionContact, ...]:
        """The frictional contacts (:meth:`PlanarBuilder.contact`): one per
        :class:`ContactTangent` joint."""
        return self._friction_contacts

    @property
    def has_outputs(self) -> bool:  # type: ignore[override]
        return bool(self.output_points) or self.outputs_fn is not None

    # ------------------------------------------------------------------ names and indices
    def body(self, name: str) -> Body:
        """The :class:`Body` called ``name``."""
        for b in self.bodies:
            if b.name == name:
                return b
        raise UnknownNameError(f"model {self.name!r} has no body {name!r}; known: {[b.name for b in self.bodies]}")

    def body_slice(self, name: str) -> slice:
        """Coordinates of a body: ``q[model.body_slice("crank")]`` is ``(x, y, θ)``."""
        if name not in self._index:
            raise UnknownNameError(f"model {self.name!r} has no body {name!r}; known: {sorted(self._index)}")
        ix, _, ith = self._index[name]
        return slice(ix, (ith if ith >= 0 else ix + 1) + 1)

    def joint(self, name: str) -> Joint:
        """The joint (constraint) called ``name``."""
        for j in self.joints:
            if j.name == name:
                return j
        raise UnknownNameError(f"model {self.name!r} has no joint {name!r}; known: {list(self.constraint_names)}")

    @property
    def point_names(self) -> tuple[str, ...]:
        return tuple(p for p, _ in self.points)

    def _point(self, name: str) -> Point:
        try:
            return self._point_map[name]
        except KeyError:
            raise UnknownNameError(
                f"model {self.name!r} has no point {name!r}; known: {list(self._point_map)}"
            ) from None

    def _kin(self, q: ArrayLike, qd: ArrayLike | None = None) -> _Kin:
        qv = _vec(q, "q", self.n)
        v = np.zeros(self.n) if qd is None else _vec(qd, "qd", self.n)
        return _Kin(self, qv, v)

    # ------------------------------------------------------------------ kinematic outputs
    def point_position(self, name: str, q: ArrayLike) -> FloatArray:
        """Global position of the named point, shape (2,)."""
        return self._kin(q).point(self._point(name))[0]

    def point_velocity(self, name: str, q: ArrayLike, qd: ArrayLike) -> FloatArray:
        """Global velocity of the named point, shape (2,)."""
        return self._kin(q, qd).point(self._point(name))[2]

    def point_jacobian(self, name: str, q: ArrayLike) -> FloatArray:
        """``∂p/∂q`` of the named point, shape (2, n)."""
        kin = self._kin(q)
        p = self._point(name)
        _, rs, _, _ = kin.point(p)
        J = np.zeros((2, self.n))
        kin.add_jac(J, p.body, rs, 1.0)
        return J

    def joint_angle(self, name: str, q: ArrayLike, qd: ArrayLike | None = None) -> tuple[float, float]:
        """Relative angle ``θ_b − θ_a`` of a revolute/weld joint and its rate."""
        j = self.joint(name)
        if not isinstance(j, Revolute | Weld):
            raise ModelError(f"joint {name!r} is a {type(j).__name__}, not a revolute joint")
        kin = self._kin(q, qd)
        tha, oma = kin.angle(j.a.body)
        thb, omb = kin.angle(j.b.body)
        return thb - tha, omb - oma

    # ------------------------------------------------------------------ dynamics
    def mass_matrix(self, q: ArrayLike) -> FloatArray:
        _vec(q, "q", self.n)  # constant M, but a (k, n) batch must not pass for one q
        return self._M.copy()

    def coriolis_matrix(self, q: ArrayLike, qd: ArrayLike) -> FloatArray:
        _vec(q, "q", self.n)
        _vec(qd, "qd", self.n)
        return np.zeros((self.n, self.n))

    def coriolis_force(self, q: ArrayLike, qd: ArrayLike) -> FloatArray:
        _vec(q, "q", self.n)
        _vec(qd, "qd", self.n)
        return np.zeros(self.n)

    def _gravity_force(self) -> FloatArray:
        f = np.zeros(self.n)
        gx, gy = self.gravity
        for b in self.bodies:
            ix, iy, _ = self._index[b.name]
            f[ix] = b.mass * gx
            f[iy] = b.mass * gy
        return f

    def _spring_geometry(self, kin: _Kin, sp: Spring) -> tuple[FloatArray, FloatArray, FloatArray]:
        """``(d, ḋ, D)`` with ``d = p_b − p_a``, ``D = ∂d/∂q``."""
        pa, rsa, va, _ = kin.point(sp.a)
        pb, rsb, vb, _ = kin.point(sp.b)
        D = np.zeros((2, self.n))
        kin.add_jac(D, sp.b.body, rsb, 1.0)
        kin.add_jac(D, sp.a.body, rsa, -1.0)
        return pb - pa, vb - va, D

    def conservative_force(self, q: ArrayLike) -> FloatArray:
        qv = _vec(q, "q", self.n)
        return self._forces_c.conservative(self._fg, qv) if self._stiff else self._fg.copy()

    def _reference_conservative_force(self, q: ArrayLike) -> FloatArray:
        """:meth:`conservative_force` element by element (reference for tests)."""
        kin = self._kin(q)
        f = self._gravity_force()
        for fe in self.forces:
            if fe.stiffness == 0.0:
                continue
            if isinstance(fe, Spring):
                d, _, D = self._spring_geometry(kin, fe)
                ell = float(np.hypot(d[0], d[1]))
                if ell > 0.0:
                    f -= fe.stiffness * (1.0 - fe.rest_length / ell) * (d @ D)
                elif fe.rest_length != 0.0:
                    raise ModelError(f"spring {fe.name!r}: zero length, force direction undefined")
            else:
                tha, _ = kin.angle(fe.body_a)
                thb, _ = kin.angle(fe.body_b)
                tau = -fe.stiffness * (thb - tha - fe.rest_angle)
                row = np.zeros((1, self.n))
                kin.add_angle(row, 0, fe.body_b, tau)
                kin.add_angle(row, 0, fe.body_a, -tau)
                f += row[0]
        return f

    def potential_energy(self, q: ArrayLike) -> float:
        qv = _vec(q, "q", self.n)
        V = -float(self._fg @ qv)
        return V + self._forces_c.potential(qv) if self._stiff else V

    def _reference_potential_energy(self, q: ArrayLike) -> float:
        """:meth:`potential_energy` element by element (reference for tests)."""
        kin = self._kin(q)
        V = -float(self._fg @ kin.q)
        for fe in self.forces:
            if fe.stiffness == 0.0:
                continue
            if isinstance(fe, Spring):
                d, _, _ = self._spring_geometry(kin, fe)
                ell = float(np.hypot(d[0], d[1]))
                V += 0.5 * fe.stiffness * (ell - fe.rest_length) ** 2
            else:
                tha, _ = kin.angle(fe.body_a)
                thb, _ = kin.angle(fe.body_b)
                V += 0.5 * fe.stiffness * (thb - tha - fe.rest_angle) ** 2
        return V

    def passive_force(self, t: float, q: ArrayLike, qd: ArrayLike) -> FloatArray:
        qv, v = self._state_arrays(q, qd)
        return self._forces_c.passive(qv, v) if self._damped else np.zeros(self.n)

    def _reference_passive_force(self, q: ArrayLike, qd: ArrayLike) -> FloatArray:
        """:meth:`passive_force` element by element (reference for tests)."""
        kin = self._kin(q, qd)
        f = np.zeros(self.n)
        for fe in self.forces:
            if fe.damping == 0.0:
                continue
            if isinstance(fe, Spring):
                d, dd, D = self._spring_geometry(kin, fe)
                ell2 = float(d @ d)
                if ell2 > 0.0:
                    # −c ℓ̇ Dᵀe with ℓ̇ = e·ḋ, e = d/ℓ
                    f -= fe.damping * float(d @ dd) / ell2 * (d @ D)
            else:
                _, oma = kin.angle(fe.body_a)
                _, omb = kin.angle(fe.body_b)
                tau = -fe.damping * (omb - oma)
                row = np.zeros((1, self.n))
                kin.add_angle(row, 0, fe.body_b, tau)
                kin.add_angle(row, 0, fe.body_a, -tau)
                f += row[0]
        return f

    def _compile_inputs(self) -> _vectorized.Inputs:
        """Constant entries of B and the index arrays of its q-dependent ones."""
        const: list[tuple[int, int, float]] = []
        forces: list[tuple[int, Point, tuple[float, float]]] = []
        prismatic: list[tuple[int, Point, Point, tuple[float, float]]] = []
        jmap = {j.name: j for j in self.joints}

        def torque(col: int, a: str, b: str) -> None:
            for body, sgn in ((b, 1.0), (a, -1.0)):
                if body != GROUND:
                    const.append((self._index[body][2], col, sgn))

        for col, act in enumerate(self.actuators):
            if isinstance(act, Torque):
                torque(col, act.body_a, act.body_b)
            elif isinstance(act, JointActuator):
                jt = jmap[act.joint]
                if isinstance(jt, Prismatic):
                    prismatic.append((col, jt.a, jt.b, jt.axis))
                else:
                    assert isinstance(jt, Revolute)
                    torque(col, jt.a.body, jt.b.body)
            else:
                d = (float(act.direction[0]), float(act.direction[1]))
                forces.append((col, act.point, d))
        return _vectorized.Inputs(const, forces, prismatic, self._index, self.n, self.k)

    def input_matrix(self, q: ArrayLike) -> FloatArray:
        return self._inputs.matrix(_vec(q, "q", self.n))

    def _reference_input_matrix(self, q: ArrayLike) -> FloatArray:
        """:meth:`input_matrix` element by element (reference for tests)."""
        kin = self._kin(q)
        B = np.zeros((self.n, self.k))
        jmap = {j.name: j for j in self.joints}
        for col, act in enumerate(self.actuators):
            row = np.zeros((1, self.n))
            if isinstance(act, Torque):
                kin.add_angle(row, 0, act.body_b, 1.0)
                kin.add_angle(row, 0, act.body_a, -1.0)
            elif isinstance(act, JointActuator):
                jt = jmap[act.joint]
                if isinstance(jt, Prismatic):
                    u = kin.rotate(jt.a.body, jt.axis)
                    pb, rsb, _, _ = kin.point(jt.b)
                    J = np.zeros((2, self.n))
                    kin.add_jac(J, jt.b.body, rsb, 1.0)
                    # reaction on body a, applied at the same global point p_b
                    xa, ya = kin._body(jt.a.body)[:2]
                    kin.add_jac(J, jt.a.body, pb - np.array([xa, ya]), -1.0)
                    row[0] = u @ J
                else:
                    assert isinstance(jt, Revolute)
                    kin.add_angle(row, 0, jt.b.body, 1.0)
                    kin.add_angle(row, 0, jt.a.body, -1.0)
            else:
                _, rs, _, _ = kin.point(act.point)
                J = np.zeros((2, self.n))
                kin.add_jac(J, act.point.body, rs, 1.0)
                row[0] = np.asarray(act.direction) @ J
            B[:, col] = row[0]
        return B

    # ------------------------------------------------------------------ constraints
    def _stack(
        self, t: float, kin: _Kin, active: Iterable[str] | None
    ) -> tuple[ConstraintTerms, FloatArray]:
        act = self.resolve_active(active)
        n = self.n
        sel = [j for j in self.joints if j.name in act]
        m = sum(j.dim for j in sel)
        if m == 0:
            e = np.zeros(0)
            return ConstraintTerms(np.zeros((0, n)), e, e.copy(), e.copy(), np.zeros(0, dtype=bool)), np.zeros((0, n))
        A = np.zeros((m, n))
        Ad = np.zeros((m, n))
        phi = np.zeros(m)
        gamma = np.zeros(m)
        phit = np.zeros(m)
        r = 0
        for j in sel:
            ph, Aj, Adj, gj, ptj = j.terms(kin, float(t))
            A[r : r + j.dim] = Aj
            Ad[r : r + j.dim] = Adj
            phi[r : r + j.dim] = ph
            gamma[r : r + j.dim] = gj
            phit[r : r + j.dim] = ptj
            r += j.dim
        return ConstraintTerms(A, gamma, phi, A @ kin.qd + phit, np.ones(m, dtype=bool)), Ad

    def _layout(self, active: Iterable[str] | None) -> _vectorized.Layout:
        """The compiled row layout of an active set (cached per frozenset)."""
        key = self.default_active if active is None else active
        lay = self._layouts.get(key) if type(key) is frozenset else None  # type: ignore[call-overload]
        if lay is None:
            act = super().resolve_active(key)
            lay = self._layouts.get(act)
            if lay is None:
                if len(self._layouts) >= _MAX_LAYOUTS:
                    self._layouts.clear()
                lay = self._plan.layout(act)
                self._layouts[act] = lay
        return lay

    def engine_program(self) -> Any | None:
        """The compiled engine's ``PlanarProgram`` of this model (see
        :meth:`nonmin.model.Model.engine_program`), built once per model and cached; None when a
        joint is user-defined (its :meth:`Joint.terms` is Python). It covers every constraint
        (the active set is a mask given to each evaluation), springs, dampers, drivers and B."""
        prog = _ENGINE_PROGRAMS.get(self, _MISSING)
        if prog is _MISSING:
            from ._program import engine_program

            prog = engine_program(self)
            _ENGINE_PROGRAMS[self] = prog
        return prog

    def _state_arrays(self, q: ArrayLike, qd: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """``q``, ``qd`` as float64 arrays of shape (n,), checked once (shape and finiteness)."""
        n = self.n
        qv = q if type(q) is np.ndarray and q.dtype == np.float64 else np.asarray(q, dtype=np.float64)
        v = qd if type(qd) is np.ndarray and qd.dtype == np.float64 else np.asarray(qd, dtype=np.float64)
        if qv.shape != (n,):
            raise ShapeError(f"q must have shape ({n},), got shape {qv.shape}")
        if v.shape != (n,):
            raise ShapeError(f"qd must have shape ({n},), got shape {v.shape}")
        # one cheap test; the exact one only when it fails (NaN/inf, or an overflow of finite values)
        if not math.isfinite(float(qv @ qv) + float(v @ v)):
            _vec(qv, "q", n)
            _vec(v, "qd", n)
        return qv, v

    def constraint_terms(
        self, t: float, q: ArrayLike, qd: ArrayLike, active: Iterable[str] | None = None
    ) -> ConstraintTerms:
        qv, v = self._state_arrays(q, qd)
        return _vectorized.constraint_terms(self, self._layout(active), t, qv, v)[0]

    def _reference_constraint_terms(
        self, t: float, q: ArrayLike, qd: ArrayLike, active: Iterable[str] | None = None
    ) -> ConstraintTerms:
        """:meth:`constraint_terms` from the per-joint formulas (:meth:`Joint.terms`), slow.

        The straightforward reference implementation against which the compiled evaluation is
        tested; same results up to round-off.
        """
        return self._stack(t, self._kin(q, qd), active)[0]

    def constraint_jacobian_dot(
        self, t: float, q: ArrayLike, qd: ArrayLike, active: Iterable[str] | None = None
    ) -> FloatArray:
        """Exact ``Ȧ`` along ``qd`` (closed form), shape (m, n)."""
        qv, v = self._state_arrays(q, qd)
        Ad = _vectorized.constraint_terms(self, self._layout(active), t, qv, v, adot=True)[1]
        assert Ad is not None
        return Ad

    def _reference_constraint_jacobian_dot(
        self, t: float, q: ArrayLike, qd: ArrayLike, active: Iterable[str] | None = None
    ) -> FloatArray:
        """:meth:`constraint_jacobian_dot` from the per-joint formulas (reference, slow)."""
        return self._stack(t, self._kin(q, qd), active)[1]

    def evaluate(
        self, t: float, q: ArrayLike, qd: ArrayLike, active: Iterable[str] | None = None
    ) -> ModelTerms:
        qv, v = self._state_arrays(q, qd)
        ct, M = _vectorized.constraint_terms_and_mass(self, self._layout(active), t, qv, v, self._M)
        return ModelTerms(
            M=M,
            h=self._forces_c.conservative(self._fg, qv) if self._stiff else self._fg.copy(),
            f_passive=self._forces_c.passive(qv, v) if self._damped else np.zeros(self.n),
            B=self._inputs.matrix(qv),
            constraints=ct,
        )

    # ------------------------------------------------------------------ outputs and geometry
    def outputs(self, t: float, q: ArrayLike, qd: ArrayLike) -> dict[str, FloatArray]:
        kin = self._kin(q, qd)
        out: dict[str, FloatArray] = {}
        for pname in self.output_points:
            pos, _, vel, _ = kin.point(self._point_map[pname])
            out[f"{pname}.position"] = pos
            out[f"{pname}.velocity"] = vel
        if self.outputs_fn is not None:
            for key, val in self.outputs_fn(self, float(t), kin.q, kin.qd).items():
                out[key] = np.asarray(val, dtype=float)
        return out

    def _body_points(self) -> dict[str, list[tuple[float, float]]]:
        pts: dict[str, list[tuple[float, float]]] = {b.name: [] for b in self.bodies}

        def add(p: Point) -> None:
            if p.body != GROUND and p.local not in pts[p.body]:
                pts[p.body].append(p.local)

        for j in self.joints:
            for attr in ("a", "b"):
                p = getattr(j, attr, None)
                if isinstance(p, Point):
                    add(p)
        for _, p in self.points:
            add(p)
        return pts

    def geometry(self, q: ArrayLike) -> Geometry:
        """Segments between each body's joint points (a polygon for three or more points)."""
        kin = self._kin(q)
        segs: list[FloatArray] = []
        for body, locs in self._body_points().items():
            glob = [kin.point(Point(body, s))[0] for s in locs]
            if len(glob) == 1:
                glob = [kin.point(Point(body, (0.0, 0.0)))[0], glob[0]]
            for i in range(len(glob) - 1 if len(glob) <= 2 else len(glob)):
                segs.append(np.array([glob[i], glob[(i + 1) % len(glob)]]))
        labels = tuple(self._point_map)
        pts = np.array([kin.point(p)[0] for p in self._point_map.values()]).reshape(-1, 2)
        return Geometry(
            dim=2,
            segments=np.array(segs).reshape(-1, 2, 2),
            points=pts,
            labels=labels,
        )

    def replace(self, **changes: Any) -> PlanarModel:
        """Copy with fields replaced (e.g. ``gravity=(0, 0)``, ``bodies=...``); re-validated."""
        import dataclasses

        allowed = {f.name for f in dataclasses.fields(self) if f.init}
        unknown = set(changes) - allowed
        if unknown:
            raise InputError(f"replace(): unknown field(s) {sorted(unknown)}; known: {sorted(allowed)}")
        return dataclasses.replace(self, **changes)
