"""RobotModel.from_mjcf against MuJoCo itself, and MJCF equality constraints."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("pinocchio")
mujoco = pytest.importorskip("mujoco")

from nonmin.core import solve_dynamics  # noqa: E402
from nonmin.errors import ModelError  # noqa: E402
from nonmin.model.robots import FrameConstraint, JointCoupling, RobotModel, data_path  # noqa: E402
from nonmin.model.robots._examples import fourbar_mjcf  # noqa: E402

TOL = 1e-10

FREE_MJCF = """
<mujoco model="free_ball">
  <option gravity="0.3 -0.2 -9.81"/>
  <worldbody>
    <body name="base" pos="0.1 0.2 1.0" quat="0.9 0.1 0.3 -0.2">
      <freejoint name="root"/>
      <geom type="box" size="0.1 0.2 0.05" density="800" pos="0.02 0 0.01"/>
      <body name="arm" pos="0.1 0 0" euler="0.2 0.1 0.4">
        <joint name="ball" type="ball" pos="0.01 0.02 0" armature="0.002"/>
        <geom type="capsule" fromto="0 0 0 0 0 -0.3" size="0.02"/>
        <body name="hand" pos="0 0 -0.3">
          <joint name="slide" type="slide" axis="0.3 0.5 1"/>
          <joint name="twist" type="hinge" axis="1 0.2 0" pos="0 0.01 0.02"/>
          <geom type="sphere" size="0.04" pos="0.01 0 -0.02"/>
          <site name="tip" pos="0 0 -0.05"/>
        </body>
      </body>
    </body>
  </worldbody>
</mujoco>
"""


_NO_EQ_NO_CONTACT = int(mujoco.mjtDisableBit.mjDSBL_EQUALITY) | int(
    mujoco.mjtDisableBit.mjDSBL_CONTACT
)


def _mj(path):
    mj = mujoco.MjModel.from_xml_path(str(path))
    return mj, mujoco.MjData(mj)


def _random_state(robot, rng):
    q = robot.random_configuration(rng)
    qd = robot.from_pinocchio_velocity(q, rng.normal(size=robot.nv))
    return q, qd


def test_fourbar_mjcf_terms_and_free_accelerations_equal_mujoco() -> None:
    """M, h = −qfrc_bias, damping and unconstrained qacc equal MuJoCo's to 1e-10."""
    path = data_path("fourbar.xml")
    robot = RobotModel.from_mjcf(path)
    mj, d = _mj(path)
    # unconstrained: MuJoCo's equalities and (geom) contacts off
    mj.opt.disableflags |= _NO_EQ_NO_CONTACT
    assert robot.coordinate_names == ("crank", "coupler", "rocker", "lock", "wheel")
    rng = np.random.default_rng(0)
    for _ in range(10):
        q, qd = rng.uniform(-2, 2, robot.n), rng.normal(size=robot.n)
        d.qpos[:], d.qvel[:] = q, qd
        mujoco.mj_forward(mj, d)
        M_mj = np.zeros((mj.nv, mj.nv))
        mujoco.mj_fullM(mj, d, M_mj)
        mt = robot.evaluate(0.0, q, qd, active=())
        np.testing.assert_allclose(mt.M, M_mj, atol=TOL, rtol=0)
        np.testing.assert_allclose(mt.h, -d.qfrc_bias, atol=TOL, rtol=0)
        np.testing.assert_allclose(mt.f_passive, d.qfrc_passive, atol=TOL, rtol=0)
        sol = solve_dynamics(mt.M, mt.h, mt.constraints.A, mt.constraints.gamma, mt.f_passive)
        np.testing.assert_allclose(sol.qdd, d.qacc, atol=TOL * max(1, np.abs(d.qacc).max()))


def test_free_and_ball_joints_equal_mujoco(tmp_path) -> None:
    """Quaternion coordinates (free + ball joints, slide + hinge on one body) vs MuJoCo."""
    path = tmp_path / "free_ball.xml"
    path.write_text(FREE_MJCF)
    robot = RobotModel.from_mjcf(path)
    mj, d = _mj(path)
    mj.opt.disableflags |= _NO_EQ_NO_CONTACT
    assert robot.n == mj.nq and robot.nv == mj.nv
    np.testing.assert_allclose(robot.from_mujoco_qpos(mj.qpos0)[3:7],
                               np.roll(mj.qpos0[3:7], -1))
    rng = np.random.default_rng(1)
    for _ in range(6):
        q, qd = _random_state(robot, rng)
        v = robot.to_pinocchio_velocity(q, qd)
        R = robot.frame_placement(q, "base")[:3, :3]
        qvel = v.copy()
        qvel[:3] = R @ v[:3]  # MuJoCo: free-joint linear velocity in world axes
        d.qpos[:], d.qvel[:] = robot.to_mujoco_qpos(q), qvel
        mujoco.mj_forward(mj, d)
        M_mj = np.zeros((mj.nv, mj.nv))
        mujoco.mj_fullM(mj, d, M_mj)
        # kinetic and potential power are coordinate-free
        ke_mj = 0.5 * qvel @ M_mj @ qvel
        assert abs(robot.kinetic_energy(q, qd) - ke_mj) < TOL * max(1.0, ke_mj)
        mt = robot.evaluate(0.0, q, qd)
        sol = solve_dynamics(mt.M, mt.h, mt.constraints.A, mt.constraints.gamma)
        a = robot.to_pinocchio_acceleration(q, qd, sol.qdd)
        # MuJoCo's acceleration coordinates: p̈ of the body (= qdd[:3]), then ω̇ and joint accels
        qacc = np.concatenate([sol.qdd[:3], a[3:]])
        # backward error in MuJoCo's own equations of motion (M is ill-conditioned here,
        # cond ≈ 2e7, so compare residuals, and accelerations to cond·eps)
        res = M_mj @ qacc + d.qfrc_bias - d.qfrc_passive
        scale = np.abs(M_mj).max() * np.abs(qacc).max() + np.abs(d.qfrc_bias).max()
        assert np.abs(res).max() < TOL * scale
        np.testing.assert_allclose(qacc, d.qacc, rtol=0,
                                   atol=1e-14 * np.linalg.cond(M_mj) * np.abs(d.qacc).max())
        # frames: MuJoCo's site position equals the converted frame's
        np.testing.assert_allclose(robot.frame_placement(q, "tip")[:3, 3], d.site_xpos[0],
                                   atol=1e-12)


