"""RobotModel + nonmin's projection dynamics against Pinocchio's own constrained dynamics.

Regular configurations: qdd and the generalized constraint force equal Pinocchio's
``constraintDynamics`` (exact KKT: proximal mu = 0, one iteration) to 1e-9. Redundant
constraints (a planar loop closed by a 3D point, a weld plus a point on the same frame pair):
Pinocchio's exact KKT returns NaN and needs its proximal regularization and iterations, while
nonmin stays finite and exact and agrees with the minimal (non-redundant) closure.
"""

from __future__ import annotations

import numpy as np
import pytest

pin = pytest.importorskip("pinocchio")

from nonmin.core import solve_dynamics  # noqa: E402
from nonmin.model import assemble  # noqa: E402
from nonmin.model.robots import FrameConstraint, RobotModel, data_path  # noqa: E402
from nonmin.model.robots._examples import fourbar, two_arm_grasp  # noqa: E402

TOL = 1e-9


def _admissible_velocity(robot, q, active, rng):
    A = robot.constraint_terms(0.0, q, np.zeros(robot.n), active).A
    _, s, Vt = np.linalg.svd(A)
    r = int(np.sum(s > 1e-10 * max(1.0, s[0])))
    N = Vt[r:].T
    return N @ rng.normal(size=N.shape[1])


@pytest.fixture
def pin_dynamics(pin_frame_constraints):
    """``pin_dynamics(robot, q, qd, tau_v, specs, mu=0.0, max_iter=1)``: Pinocchio's
    constraintDynamics on the same tree and constraint frames (q̈, f_c, J, λ, the settings)."""

    def run(robot, q, qd, tau_v, specs, *, mu=0.0, max_iter=1):
        pm = robot.pinocchio_model
        data = pm.createData()
        models, datas = pin_frame_constraints(robot, specs)
        pin.initConstraintDynamics(pm, data, models, datas)
        prox = pin.ProximalSettings(1e-12, mu, max_iter)
        qn = robot.pinocchio_configuration(q)
        v = robot.to_pinocchio_velocity(q, qd)
        a = np.array(pin.constraintDynamics(pm, data, qn, v, tau_v, models, datas, prox))
        M = pin.crba(pm, pm.createData(), qn)
        M = np.triu(M) + np.triu(M, 1).T
        nle = np.array(pin.nonLinearEffects(pm, pm.createData(), qn, v))
        f_c = M @ a + nle - tau_v  # generalized constraint force in velocity space
        J = np.array(pin.getConstraintsJacobian(pm, data, models, datas))
        lam = np.array(data.lambda_c)
        return a, f_c, J, lam, prox

    return run


def _nonmin(robot, q, qd, tau_v, active):
    mt = robot.evaluate(0.0, q, qd, active)
    T = robot.velocity_map(q)
    ct = mt.constraints
    sol = solve_dynamics(mt.M, mt.h, ct.A, ct.gamma, T.T @ tau_v)
    return sol, mt, T


def test_arm_point_contact_matches_pinocchio_kkt(pin_dynamics) -> None:
    """Fixed-base 4-dof arm, end effector pinned to the ground (3D point, rank 3, 1 dof)."""
    base = RobotModel.from_urdf(data_path("arm4.urdf"))
    robot = base.replace(robot_constraints=(FrameConstraint.point("pin", "ee"),))
    q0 = assemble(robot.replace(robot_constraints=(FrameConstraint.contact("c", "ee"),),
                                default_active_names=frozenset({"c"})),
                  [0.3, 0.6, 0.9, 0.4], fixed=["yaw", "wrist"]).q
    # pin the end effector where it is
    p = robot.frame_placement(q0, "ee")[:3, 3]
    robot = base.replace(robot_constraints=(FrameConstraint.point("pin", "ee", placement_b=p),))
    rng = np.random.default_rng(3)
    for _ in range(3):
        qd = _admissible_velocity(robot, q0, None, rng)
        tau = rng.normal(size=robot.nv)
        sol, _, T = _nonmin(robot, q0, qd, tau, None)
        a, f_c, J, lam, _ = pin_dynamics(robot, q0, qd, tau, [(3, "pin")])
        assert int(sol.rank) == 3
        np.testing.assert_allclose(sol.qdd, a, atol=TOL, rtol=0)
        np.testing.assert_allclose(sol.f_c, T.T @ f_c, atol=TOL * max(1.0, np.abs(f_c).max()))
        np.testing.assert_allclose(J.T @ lam, f_c, atol=1e-8 * max(1.0, np.abs(f_c).max()))


