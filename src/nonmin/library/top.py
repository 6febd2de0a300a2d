"""Spinning top: a symmetric heavy top with a fixed tip, in unit-quaternion coordinates.

Source: the classical Lagrange top (e.g. Goldstein, *Classical Mechanics*, §5.7), built with
the spatial source: one body (7 coordinates: centre of mass, quaternion), a norm constraint
and a spherical joint ``"tip"`` to the ground at the origin; n = 7, m = 4, 3 degrees of
freedom. The body z axis is the symmetry axis; the centre of mass lies at distance ``l`` from
the tip along it; gravity ``g`` along −z.

Initial state: the symmetry axis tilted by ``tilt`` about the world x axis, spinning at
``spin`` about the symmetry axis, precessing at ``precession`` about the world z axis; the
velocities are consistent (tip at rest, ``εᵀε̇ = 0``). Outputs: ``com.position``,
``apex.position`` (the point at ``2 l`` on the axis) and their ``.velocity``.
"""

from __future__ import annotations

import numpy as np

from ..model import State
from ..model.spatial import (
    G_matrix,
    SpatialBuilder,
    SpatialModel,
    quaternion_from_axis_angle,
    rotation_matrix,
)
from ._registry import Mechanism, register

__all__ = ["NAME", "spinning_top", "top_model", "top_state"]

#: Registry name.
NAME = "spinning_top"


def top_model(
    *,
    mass: float = 0.5,
    l: float = 0.1,
    transverse_inertia: float = 2.5e-3,
    axial_inertia: float = 3.0e-3,
    g: float = 9.81,
    tilt: float = 0.3,
) -> SpatialModel:
    """The heavy symmetric top as a :class:`~nonmin.model.spatial.SpatialModel`.

    Parameters
    ----------
    mass : float
        Mass, kg.
    l : float
        Distance from the tip to the centre of mass, m.
    transverse_inertia, axial_inertia : float
        Principal moments about the centre of mass, kg·m².
    g : float
        Gravity along −z, m/s².
    tilt : float
        Reference tilt of the symmetry axis about the world x axis, rad (the reference
        configuration is the initial one).
    """
    e = quaternion_from_axis_angle([1.0, 0.0, 0.0], tilt)
    R = rotation_matrix(e)
    b = SpatialBuilder(NAME, gravity=(0.0, 0.0, -g))
    b.add_body(
        "top",
        mass=mass,
        inertia=[transverse_inertia, transverse_inertia, axial_inertia],
        position=R @ [0.0, 0.0, l],
        quaternion=e,
    )
    b.add_spherical("tip", "ground", "top", point=[0.0, 0.0, 0.0])
    b.add_output_point("com", "top", point=R @ [0.0, 0.0, l])
    b.add_output_point("apex", "top", point=R @ [0.0, 0.0, 2.0 * l])
    return b.build()


def top_state(model: SpatialModel, *, spin: float = 60.0, precession: float = 0.0) -> State:
    """Initial state: reference pose, body angular velocity ``(0, 0, spin)`` plus ``precession``
    about the world z axis (rad/s)."""
    q = model.reference_configuration()
    e = q[3:7]
    R = rotation_matrix(e)
    w_body = np.array([0.0, 0.0, spin]) + R.T @ np.array([0.0, 0.0, precession])
    ed = 0.5 * G_matrix(e).T @ w_body
    rd = np.cross(R @ w_body, q[0:3])  # tip at the origin is at rest
    return model.state(q, np.concatenate((rd, ed)))


@register(NAME)
def spinning_top(
    *,
    mass: float = 0.5,
    l: float = 0.1,
    transverse_inertia: float = 2.5e-3,
    axial_inertia: float = 3.0e-3,
    g: float = 9.81,
    tilt: float = 0.3,
    spin: float = 60.0,
    precession: float = 0.0,
    t_final: float = 2.0,
) -> Mechanism:
    """Heavy symmetric (Lagrange) top with a fixed tip, one body in unit-quaternion coordinates.

    Source: the classical Lagrange top (Goldstein, *Classical Mechanics*, 3rd ed., §5.7);
    reference solution: Euler's equations about the fixed point (tests integrate both).
    See :func:`top_model` and :func:`top_state` for the parameters.
    """
    model = top_model(
        mass=mass,
        l=l,
        transverse_inertia=transverse_inertia,
        axial_inertia=axial_inertia,
        g=g,
        tilt=tilt,
    )
    return Mechanism(
        model=model,
        state=top_state(model, spin=spin, precession=precession),
        t_final=float(t_final),
        description="heavy symmetric top with a fixed tip (spatial, unit quaternion, "
        "spherical joint to the ground)",
        reference="H. Goldstein, C. Poole, J. Safko, Classical Mechanics, 3rd ed. (2002), §5.7",
    )
