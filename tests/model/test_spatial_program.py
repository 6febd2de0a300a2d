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
