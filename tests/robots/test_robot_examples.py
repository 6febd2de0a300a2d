"""The example robots shipped in nonmin/data/robots: load, consistent, and behave physically."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("pinocchio")

from nonmin.core import forward_dynamics, impact_map
from nonmin.errors import InputError, UnknownNameError
from nonmin.model import assembly_residual
from nonmin.model.robots import data_path
from nonmin.model.robots._examples import (
    FOURBAR_CLOSURES,
    fourbar,
    serial_arm,
    two_arm_grasp,
)


def test_shipped_files_and_data_path() -> None:
    for name in ("arm4.urdf", "fourbar.urdf", "two_arms.urdf", "fourbar.xml"):
        assert data_path(name).is_file()
    with pytest.raises(UnknownNameError, match="available"):
        data_path("nope.urdf")


def test_serial_arm_contact_switching_and_impact() -> None:
    robot, state = serial_arm()
    assert robot.constraint("ee_contact").kind == "unilateral"
    assert "ee_contact" not in state.active
    gap = robot.constraint_residual(0.0, state.q, {"ee_contact"})
    assert abs(gap[0]) < 1e-10  # end effector on the ground
    # falling onto the ground: the inactive contact would be violated by gravity
    mt = robot.evaluate(0.0, state.q, state.qd, state.active)
    qdd = forward_dynamics(mt.M, mt.h, mt.constraints.A, mt.constraints.gamma)
    A = robot.constraint_jacobian(0.0, state.q, {"ee_contact"})
    assert (A @ qdd)[0] < 0.0
    # activate the contact: the end effector's normal acceleration becomes zero
    on = robot.evaluate(0.0, state.q, state.qd, {"ee_contact"})
    qdd_on = forward_dynamics(on.M, on.h, on.constraints.A, on.constraints.gamma)
    assert abs(A @ qdd_on)[0] < 1e-10
    # an impact with a downward end-effector velocity removes the normal velocity
    qd_minus = np.array([0.0, 0.5, 0.2, -0.1])
    qd_plus = impact_map(on.M, on.constraints.A, qd_minus)
    assert abs(A @ qd_plus)[0] < 1e-12
    assert robot.kinetic_energy(state.q, qd_plus) <= robot.kinetic_energy(state.q, qd_minus)


@pytest.mark.parametrize("closure", FOURBAR_CLOSURES)
def test_fourbar_closures(closure: str) -> None:
    robot, state = fourbar(closure)
    assert assembly_residual(robot, state).position < 1e-9
    A = robot.constraint_jacobian(0.0, state.q)
    rank = np.linalg.matrix_rank(A, tol=1e-9)
    assert rank == (3 if closure.endswith("weld") else 2)
    assert A.shape[0] == {"point": 3, "planar_point": 2, "hinge": 5, "weld": 6,
                          "planar_weld": 3}[closure]


def test_fourbar_all_closures_give_the_same_motion() -> None:
    """RK4 over 0.3 s: every rank-2 closure (minimal or redundant) gives the same trajectory."""
    finals = {}
    for closure in ("planar_point", "point", "hinge"):
        robot, state = fourbar(closure)

        def rhs(x, robot=robot):
            q, qd = x[:3], x[3:]
            mt = robot.evaluate(0.0, q, qd)
            ct = mt.constraints
            return np.concatenate([qd, forward_dynamics(mt.M, mt.h, ct.A, ct.gamma)])

        x = np.concatenate([state.q, state.qd])
        E0 = robot.energy(state.q, state.qd)
        dt = 2e-3
        for _ in range(150):
            k1 = rhs(x)
            k2 = rhs(x + 0.5 * dt * k1)
            k3 = rhs(x + 0.5 * dt * k2)
            k4 = rhs(x + dt * k3)
            x = x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        assert abs(robot.energy(x[:3], x[3:]) - E0) < 1e-6
        assert np.abs(robot.constraint_residual(0.0, x[:3])).max() < 1e-6
        finals[closure] = x
    np.testing.assert_allclose(finals["point"], finals["planar_point"], atol=1e-9)
    np.testing.assert_allclose(finals["hinge"], finals["planar_point"], atol=1e-9)


def test_two_arm_grasp_is_consistent() -> None:
    robot, state = two_arm_grasp()
    res = assembly_residual(robot, state)
    assert res.position < 1e-9 and res.velocity < 1e-12
    A = robot.constraint_jacobian(0.0, state.q)
    assert A.shape == (10, 15) and np.linalg.matrix_rank(A, tol=1e-9) == 10
    assert robot.k == 8  # the arms are actuated, the box is not
    with pytest.raises(InputError, match="closure"):
        fourbar("glue")


@pytest.mark.parametrize("name", ["serial_arm", "fourbar", "fourbar_mjcf", "two_arm_grasp"])
def test_examples_pass_the_model_checker(name: str) -> None:
    """The project's checker: A = ∂φ/∂q, Christoffel C, f_g = −∂V/∂q, consistency, M̄ > 0."""
    if name == "fourbar_mjcf":
        pytest.importorskip("mujoco")
    import nonmin.model.robots as robots
    from nonmin import check_model

    robot, state = getattr(robots, name)()
    report = check_model(robot, state, duration=0.0)
    assert report.passed, report.format()