def test_two_arm_grasp_with_free_box_matches_pinocchio_kkt(pin_dynamics) -> None:
    """Free-flyer box (quaternion coordinates) held by a weld (6D) and a point (3D)."""
    robot, state = two_arm_grasp()
    q = state.q
    rng = np.random.default_rng(4)
    for _ in range(3):
        qd = _admissible_velocity(robot, q, None, rng)
        tau = np.concatenate([np.zeros(6), rng.normal(size=robot.nv - 6)])
        sol, mt, T = _nonmin(robot, q, qd, tau, None)
        a, f_c, _, _, _ = pin_dynamics(
            robot, q, qd, tau, [(6, "grasp_left"), (3, "grasp_right")]
        )
        assert int(sol.rank) == 1 + 9
        a_nonmin = robot.to_pinocchio_acceleration(q, qd, sol.qdd)
        scale = max(1.0, np.abs(a).max())
        np.testing.assert_allclose(a_nonmin, a, atol=TOL * scale, rtol=0)
        np.testing.assert_allclose(sol.f_c, T.T @ f_c, atol=TOL * max(1.0, np.abs(f_c).max()))
        # the actuation matrix is Tᵀ S: B u reproduces Tᵀ τ for the arm torques
        np.testing.assert_allclose(mt.B @ tau[6:], T.T @ tau, atol=1e-14)


def _exactness(sol, mt, f):
    ct = mt.constraints
    res_acc = np.abs(ct.A @ sol.qdd + ct.gamma).max()
    res_dyn = np.abs(sol.P @ (mt.M @ sol.qdd - f - mt.h)).max()
    return res_acc, res_dyn


def test_redundant_planar_loop_nonmin_exact_where_pinocchio_needs_regularization(pin_dynamics) -> None:
    """Four-bar closed by a 3D point: the out-of-plane row is identically zero (rank 2 < 3)."""
    red, state = fourbar("point")
    mini, _ = fourbar("planar_point")
    q = state.q
    rng = np.random.default_rng(5)
    qd = _admissible_velocity(red, q, None, rng)
    tau = np.array([0.7, 0.0, 0.0])
    sol, mt, _ = _nonmin(red, q, qd, tau, None)
    sol_min, _, _ = _nonmin(mini, q, qd, tau, None)
    assert int(sol.rank) == 2 and mt.constraints.A.shape[0] == 3
    assert np.isfinite(sol.qdd).all() and np.isfinite(sol.f_c).all()
    res_acc, res_dyn = _exactness(sol, mt, tau)
    assert res_acc < 1e-10 and res_dyn < 1e-10
    np.testing.assert_allclose(sol.qdd, sol_min.qdd, atol=1e-10)
    np.testing.assert_allclose(sol.f_c, sol_min.f_c, atol=1e-10)
    # Pinocchio: the exact KKT (mu = 0) breaks down on the singular system ...
    a0, *_ = pin_dynamics(red, q, qd, tau, [(3, "closure")], mu=0.0, max_iter=1)
    assert not np.isfinite(a0).all()
    # ... a single regularized step is off by ~mu, and converging needs several iterations
    a1, *_ = pin_dynamics(red, q, qd, tau, [(3, "closure")], mu=1e-6, max_iter=1)
    assert np.abs(a1 - sol.qdd).max() > 1e-7
    a_it, _, _, _, prox = pin_dynamics(
        red, q, qd, tau, [(3, "closure")], mu=1e-6, max_iter=100
    )
    assert prox.iter > 1
    np.testing.assert_allclose(a_it, sol.qdd, atol=1e-8)


