"""Frictional contact mechanisms (Coulomb friction with stick–slip, issue #22)."""

from __future__ import annotations

import math

import numpy as np

from ..errors import InputError
from ..model.planar import PlanarBuilder
from ._registry import Mechanism, register

__all__ = ["foot_friction"]


@register("foot_friction")
def foot_friction(
    *,
    mu: float = 0.5,
    length: float = 0.3,
    height: float = 0.1,
    mass: float = 1.2,
    drop: float = 0.12,
    tilt: float = 0.35,
    vx: float = 1.5,
    vy: float = -0.5,
    spin: float = 0.0,
    g: float = 9.81,
    t_final: float = 1.5,
) -> Mechanism:
    """A rigid foot (a box) thrown onto the floor with Coulomb friction at heel and toe.

    Source: nonmin issue #22 (a foot making and breaking frictional contact). The box
    (``length`` × ``height``, uniform, ``mass``) has two frictional point contacts on the
    floor ``y = 0`` (:meth:`PlanarBuilder.contact`, coefficient ``mu``): ``heel`` and ``toe``
    (its lower corners), both open at the start. It starts with its centre ``drop`` above the
    lowest corner's contact height, tilted by ``tilt`` (heel down), moving at ``(vx, vy)`` and
    spinning at ``spin``: the heel lands (impact), slips, the foot rolls onto its toe, both
    corners slide and stick; with restitution the heel bounces (the contact opens and closes
    again). Outputs: ``heel.position``, ``toe.position`` and their velocities.
    """
    for name, v in (("mu", mu), ("length", length), ("height", height), ("mass", mass)):
        if not (math.isfinite(v) and v > 0.0):
            raise InputError(f"foot_friction: {name} must be a finite number > 0, got {v!r}")
    b = PlanarBuilder("foot_friction", gravity=(0.0, -float(g)),
                      description="a rigid foot landing on a floor with Coulomb friction at heel and toe")  # fmt: skip
    hl, hh = length / 2, height / 2
    b.body("foot", mass=mass, inertia=mass * (length**2 + height**2) / 12,
           points={"heel": (-hl, -hh), "toe": (hl, -hh)})  # fmt: skip
    for corner in ("heel", "toe"):
        b.contact(corner, ("ground", (0.0, 0.0)), corner, axis=(1.0, 0.0), friction=mu)
    b.output("heel", "toe")
    model = b.build()
    c, s = math.cos(tilt), math.sin(tilt)
    low = min(-hl * s - hh * c, hl * s - hh * c)  # the lowest corner's height above the centre
    q0 = np.array([0.0, drop - low, tilt])
    qd0 = np.array([vx, vy, spin])
    return Mechanism(
        model=model,
        state=model.state(q0, qd0, active=()),
        t_final=float(t_final),
        description="rigid foot landing heel first, slipping and sticking on a frictional floor",
        reference="nonmin issue #22 (Coulomb friction with stick-slip); docs/contact.md",
    )
