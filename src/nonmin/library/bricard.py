"""A04 — Bricard's mechanism: five rods, six revolute joints, one redundant constraint.

Source: IFToMM / A Coruña library of computational benchmark problems for multibody dynamics
(González, Dopico, Lugrís, Cuadrado, Multibody System Dynamics 16 (2006) 179–190), problem
A04; see ``shared/benchmarks/README.md``. Five rods, each 1 m, 1 kg, square cross-section
0.1 m (inertia about the centre: axial ``m a²/6``, transverse ``m (L² + a²)/12``); gravity
9.81 along −y; six revolute joints, the ground closing the loop:

=====  ==============  ====  ===============
joint  position        axis  connects
=====  ==============  ====  ===============
J1     (0, 0, 0)       y     ground – rod1
J2     (1, 0, 0)       z     rod1 – rod2
J3     (1, −1, 0)      x     rod2 – rod3
J4     (1, −1, 1)      y     rod3 – rod4
J5     (0, −1, 1)      z     rod4 – rod5
J6     (0, 0, 1)       x     rod5 – ground
=====  ==============  ====  ===============

Released from rest at that configuration; outputs ``P3.position`` (J3) and
``P3.velocity``. Built with the spatial (unit-quaternion) source: n = 35 coordinates,
m = 5 norm + 6 × 5 joint rows = 35 constraint rows of rank 34 along the motion (Grübler
counts 0 degrees of freedom, the mobility is 1: one row is redundant everywhere). nonmin
treats it like any other model: the rank-revealing projector absorbs the redundancy.

Rank tolerance in time integration: the redundancy is exact only *on* the constraint
manifold. At a point a distance ‖φ‖ off it (an explicit Runge–Kutta stage, typically
1e-9 .. 1e-6 m) the redundant singular value of A is about 0.04 ‖φ‖ σ_max, so with the default
cutoff (1e-10) the rank flips to m at the stages and the step-size control collapses
(measured: dopri5 at rtol 1e-9 needs 5599 steps and ~290 s for 1 s of motion). Pass a cutoff
above that noise, e.g. ``simulate(..., rank_rtol=1e-6)`` (69 steps, 2.2 s for 1 s; 575 steps,
15 s for the 10 s benchmark, closure 4e-16 m, energy drift 1.7e-9 J; 2 shared cores, load ~10).
"""

from __future__ import annotations

import numpy as np

from ..model import State
from ..model.spatial import SpatialBuilder, SpatialModel
from ._registry import Mechanism, register

__all__ = ["NAME", "a04_bricard", "bricard_model", "bricard_state"]

IFTOMM_REF = (
    "M. González, D. Dopico, U. Lugrís, J. Cuadrado, Multibody Syst. Dyn. 16 (2006) 179–190; "
    "IFToMM Library of Computational Benchmark Problems, problem A04 (Bricard's mechanism)"
)

#: Registry name.
NAME = "A04_bricard"

# (name, start, end) of each rod; joints (name, point, axis, body_a, body_b)
_RODS = (
    ("rod1", (0.0, 0.0, 0.0), (1.0, 0.0, 0.0)),
    ("rod2", (1.0, 0.0, 0.0), (1.0, -1.0, 0.0)),
    ("rod3", (1.0, -1.0, 0.0), (1.0, -1.0, 1.0)),
    ("rod4", (1.0, -1.0, 1.0), (0.0, -1.0, 1.0)),
    ("rod5", (0.0, -1.0, 1.0), (0.0, 0.0, 1.0)),
)
_JOINTS = (
    ("J1", (0.0, 0.0, 0.0), (0.0, 1.0, 0.0), "ground", "rod1"),
    ("J2", (1.0, 0.0, 0.0), (0.0, 0.0, 1.0), "rod1", "rod2"),
    ("J3", (1.0, -1.0, 0.0), (1.0, 0.0, 0.0), "rod2", "rod3"),
    ("J4", (1.0, -1.0, 1.0), (0.0, 1.0, 0.0), "rod3", "rod4"),
    ("J5", (0.0, -1.0, 1.0), (0.0, 0.0, 1.0), "rod4", "rod5"),
    ("J6", (0.0, 0.0, 1.0), (1.0, 0.0, 0.0), "rod5", "ground"),
)


def bricard_model(
    *, g: float = 9.81, mass: float = 1.0, length: float = 1.0, width: float = 0.1
) -> SpatialModel:
    """Bricard's mechanism (A04) as a :class:`~nonmin.model.spatial.SpatialModel`.

    Parameters
    ----------
    g : float
        Gravity (along −y), m/s².
    mass, length, width : float
        Mass (kg), length (m) and square cross-section side (m) of every rod. ``length``
        scales the joint positions of the table.

    Returns
    -------
    SpatialModel
        Bodies ``rod1..rod5`` (body frames aligned with the world at the reference
        configuration), revolute joints ``J1..J6``, output point ``P3``.
    """
    axial = mass * width**2 / 6.0
    transverse = mass * (length**2 + width**2) / 12.0
    b = SpatialBuilder(NAME, gravity=(0.0, -g, 0.0))
    for name, start, end in _RODS:
        p0 = length * np.asarray(start)
        p1 = length * np.asarray(end)
        d = np.abs(p1 - p0) / length
        inertia = np.diag(np.where(d > 0.5, axial, transverse))
        b.add_body(name, mass=mass, inertia=inertia, position=0.5 * (p0 + p1))
    for name, point, axis, body_a, body_b in _JOINTS:
        b.add_revolute(name, body_a, body_b, point=length * np.asarray(point), axis=axis)
    b.add_output_point("P3", "rod2", point=length * np.array([1.0, -1.0, 0.0]))
    return b.build()


def bricard_state(model: SpatialModel) -> State:
    """The benchmark's initial state: the tabled configuration, at rest."""
    return model.state(model.reference_configuration(), np.zeros(model.n))


@register(NAME)
def a04_bricard(
    *,
    g: float = 9.81,
    mass: float = 1.0,
    length: float = 1.0,
    width: float = 0.1,
    t_final: float = 10.0,
) -> Mechanism:
    """IFToMM A04: Bricard's mechanism (five rods, six revolute joints, one redundant row).

    Source: IFToMM benchmark A04 (González et al., Multibody Syst. Dyn. 16 (2006) 179–190).
    Spatial unit-quaternion model (:func:`bricard_model`), released from rest in the tabled
    configuration (:func:`bricard_state`); horizon 10 s; outputs ``P3.position``,
    ``P3.velocity``. rank(A) = m − 1 = 34 along the motion, mobility 1 (Grübler: 0).
    """
    model = bricard_model(g=g, mass=mass, length=length, width=width)
    return Mechanism(
        model=model,
        state=bricard_state(model),
        t_final=float(t_final),
        description="IFToMM A04 Bricard mechanism (spatial, unit quaternions; one redundant "
        "constraint along the whole motion)",
        reference=IFTOMM_REF,
    )