def test_equalities_become_constraints_with_mujoco_residuals() -> None:
    path = data_path("fourbar.xml")
    robot = RobotModel.from_mjcf(path)
    assert robot.constraint_names == ("closure", "lock", "gear", "brake")
    assert robot.default_active == {"closure", "lock", "gear"}  # brake: active="false"
    kinds = {type(c).__name__: c for c in robot.robot_constraints}
    assert isinstance(kinds["JointCoupling"], JointCoupling)
    assert [c.type for c in robot.robot_constraints if isinstance(c, FrameConstraint)] == [
        "point", "weld", "weld"]
    mj, d = _mj(path)
    rng = np.random.default_rng(2)
    q, qd = rng.uniform(-1, 1, robot.n), rng.normal(size=robot.n)
    d.qpos[:], d.qvel[:] = q, qd
    mujoco.mj_forward(mj, d)
    ct = robot.constraint_terms(0.0, q, qd, {"closure", "lock", "gear"})
    rows = robot.row_slices({"closure", "lock", "gear"})
    efc_pos, efc_J = d.efc_pos[: d.ne], d.efc_J.reshape(-1, mj.nv)[: d.ne]
    # connect: MuJoCo's residual and Jacobian are p_1 − p_2 in world axes, as ours
    np.testing.assert_allclose(ct.phi[rows["closure"]], efc_pos[0:3], atol=1e-12)
    np.testing.assert_allclose(ct.A[rows["closure"]], efc_J[0:3], atol=1e-12)
    # weld: same position residual; rotation: MuJoCo uses sin(θ/2)·axis, we use θ·axis
    np.testing.assert_allclose(ct.phi[rows["lock"]][:3], efc_pos[3:6], atol=1e-12)
    theta = ct.phi[rows["lock"]][3:]
    ang = np.linalg.norm(theta)
    np.testing.assert_allclose(np.sin(ang / 2) * np.abs(theta) / ang, np.abs(efc_pos[6:9]),
                               atol=1e-12)
    # joint: polynomial coupling residual and Jacobian
    np.testing.assert_allclose(ct.phi[rows["gear"]], efc_pos[9:10], atol=1e-12)
    np.testing.assert_allclose(ct.A[rows["gear"]], efc_J[9:10], atol=1e-12)
    # satisfied in the reference configuration, as MuJoCo's compiler assumes
    every = robot.constraint_names
    assert np.abs(robot.constraint_residual(0.0, robot.from_mujoco_qpos(mj.qpos0), every)).max() < 1e-7


def test_constrained_mjcf_solution_satisfies_equalities() -> None:
    robot, state = fourbar_mjcf()
    q = state.q
    ct0 = robot.constraint_terms(0.0, q, np.zeros(robot.n))
    # 10 rows, rank 4: one degree of freedom (redundant planar connect and 1-dof weld)
    assert ct0.A.shape == (10, 5)
    _, s, Vt = np.linalg.svd(ct0.A)
    assert int(np.sum(s > 1e-10)) == 4
    qd = Vt[-1] * 1.3
    mt = robot.evaluate(0.0, q, qd)
    f = mt.B @ np.array([0.4]) + mt.f_passive
    sol = solve_dynamics(mt.M, mt.h, mt.constraints.A, mt.constraints.gamma, f)
    ct = mt.constraints
    assert int(sol.rank) == 4
    assert np.abs(ct.A @ sol.qdd + ct.gamma).max() < 1e-10
    assert np.abs(sol.P @ (mt.M @ sol.qdd - f - mt.h)).max() < 1e-10
    assert np.abs(ct.velocity).max() < 1e-12
    # the lock weld freezes the small pendulum relative to the rocker; the gear couples the wheel
    i = robot.coordinate_names.index
    assert abs(sol.qdd[i("lock")]) < 1e-10
    assert abs(sol.qdd[i("wheel")] + 2 * sol.qdd[i("crank")]) < 1e-10
    # switching the brake on locks the whole mechanism
    braked = solve_dynamics(*_terms(robot, q, qd * 0, robot.default_active | {"brake"}), f)
    assert np.abs(braked.qdd).max() < 1e-10


def _terms(robot, q, qd, active):
    mt = robot.evaluate(0.0, q, qd, active)
    return mt.M, mt.h, mt.constraints.A, mt.constraints.gamma


def test_unsupported_mjcf_features_are_rejected(tmp_path) -> None:
    path = tmp_path / "spring.xml"
    path.write_text('<mujoco><worldbody><body><joint name="j" stiffness="3"/>'
                    '<geom size="0.1"/></body></worldbody></mujoco>')
    with pytest.raises(ModelError, match="stiffness"):
        RobotModel.from_mjcf(path)


def test_free_joint_damping_is_rejected(tmp_path) -> None:
    path = tmp_path / "damped.xml"
    path.write_text('<mujoco><worldbody><body><joint name="f" type="free" damping="1"/>'
                    '<geom size="0.1"/></body></worldbody></mujoco>')
    with pytest.raises(ModelError, match="damping"):
        RobotModel.from_mjcf(path)
