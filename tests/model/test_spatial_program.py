"""The engine's SpatialProgram (C++, unit quaternions) equals the Python spatial evaluation.

``SpatialModel.engine_program()`` emits the model's bodies, the attachments and rows ``φ = X·Y``
of its row plan, the norm rows, springs and actuators as plain data (``spatial/_program.py``);
the C++ program evaluates M, ``h = f_g − C q̇``, f_passive, B, A, γ, φ, the velocity residual and
the energies. Every output is compared with :meth:`SpatialModel.evaluate` (itself tested against
finite differences, Pinocchio and the SymPy top) at random states off the constraint manifold and
random active sets: every joint kind to a body and to the ground, a model with springs, dampers
and actuators, and the library's spatial mechanisms (A04 Bricard, spinning top).
"""

from __future__ import annotations

import numpy as np
import pytest
from program_check import check_terms, close
from test_spatial_model import _joint_model, _rich_model

from nonmin import _engine, library
from nonmin.errors import ModelError, NonFiniteError
from nonmin.model.spatial import JOINT_KINDS, SpatialModel

#: agreement of the engine and the Python evaluation (relative to max(1, |Python|))
REL_TOL = 1e-13


def _close(got: np.ndarray, ref: np.ndarray, what: str) -> None:
    close(got, ref, what, REL_TOL)


def check(model: SpatialModel, t: float, q: np.ndarray, qd: np.ndarray, active: frozenset[str]) -> None:
    check_terms(model, t, q, qd, active, REL_TOL)


def _random_checks(model: SpatialModel, seed: int, count: int = 3) -> None:
    rng = np.random.default_rng(seed)
    q0 = model.reference_configuration()
    names = model.constraint_names
    for _ in range(count):
        q = q0 + 0.3 * rng.standard_normal(model.n)  # off the manifold, quaternions not unit
        qd = rng.standard_normal(model.n)
        t = float(rng.uniform(0, 1))
        for active in (frozenset(names), frozenset(), frozenset(n for n in names if rng.random() < 0.5)):
            check(model, t, q, qd, active)


@pytest.mark.parametrize("body_a", ["b0", "ground"])
@pytest.mark.parametrize("kind", JOINT_KINDS)
def test_every_joint_kind(kind: str, body_a: str) -> None:
    rng = np.random.default_rng(2 * JOINT_KINDS.index(kind) + (body_a == "ground"))
    _random_checks(_joint_model(kind, body_a, rng), seed=JOINT_KINDS.index(kind))


def test_springs_dampers_and_actuators() -> None:
    model = _rich_model(np.random.default_rng(4))
    assert model.k == 3 and model.springs
    prog = model.engine_program()
    assert prog is model.engine_program() and not prog.constant_mass and prog.thread_safe
    _random_checks(model, seed=1, count=5)


@pytest.mark.parametrize("name", ["A04_bricard", "spinning_top"])
def test_library_mechanisms(name: str) -> None:
    mech = library.get(name)
    model = mech.model
    s = mech.state
    check(model, float(s.t), s.q, s.qd, s.active)
    _random_checks(model, seed=2)


def test_errors() -> None:
    model = library.get("spinning_top").model
    prog = model.engine_program()
    q = model.reference_configuration()
    q[4] = np.inf
    with pytest.raises(NonFiniteError):
        prog.evaluate(0.0, q, np.zeros(model.n), model.active_mask(None))
    d = _engine.SpatialDescription()
    d.add_body(1.0, (1.0, 0, 0, 0, 1.0, 0, 0, 0, 1.0))
    c = d.add_constraint("j", 0, 2)
    d.add_norm_row(c, 0, 0)  # row 1 is not defined
    with pytest.raises(ModelError, match="defined 0 times"):
        _engine.SpatialProgram(d)
    d = _engine.SpatialDescription()
    d.add_body(1.0, (1.0, 0, 0, 0, 1.0, 0, 0, 0, 1.0))
    c = d.add_constraint("j", 0, 1)
    d.add_dot_row(c, 0, [(3, 1.0)], [])
    with pytest.raises(ModelError, match="attachment index"):
        _engine.SpatialProgram(d)


@pytest.mark.parametrize("body_a", ["b0", "ground"])
def test_joint_limits(body_a: str) -> None:
    """Angle limits (revolute, cylindrical) and slide limits (prismatic) with both sides: the
    engine's unilateral rows equal the NumPy ones, and at a rotation θ about the hinge the
    NumPy gaps are ``sin(θ − lower)``, ``sin(upper − θ)`` (slide: ``s − lower``, ``upper − s``)."""
    from nonmin.model.spatial import SpatialBuilder

    b = SpatialBuilder("limits")
    b.add_body("b0", mass=1.0, inertia=(0.1, 0.2, 0.25), position=(0.1, 0.0, 0.2))
    b.add_body("b1", mass=1.3, inertia=(0.2, 0.15, 0.3), position=(0.5, 0.2, 0.0))
    b.add_body("b2", mass=0.7, inertia=(0.1, 0.1, 0.1), position=(0.9, 0.3, -0.2))
    if body_a == "ground":
        b.add_spherical("fix", "ground", "b0", point=(0.1, 0.0, 0.2))
    b.add_revolute("hinge", body_a, "b1", point=(0.3, 0.1, 0.0), axis=(0.3, -0.5, 0.8))
    b.add_prismatic("rail", "b1", "b2", point=(0.7, 0.2, -0.1), axis=(1.0, 0.2, 0.1))
    b.add_angle_limit("turn", "hinge", lower=-0.4, upper=1.1)
    b.add_slide_limit("slide", "rail", lower=-0.2, upper=0.3)
    model = b.build()
    _random_checks(model, seed=7, count=4)

    # rotate b1 (and b2 with it) by θ about the hinge axis through its point: the limit gaps
    if body_a == "ground":
        th, u = 0.6, np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
        q = model.reference_configuration().copy()
        c = np.array([0.3, 0.1, 0.0])
        K = np.array([[0, -u[2], u[1]], [u[2], 0, -u[0]], [-u[1], u[0], 0]])
        R = np.eye(3) + np.sin(th) * K + (1 - np.cos(th)) * K @ K
        eps = np.concatenate([[np.cos(th / 2)], np.sin(th / 2) * u])
        for i in (1, 2):
            q[7 * i:7 * i + 3] = c + R @ (q[7 * i:7 * i + 3] - c)
            q[7 * i + 3:7 * i + 7] = eps  # reference orientations are the identity
        names = ("turn.lower", "turn.upper", "slide.lower", "slide.upper")
        phi = model.constraint_residual(0.0, q, names)[-4:]
        np.testing.assert_allclose(phi, [np.sin(th + 0.4), np.sin(1.1 - th), 0.2, 0.3], atol=1e-14)
