"""A planar four-bar with a diagonal spring: nonmin's tangent-space eigenfrequency against
Exudyn's ``ComputeODE2Eigenvalues`` (constrained eigenvalues on the null space of the
constraint Jacobian) on the same model built here in both libraries.

Crank 0.4 m, coupler 1.0 m, rocker 0.7 m, ground link 0.9 m, uniform bars (1.0, 1.5, 0.8 kg,
I = m L²/12), crank at 1.2 rad (upper assembly branch), a spring of stiffness 500 N/m from the
crank's ground pivot to the coupler–rocker joint at its rest length, no gravity: a rest state
with zero constraint forces, so both eigenproblems are the same linear one (Exudyn's
eigenvalue routine does not add the geometric stiffness of constraint forces).
"""

import math

import numpy as np
import pytest

import nonmin
from nonmin.model.planar import PlanarBuilder

exu = pytest.importorskip("exudyn")

A_, B_, C_, D_ = 0.4, 1.0, 0.7, 0.9
MASSES = (1.0, 1.5, 0.8)
K_SPRING = 500.0
THETA = 1.2


def _joints():
    Bp = np.array([A_ * math.cos(THETA), A_ * math.sin(THETA)])
    O2 = np.array([D_, 0.0])
    dv = O2 - Bp
    L = float(np.linalg.norm(dv))
    x = (B_**2 - C_**2 + L**2) / (2 * L)
    h = math.sqrt(B_**2 - x**2)
    e = dv / L
    Cp = Bp + x * e + h * np.array([-e[1], e[0]])
    return np.zeros(2), Bp, Cp, O2


def _bars():
    O1, Bp, Cp, O2 = _joints()
    return [(O1, Bp, MASSES[0]), (Bp, Cp, MASSES[1]), (O2, Cp, MASSES[2])]


def _nonmin_model():
    Cp = _joints()[2]
    b = PlanarBuilder("fourbar_spring", gravity=(0.0, 0.0))
    q = []
    for name, (p0, p1, m) in zip(("crank", "coupler", "rocker"), _bars(), strict=True):
        L = float(np.linalg.norm(p1 - p0))
        b.body(
            name,
            mass=m,
            inertia=m * L * L / 12,
            points={f"{name}0": (-L / 2, 0.0), f"{name}1": (L / 2, 0.0)},
        )
        c = 0.5 * (p0 + p1)
        q += [c[0], c[1], math.atan2(p1[1] - p0[1], p1[0] - p0[0])]
    b.revolute("O1", ("ground", (0.0, 0.0)), "crank0")
    b.revolute("B", "crank1", "coupler0")
    b.revolute("C", "coupler1", "rocker1")
    b.revolute("O2", ("ground", (D_, 0.0)), "rocker0")
    b.spring(
        "diagonal",
        ("ground", (0.0, 0.0)),
        "rocker1",
        stiffness=K_SPRING,
        rest_length=float(np.linalg.norm(Cp)),
    )
    return b.build(), np.array(q)


def _exudyn_omega2():
    from exudyn.itemInterface import (
        MarkerBodyPosition,
        NodeRigidBody2D,
        ObjectGround,
        ObjectRigidBody2D,
        RevoluteJoint2D,
        SpringDamper,
    )  # fmt: skip

    Cp = _joints()[2]
    SC = exu.SystemContainer()
    mbs = SC.AddSystem()
    ground = mbs.AddObject(ObjectGround())
    bodies = []
    for p0, p1, m in _bars():
        c = 0.5 * (p0 + p1)
        L = float(np.linalg.norm(p1 - p0))
        n = mbs.AddNode(
            NodeRigidBody2D(referenceCoordinates=[c[0], c[1], math.atan2(*(p1 - p0)[::-1])])
        )
        bodies.append(
            (mbs.AddObject(ObjectRigidBody2D(nodeNumber=n, mass=m, inertia=m * L * L / 12)), L)
        )

    def marker(body, local):
        return mbs.AddMarker(
            MarkerBodyPosition(bodyNumber=body, localPosition=[local[0], local[1], 0.0])
        )

    g1 = marker(ground, (0.0, 0.0))
    g2 = marker(ground, (D_, 0.0))
    (o0, L0), (o1, L1), (o2, L2) = bodies
    mbs.AddObject(RevoluteJoint2D(markerNumbers=[g1, marker(o0, (-L0 / 2, 0.0))]))
    mbs.AddObject(
        RevoluteJoint2D(markerNumbers=[marker(o0, (L0 / 2, 0.0)), marker(o1, (-L1 / 2, 0.0))])
    )
    mbs.AddObject(
        RevoluteJoint2D(markerNumbers=[marker(o1, (L1 / 2, 0.0)), marker(o2, (L2 / 2, 0.0))])
    )
    mbs.AddObject(RevoluteJoint2D(markerNumbers=[g2, marker(o2, (-L2 / 2, 0.0))]))
    mbs.AddObject(SpringDamper(markerNumbers=[g1, marker(o2, (L2 / 2, 0.0))], stiffness=K_SPRING, damping=0.0,
                               referenceLength=float(np.linalg.norm(Cp))))  # fmt: skip
    mbs.Assemble()
    ev, _ = mbs.ComputeODE2Eigenvalues()
    return np.asarray(ev, dtype=float)


def test_fourbar_with_diagonal_spring_matches_exudyn():
    model, q = _nonmin_model()
    assert np.abs(model.constraint_residual(0.0, q)).max() <= 1e-14
    m = nonmin.modes(model, q)
    assert m.frequencies.shape == (1,) and m.stable
    ev = _exudyn_omega2()
    assert ev.shape == (1,)
    assert abs(m.frequencies[0] ** 2 - ev[0]) <= 1e-8 * ev[0]
