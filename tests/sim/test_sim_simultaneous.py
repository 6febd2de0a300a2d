"""Simultaneous impacts in a simulation: one impact over every contact closing at the instant
(issue #22), with closed-form references, on both drivers."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import G
from nonmin.model import FunctionConstraint, FunctionModel
from nonmin.model.planar import PlanarBuilder
from nonmin.sim import simulate

H0 = 0.5


def _bar_on_three_points():  # type: ignore[no-untyped-def]
    b = PlanarBuilder("bar3")
    b.body("bar", mass=1.0, inertia=4.0 / 12.0, points={"l": (-1.0, 0.0), "c": (0.0, 0.0), "r": (1.0, 0.0)})
    for p in "lcr":
        b.point_on_line(f"floor_{p}", ("ground", (0.0, 0.0)), p, axis=(1.0, 0.0), unilateral=True)
    return b.build()


@pytest.mark.parametrize("engine", ["python", "auto"])
def test_flat_bar_dropped_on_three_contacts_bounces_without_spin(engine: str) -> None:
    """The issue's example: e = 0.5 gave ω = −0.84 rad/s (contacts one at a time); one impact
    over the set gives ω = 0 and v⁺ = e·√(2 g h) at t = √(2h/g)."""
    tr = simulate(_bar_on_three_points(), 0.5, [0.0, H0, 0.0], [0.0, 0.0, 0.0], restitution=0.5,
                  dt=1e-3, engine=engine, progress=False)  # fmt: skip
    assert [e.name for e in tr.events] == ["impact:floor_l+floor_c+floor_r"]
    ev = tr.events[0]
    assert abs(ev.t - np.sqrt(2 * H0 / G)) < 1e-10
    v = np.sqrt(2 * G * H0)
    assert np.max(np.abs(ev.qd_after - [0.0, 0.5 * v, 0.0])) < 1e-10
    assert ev.active_after == frozenset()  # every contact bounces
    assert np.max(np.abs(tr.qd[:, 2])) < 1e-12 and np.max(np.abs(tr.q[:, 2])) < 1e-12


def _ball_on_floor_into_ramp() -> FunctionModel:
    """Unit point mass (x, y): floor gap y ≥ 0 and a 45° ramp gap (x + y)/√2 ≥ 0."""
    s = 1.0 / np.sqrt(2.0)
    floor = FunctionConstraint.unilateral("floor", gap=lambda q: [q[1]], jacobian=lambda q: np.array([[0.0, 1.0]]),
                                          adot_qd=lambda q, qd: [0.0])  # fmt: skip
    ramp = FunctionConstraint.unilateral("ramp", gap=lambda q: [s * (q[0] + q[1])],
                                         jacobian=lambda q: np.array([[s, s]]), adot_qd=lambda q, qd: [0.0])  # fmt: skip
    return FunctionModel(
        name="ball_ramp", coordinate_names=("x", "y"), mass=lambda q: np.eye(2),
        coriolis=lambda q, qd: np.zeros((2, 2)), conservative=lambda q: [0.0, -G],
        potential=lambda q: G * q[1], constraints=(floor, ramp),
    )  # fmt: skip


@pytest.mark.parametrize("engine", ["python", "auto"])
def test_impact_into_a_ramp_reopens_the_resting_floor_contact(engine: str) -> None:
    """Sliding at 1 m/s on the floor (active) into a 45° ramp with e = 1: the ball leaves
    straight up at 1 m/s (the floor opens; an equality floor row would pull and send it back
    along the floor at 1 m/s), flies 2/g s and lands in the corner, on both contacts at once,
    and leaves straight up again."""
    model = _ball_on_floor_into_ramp()
    tr = simulate(model, 1.0 + 3.0 / G, [1.0, 0.0], [-1.0, 0.0], active={"floor"}, restitution=1.0, dt=1e-3,
                  engine=engine, progress=False)  # fmt: skip
    names = [e.name for e in tr.events]
    assert names[:2] == ["impact:ramp", "impact:floor+ramp"], names
    e1, e2 = tr.events[:2]
    assert abs(e1.t - 1.0) < 1e-10
    assert np.max(np.abs(e1.qd_after - [0.0, 1.0])) < 1e-10
    assert e1.active_after == frozenset()
    assert abs(e2.t - (1.0 + 2.0 / G)) < 1e-9
    assert np.max(np.abs(e2.qd_after - [0.0, 1.0])) < 1e-9
    assert np.max(np.abs(tr.q[:, 0])[tr.t > 1.0 + 1e-9]) < 1e-9  # stays in the corner's vertical