def test_redundant_weld_plus_point_on_same_frames(pin_dynamics) -> None:
    """A weld and a point on the same frame pair (3 duplicated rows) change nothing in nonmin."""
    robot, state = two_arm_grasp()
    weld = robot.robot_constraints[0]
    dup = FrameConstraint.point(
        "grasp_left_point", weld.frame_a, weld.frame_b,
        placement_a=weld.placement_a, placement_b=weld.placement_b,
    )
    red = robot.replace(robot_constraints=(*robot.robot_constraints, dup))
    q = state.q
    rng = np.random.default_rng(6)
    qd = _admissible_velocity(robot, q, None, rng)
    tau = np.concatenate([np.zeros(6), rng.normal(size=robot.nv - 6)])
    sol, mt, _ = _nonmin(red, q, qd, tau, None)
    ref, _, _ = _nonmin(robot, q, qd, tau, None)
    T = robot.velocity_map(q)
    assert mt.constraints.A.shape[0] == 1 + 6 + 3 + 3 and int(sol.rank) == 10
    res_acc, res_dyn = _exactness(sol, mt, T.T @ tau)
    assert res_acc < 1e-9 and res_dyn < 1e-9
    np.testing.assert_allclose(sol.qdd, ref.qdd, atol=1e-9)
    np.testing.assert_allclose(sol.f_c, ref.f_c, atol=1e-9)
    specs = [(6, "grasp_left"), (3, "grasp_right"), (3, "grasp_left_point")]
    a0, *_ = pin_dynamics(red, q, qd, tau, specs, mu=0.0, max_iter=1)
    a_ref = red.to_pinocchio_acceleration(q, qd, sol.qdd)
    assert not (np.isfinite(a0).all() and np.abs(a0 - a_ref).max() < 1e-6)
    a_it, _, _, _, prox = pin_dynamics(red, q, qd, tau, specs, mu=1e-6, max_iter=200)
    assert prox.iter > 1
    np.testing.assert_allclose(a_it, a_ref, atol=1e-6 * max(1.0, np.abs(a_ref).max()))


def _solo12_urdf():
    from pathlib import Path

    root = Path(pin.__file__).resolve().parents[4] / "share" / "example-robot-data" / "robots"
    path = root / "solo_description" / "robots" / "solo12.urdf"
    if not path.is_file():
        pytest.skip("example-robot-data (solo12.urdf) is not installed")
    return path


def test_real_quadruped_four_feet_pinned_and_redundant_contacts(pin_dynamics) -> None:
    """Solo-12 (example-robot-data, free-flyer base): 4 feet pinned (12 rows) vs Pinocchio;
    adding the 4 unilateral ground contacts of the same feet (4 duplicated rows) changes
    nothing in nonmin while Pinocchio's exact KKT fails."""
    base = RobotModel.from_urdf(_solo12_urdf(), root_joint="freeflyer")
    feet = ["FL_FOOT", "FR_FOOT", "HL_FOOT", "HR_FOOT"]
    rng = np.random.default_rng(7)
    q = base.random_configuration(rng)
    q[:3] = [0.0, 0.0, 0.3]
    pins = tuple(
        FrameConstraint.point(f"pin_{f}", f, placement_b=base.frame_placement(q, f)[:3, 3])
        for f in feet
    )
    robot = base.replace(robot_constraints=pins)
    qd = _admissible_velocity(robot, q, None, rng)
    tau = np.concatenate([np.zeros(6), rng.normal(size=robot.nv - 6)])
    sol, _, T = _nonmin(robot, q, qd, tau, None)
    a, f_c, _, _, _ = pin_dynamics(robot, q, qd, tau, [(3, c.name) for c in pins])
    assert int(sol.rank) == 1 + 12
    scale = max(1.0, np.abs(a).max())
    np.testing.assert_allclose(robot.to_pinocchio_acceleration(q, qd, sol.qdd), a,
                               atol=TOL * scale, rtol=0)
    np.testing.assert_allclose(sol.f_c, T.T @ f_c, atol=TOL * max(1.0, np.abs(f_c).max()))
    # ground contacts at the feet's heights duplicate the pins' vertical rows
    contacts = tuple(
        FrameConstraint.contact(f"ground_{f}", f,
                                plane_placement=[0.0, 0.0, base.frame_placement(q, f)[2, 3]])
        for f in feet
    )
    red = robot.replace(robot_constraints=pins + contacts)
    every = red.constraint_names
    assert red.constraint("ground_FL_FOOT").kind == "unilateral"
    sol_r, mt_r, _ = _nonmin(red, q, qd, tau, every)
    assert mt_r.constraints.A.shape[0] == 1 + 16 and int(sol_r.rank) == 13
    np.testing.assert_allclose(sol_r.qdd, sol.qdd, atol=1e-9 * max(1.0, np.abs(sol.qdd).max()))
    assert np.abs(mt_r.constraints.A @ sol_r.qdd + mt_r.constraints.gamma).max() < 1e-9
