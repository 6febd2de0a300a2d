"""Targets: quaternion targets do not unwind; references and projection helpers; Switched state."""

from __future__ import annotations

import math

import numpy as np
import pytest

from nonmin.control import Reference, Regulator, Switched, align_quaternions, project_configuration
from nonmin.errors import AssemblyError, InputError
from nonmin.model.planar import PlanarBuilder
from nonmin.model.spatial import SpatialBuilder
from nonmin.sim import simulate


def _wheel():
    b = SpatialBuilder("wheel", gravity=(0.0, 0.0, -9.81))
    b.add_body("disk", mass=1.0, inertia=[0.1, 0.1, 0.2], position=[0.0, 0.0, 0.0])
    b.add_revolute("hinge", "ground", "disk", point=[0.0, 0.0, 0.0], axis=[0.0, 0.0, 1.0])
    b.add_actuator("motor", "hinge")
    return b.build()


def test_quaternion_target_does_not_unwind() -> None:
    """Target rotation 0.5 rad about z given by the negative quaternion −q*: with the quaternion
    block declared the wheel turns 0.5 rad; without, the Euclidean error drives it the long way
    (0.5 − 2π)."""
    model = _wheel()
    q0 = model.reference_configuration()
    alpha = 0.5
    target = np.r_[0.0, 0.0, 0.0, -math.cos(alpha / 2), 0.0, 0.0, -math.sin(alpha / 2)]
    final = {}
    for blocks in ([(3, 4, 5, 6)], []):
        reg = Regulator(model, target=target, Kp=40.0, Kd=8.0, quaternion_blocks=blocks)
        traj = simulate(model, (0.0, 2.0), q0, method="rk4", dt=1e-2, controller=reg)
        angle = np.unwrap(2.0 * np.unwrap(np.arctan2(traj.q[:, 6], traj.q[:, 3])))
        final[bool(blocks)] = (angle[-1], np.abs(angle).max())
    assert final[True][0] == pytest.approx(alpha, abs=1e-3)
    assert final[True][1] < alpha + 0.1  # never more than a small overshoot
    assert final[False][0] == pytest.approx(alpha - 2 * math.pi, abs=2e-2)  # unwinding


def test_align_quaternions() -> None:
    q = np.array([9.0, 1.0, 0.0, 0.0, 0.0])
    qs = np.array([1.0, -0.9, 0.1, 0.0, 0.1])
    out = align_quaternions(q, qs, [(1, 2, 3, 4)])
    np.testing.assert_allclose(out, [1.0, 0.9, -0.1, 0.0, -0.1])
    np.testing.assert_allclose(align_quaternions(q, -qs, [(1, 2, 3, 4)])[1:], out[1:])
    with pytest.raises(InputError, match="4 distinct coordinate indices"):
        Regulator(_wheel(), target=np.r_[0, 0, 0, 1, 0, 0, 0.0], quaternion_blocks=[(3, 4, 5)])


def test_reference_constructors() -> None:
    t = np.linspace(0.0, 1.0, 11)
    q = np.stack([np.sin(t), t**2], axis=1)
    ref = Reference.spline(t, q)
    pos = ref(0.5)[0]
    assert pos == pytest.approx([math.sin(0.5), 0.25], abs=1e-3)
    np.testing.assert_allclose(ref(2.0)[1], 0.0)  # holds the end point
    f = Reference.from_functions(lambda s: np.array([math.sin(s), s**3]))
    _, v, a = f(0.3)
    np.testing.assert_allclose(v, [math.cos(0.3), 3 * 0.09], atol=1e-7)
    np.testing.assert_allclose(a, [-math.sin(0.3), 6 * 0.3], atol=1e-4)
    c = Reference.constant([1.0, 2.0])
    np.testing.assert_allclose(c(5.0)[0], [1.0, 2.0])
    with pytest.raises(InputError):
        Reference.from_functions(3.0)  # type: ignore[arg-type]


def _two_link_loop():
    b = PlanarBuilder("reach", gravity=(0.0, 0.0))
    b.point_mass("p", mass=1.0, points=["P"])
    b.ground_point("O", (0.0, 0.0))
    b.rod("r", "O", "P", length=1.0)
    b.force("fx", "P", direction=(1.0, 0.0))
    b.force("fy", "P", direction=(0.0, 1.0))
    return b.build()


def test_projection_metrics_and_failure() -> None:
    model = _two_link_loop()
    for metric in ("euclidean", "mass"):
        out = project_configuration(model, [3.0, 4.0], metric=metric)  # type: ignore[arg-type]
        np.testing.assert_allclose(out, [0.6, 0.8], atol=1e-12)
    with pytest.raises(InputError, match="metric"):
        project_configuration(model, [3.0, 4.0], metric="manhattan")  # type: ignore[arg-type]
    with pytest.raises(AssemblyError, match="could not project"):
        # the origin is equidistant from the whole circle: Gauss–Newton cannot converge
        project_configuration(model, [0.0, 0.0], max_iter=5)


def test_switched_state_and_dispatch() -> None:
    model = _two_link_loop()
    a = Regulator(model, target=[1.0, 0.0])
    b = Regulator(model, target=[0.0, 1.0])
    sw = Switched(model, {("r",): a}, default=b)
    st = sw.initial_state()
    assert len(st) == 2
    q, qd = np.array([0.6, 0.8]), np.zeros(2)
    np.testing.assert_allclose(sw(0.0, q, qd, st, active=["r"]), a(0.0, q, qd))
    np.testing.assert_allclose(sw(0.0, q, qd, st, active=[]), b(0.0, q, qd, active=[]))
    st2 = sw.update(0.0, q, qd, st, active=["r"])
    assert st2[0].steps == 1 and st2[1].steps == 0
    assert sw.info(0.0, q, qd, st2, active=["r"]).feasible
