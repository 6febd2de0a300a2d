"""The planar model compiled once to the engine's :class:`PlanarProgram` (plain-data description).

:func:`description` walks a :class:`~nonmin.model.planar.PlanarModel` and emits its bodies,
gravity, every constraint as row primitives (pin, line, rod, angle: the decomposition of
:mod:`._vectorized`), springs, dampers and actuators into a ``nonmin._engine.PlanarDescription``;
:func:`engine_program` builds the C++ ``PlanarProgram`` from it. The engine then evaluates M,
h, f_passive, B, A, γ, φ, the velocity residual and the energies for any active set (a mask
over the constraints) with no Python per evaluation, except a driver's motion given as a
plain Python callable (called back once per driver and evaluation; constant speed and the
time functions of :mod:`nonmin.model._timefn` — polynomials, splines, sampled arrays,
expressions — are data).

Formulas: those of :mod:`._elements` (the per-joint reference); ``tests/model/
test_planar_program.py`` demands agreement with :meth:`PlanarModel.evaluate` to round-off.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, Protocol

from ... import _engine  # type: ignore[attr-defined]  # the compiled extension (no stubs)
from .._timefn import Callback, TimeFunction
from ._elements import (
    GROUND,
    AngleDriver,
    AngleLimit,
    ContactTangent,
    CoordinateDriver,
    DistanceDriver,
    Gear,
    JointActuator,
    PathDriver,
    Point,
    PointOnLine,
    Prismatic,
    Revolute,
    Rod,
    RotationalSpring,
    SlideDriver,
    Spring,
    Torque,
    Weld,
)


class PlanarModelLike(Protocol):
    """What the compiler reads of a :class:`~nonmin.model.planar.PlanarModel` (this module
    sits below the model and does not import it)."""

    @property
    def gravity(self) -> Any: ...
    @property
    def bodies(self) -> Sequence[Any]: ...
    @property
    def joints(self) -> Sequence[Any]: ...
    @property
    def forces(self) -> Sequence[Any]: ...
    @property
    def actuators(self) -> Sequence[Any]: ...

    @property
    def n(self) -> int: ...

    @property
    def _index(self) -> Mapping[str, tuple[int, int, int]]: ...

__all__ = ["description", "engine_program"]

#: ``nonmin._engine.ConstraintKind`` values of the protocol's kinds.
KIND_CODES = {"holonomic": 0, "rheonomic": 1, "nonholonomic": 2, "unilateral": 3}


def description(model: PlanarModelLike) -> Any | None:
    """The engine description of ``model``, or None if a joint is user-defined (a
    :class:`~nonmin.model.planar.Joint` subclass the compiler does not know: its
    :meth:`Joint.terms` is Python)."""
    d = _engine.PlanarDescription()
    d.set_gravity(*model.gravity)
    index: dict[str, int] = {}
    for b in model.bodies:
        index[b.name] = d.add_body(b.mass, -1.0 if b.inertia is None else b.inertia)
    if d.n != model.n:  # coordinate order is the model's: body by body, (x, y[, θ])
        raise AssertionError(f"planar description has {d.n} coordinates, model {model.n}")

    def body(name: str) -> int:
        return -1 if name == GROUND else index[name]

    def pt(p: Point) -> tuple[int, float, float]:
        return (body(p.body), p.local[0], p.local[1])

    def driver(prof: Any) -> int:
        """Engine index of a prescribed motion: constant speed and time functions as data,
        other callables as a Python callback."""
        if isinstance(prof, TimeFunction) and not isinstance(prof, Callback):
            return int(d.add_driver_function(prof.engine()))
        return int(d.add_driver_callback(prof))

    for j in model.joints:
        c = d.add_constraint(j.name, KIND_CODES[j.kind], j.dim)
        tj = type(j)
        if tj is Revolute:
            assert isinstance(j, Revolute)
            d.add_pin(c, 0, pt(j.a), pt(j.b))
        elif tj is Weld:
            assert isinstance(j, Weld)
            d.add_pin(c, 0, pt(j.a), pt(j.b))
            d.add_angle(c, 2, [body(j.b.body), body(j.a.body)], [1.0, -1.0], j.angle)
        elif tj is PointOnLine:
            assert isinstance(j, PointOnLine)
            d.add_line(c, 0, pt(j.a), j.axis[0], j.axis[1], pt(j.b))
        elif tj is ContactTangent:
            assert isinstance(j, ContactTangent)
            d.add_line(c, 0, pt(j.a), j.axis[1], -j.axis[0], pt(j.b), j.roll)
        elif tj is Prismatic:
            assert isinstance(j, Prismatic)
            d.add_angle(c, 0, [body(j.b.body), body(j.a.body)], [1.0, -1.0], j.angle)
            d.add_line(c, 1, pt(j.a), j.axis[0], j.axis[1], pt(j.b))
        elif tj is Rod:
            assert isinstance(j, Rod)
            d.add_rod(c, 0, pt(j.a), pt(j.b), j.length, -1.0 if j.unilateral else 1.0)
        elif tj is Gear:
            assert isinstance(j, Gear)
            d.add_angle(
                c, 0, [body(j.body_b), body(j.carrier), body(j.body_a)],
                [1.0, -1.0 + j.ratio, -j.ratio], j.offset,
            )  # fmt: skip
        elif tj is AngleLimit:
            assert isinstance(j, AngleLimit)  # s (θ_b − θ_a) − s·bound
            d.add_angle(c, 0, [body(j.body_b), body(j.body_a)], [j.sign, -j.sign], j.sign * j.bound)
        elif tj is AngleDriver:
            assert isinstance(j, AngleDriver)
            d.add_angle(c, 0, [body(j.body_b), body(j.body_a)], [1.0, -1.0], 0.0, driver(j.profile))
        elif tj is CoordinateDriver:
            assert isinstance(j, CoordinateDriver)
            i = model._index[j.body][("x", "y", "theta").index(j.coordinate)]
            d.add_coord(c, 0, [i], [1.0], 0.0, driver(j.profile))
        elif tj is DistanceDriver:
            assert isinstance(j, DistanceDriver)
            d.add_rod(c, 0, pt(j.a), pt(j.b), j.reference, 1.0)
            d.set_drivers(-1, driver(j.profile))
        elif tj is SlideDriver:
            assert isinstance(j, SlideDriver)
            d.add_line(c, 0, pt(j.a), j.line_axis[0], j.line_axis[1], pt(j.b))
            d.set_drivers(-1, driver(j.profile))
        elif tj is PathDriver:
            assert isinstance(j, PathDriver)
            d.add_pin(c, 0, pt(j.a), (-1, 0.0, 0.0))
            d.set_drivers(-1, driver(j.x), driver(j.y))
        else:
            return None
    for fe in model.forces:
        if isinstance(fe, Spring):
            d.add_spring(pt(fe.a), pt(fe.b), fe.stiffness, fe.rest_length, fe.damping)
        else:
            assert isinstance(fe, RotationalSpring)
            d.add_rotational_spring(body(fe.body_a), body(fe.body_b), fe.stiffness, fe.rest_angle,
                                    fe.damping)  # fmt: skip
    jmap = {j.name: j for j in model.joints}
    for act in model.actuators:
        if isinstance(act, Torque):
            d.add_torque(body(act.body_a), body(act.body_b))
        elif isinstance(act, JointActuator):
            jt = jmap[act.joint]
            if isinstance(jt, Prismatic):
                d.add_prismatic_actuator(pt(jt.a), jt.axis[0], jt.axis[1], pt(jt.b))
            else:
                assert isinstance(jt, Revolute)
                d.add_torque(body(jt.a.body), body(jt.b.body))
        else:
            d.add_force(pt(act.point), float(act.direction[0]), float(act.direction[1]))
    return d


def engine_program(model: PlanarModelLike) -> Any | None:
    """The engine's ``PlanarProgram`` of ``model`` (all constraints; the active set is a mask
    given to each evaluation), or None when a joint is user-defined."""
    d = description(model)
    return None if d is None else _engine.PlanarProgram(d)
