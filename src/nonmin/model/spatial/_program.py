"""The spatial quaternion model compiled once to the engine's ``SpatialProgram``.

:func:`description` emits a :class:`~nonmin.model.spatial.SpatialModel` as plain data: bodies
(mass, body-frame inertia), gravity, the world-frame attachments of its row plan (body points
``r + R(ε) s`` and vectors ``R(ε) s`` given by their point tensors ``Q(s)``, constants on the
ground), one norm row per body, every joint row as ``φ = X·Y`` over attachments (the
decomposition of ``_model._RowPlan``), the spring-dampers and the joint actuators. The C++
program evaluates M, h = f_g − C q̇, f_passive, B, A, γ, φ, the velocity residual and the
energies for any active mask with no Python (formulas in ``engine/include/nonmin/spatial.hpp``).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Protocol

import numpy as np

from ... import _engine  # type: ignore[attr-defined]  # the compiled extension (no stubs)
from ._quaternion import point_tensor


class SpatialModelLike(Protocol):
    """What the compiler reads of a :class:`~nonmin.model.spatial.SpatialModel` (this module
    sits below the model and does not import it)."""

    @property
    def gravity(self) -> Any: ...
    @property
    def bodies(self) -> Sequence[Any]: ...
    @property
    def springs(self) -> Sequence[Any]: ...
    @property
    def actuators(self) -> Sequence[Any]: ...
    @property
    def _plan(self) -> Any: ...

    @property
    def constraints(self) -> Sequence[Any]: ...

    def body_index(self, name: str) -> int: ...

    def joint(self, name: str) -> Any: ...

__all__ = ["description", "engine_program"]

_KIND_CODES = {"holonomic": 0, "rheonomic": 1, "nonholonomic": 2, "unilateral": 3}


def _engine_fn(motion: Any) -> Any:
    """The engine's TimeFunction of a driver's motion."""
    return motion.engine()


def description(model: SpatialModelLike) -> Any:
    """The engine description (``nonmin._engine.SpatialDescription``) of ``model``."""
    d = _engine.SpatialDescription()
    d.set_gravity(tuple(float(g) for g in model.gravity))
    for b in model.bodies:
        d.add_body(float(b.mass), tuple(float(x) for x in np.asarray(b.inertia, dtype=float).ravel()))
    nb = len(model.bodies)
    plan = model._plan
    zero_q = np.zeros(48)
    att: list[int] = []
    for k in range(plan.att_body.shape[0]):
        body = int(plan.att_body[k])
        if body == nb:
            att.append(d.add_attachment(-1, False, zero_q, tuple(float(x) for x in plan.att_const[k])))
        else:
            att.append(d.add_attachment(body, bool(plan.att_point[k] > 0.0),
                                        np.ascontiguousarray(plan.att_Q[k], dtype=float).ravel(),
                                        (0.0, 0.0, 0.0)))  # fmt: skip

    def attachment(body: str, local: Any, point: bool) -> int:
        i = model.body_index(body)
        loc = np.asarray(local, dtype=float).reshape(3)
        if i < 0:
            return int(d.add_attachment(-1, False, zero_q, tuple(float(x) for x in loc)))
        return int(d.add_attachment(i, point, point_tensor(loc).ravel(), (0.0, 0.0, 0.0)))

    specs = model.constraints
    for i in range(nb):
        c = d.add_constraint(specs[i].name, _KIND_CODES[specs[i].kind], 1)
        d.add_norm_row(c, 0, i)
    def terms(r: int) -> tuple[list[tuple[int, float]], list[tuple[int, float]]]:
        xs = [(att[k], float(plan.SX[r, k])) for k in np.flatnonzero(plan.SX[r])]
        ys = [(att[k], float(plan.SY[r, k])) for k in np.flatnonzero(plan.SY[r])]
        return xs, ys

    angle_of = {row: (r1, r2, k) for row, r1, r2, k in plan.angle_rows}
    r = 0
    for spec in specs[nb:]:
        c = d.add_constraint(spec.name, _KIND_CODES[spec.kind], spec.dim)
        for off in range(spec.dim):
            if r in angle_of:
                r1, r2, k = angle_of[r]
                d.add_angle_row(c, off, *terms(r1), *terms(r2), int(d.add_driver(_engine_fn(plan.motions[k]))))
                r += 1
                continue
            xs, ys = terms(r)
            d.add_dot_row(c, off, xs, ys)
            k = int(plan.row_driver[r])
            if k >= 0:
                d.set_row_driver(int(d.add_driver(_engine_fn(plan.motions[k]))), float(plan.row_square[r]))
            r += 1
    for s in model.springs:
        d.add_spring(attachment(s.body_a, s.point_a, True), attachment(s.body_b, s.point_b, True),
                     float(s.stiffness), float(s.rest_length), float(s.damping))  # fmt: skip
    for a in model.actuators:
        j = model.joint(a.joint)
        axis = attachment(j.body_a, j.vectors_a[0], False)
        if a.dof == "rotation":
            d.add_rotation_actuator(axis, model.body_index(j.body_a), model.body_index(j.body_b))
        else:
            d.add_translation_actuator(axis, attachment(j.body_a, j.point_a, True),
                                       attachment(j.body_b, j.point_b, True))  # fmt: skip
    return d


def engine_program(model: SpatialModelLike) -> Any:
    """The engine's ``SpatialProgram`` of ``model`` (every constraint; the active set is a mask
    given to each evaluation)."""
    return _engine.SpatialProgram(description(model))
