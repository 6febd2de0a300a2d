"""Robot drivers beyond joints (issue #22, "drivers everywhere"): a frame point on a path
(:class:`PathDriver`, time functions as spline, expression or sampled array) and a prescribed
distance between two frame points (:class:`DistanceDriver`), compiled in the engine.

References: closed-form inverse kinematics of a planar 2R arm (the tip on a circle), the law of
cosines (a one-link arm lifted by a linear actuator), the Python/Pinocchio evaluation of the same
rows (``_evaluate_pinocchio``: Pinocchio's frame Jacobians and classical accelerations) including
a free-floating body (quaternion coordinates), and the inverse dynamics of the undriven arm.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pin = pytest.importorskip("pinocchio")

import nonmin  # noqa: E402
from nonmin.errors import InputError  # noqa: E402
from nonmin.model import Expression, Polynomial, Sampled, Spline, assemble  # noqa: E402
from nonmin.model.robots import DistanceDriver, PathDriver, RobotModel  # noqa: E402

L1, L2 = 1.0, 0.8

ARM2 = f"""<?xml version="1.0"?>
<robot name="arm2">
  <link name="base"/>
  <link name="link1">
    <inertial><origin xyz="{L1 / 2} 0 0"/><mass value="1.0"/>
      <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.09" iyz="0" izz="0.09"/></inertial>
  </link>
  <link name="link2">
    <inertial><origin xyz="{L2 / 2} 0 0"/><mass value="0.7"/>
      <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.04" iyz="0" izz="0.04"/></inertial>
  </link>
  <joint name="shoulder" type="revolute">
    <parent link="base"/><child link="link1"/><axis xyz="0 1 0"/>
    <limit lower="-3" upper="3" effort="10" velocity="1"/>
  </joint>
  <joint name="elbow" type="revolute">
    <parent link="link1"/><child link="link2"/><origin xyz="{L1} 0 0"/><axis xyz="0 1 0"/>
    <limit lower="-3" upper="3" effort="10" velocity="1"/>
  </joint>
</robot>
"""


def _arm2(tmp_path: Path) -> RobotModel:
    p = tmp_path / "arm2.urdf"
    p.write_text(ARM2)
    return RobotModel.from_urdf(p, joint_limits="ignore")


def _ik(x: np.ndarray, z: np.ndarray) -> np.ndarray:
    """Joint angles (elbow θ2 > 0) with the tip at (x, 0, z): about +y, x → (cos θ, −sin θ)."""
    zz = -z
    c2 = (x * x + zz * zz - L1 * L1 - L2 * L2) / (2 * L1 * L2)
    th2 = np.arccos(c2)
    th1 = np.arctan2(zz, x) - np.arctan2(L2 * np.sin(th2), L1 + L2 * np.cos(th2))
    return np.stack([th1, th2], -1)


def test_tip_on_a_circle_follows_the_inverse_kinematics(tmp_path: Path) -> None:
    """The tip of a 2R arm driven along a circle (x, z expressions; y free: the arm is planar)
    moves the joints as the closed-form inverse kinematics says; the engine program is used."""
    free = _arm2(tmp_path)
    x = Expression("1.1 + 0.25*cos(2*t)")
    z = Expression("-0.4 + 0.25*sin(2*t)")
    model = free.replace(robot_constraints=(PathDriver("pen", "link2", x=x, z=z, point=[L2, 0.0, 0.0]),))
    assert model.engine_program() is not None
    assert model.constraint("pen").kind == "rheonomic" and model.constraint("pen").dim == 2
    q0 = _ik(np.array([1.35]), np.array([-0.4]))[0]
    st = assemble(model, q0, t=0.0)
    te = np.linspace(0.0, 1.5, 16)
    traj = nonmin.simulate(model, 1.5, st, dt=1e-3, t_eval=te)
    want = _ik(1.1 + 0.25 * np.cos(2 * te), -0.4 + 0.25 * np.sin(2 * te))
    np.testing.assert_allclose(traj.q, want, atol=1e-9)
    tip = np.array([model.frame_placement(q, "pen:b")[:3, 3] for q in traj.q])
    np.testing.assert_allclose(tip[:, 0], 1.1 + 0.25 * np.cos(2 * te), atol=1e-9)
    assert traj.velocity_residual_norm.max() < 1e-9


def test_path_as_spline_and_sampled_array_and_its_force(tmp_path: Path) -> None:
    """x(t) a spline through knots and z(t) a sampled array: the tip follows both; the driver's
    reaction (force on the tip, world axes) reproduces the generalized force, and the joint
    torques that the undriven arm needs for that motion (inverse dynamics) equal Jᵀ F."""
    free = _arm2(tmp_path)
    xs = Spline([0.0, 0.5, 1.0, 1.5], [1.3, 1.2, 1.0, 1.1])
    zs = Sampled(-0.4 + 0.1 * np.sin(np.linspace(0.0, 3.0, 31)), dt=0.05)
    model = free.replace(robot_constraints=(PathDriver("pen", "link2", x=xs, z=zs, point=[L2, 0.0, 0.0]),))
    q0 = _ik(np.array([1.3]), np.array([-0.4]))[0]
    te = np.linspace(0.0, 1.5, 7)
    traj = nonmin.simulate(model, 1.5, assemble(model, q0, t=0.0), dt=1e-3, t_eval=te).with_reactions(model)
    tip = np.array([model.frame_placement(q, "pen:b")[:3, 3] for q in traj.q])
    np.testing.assert_allclose(tip[:, 0], [xs(t)[0] for t in te], atol=1e-9)
    np.testing.assert_allclose(tip[:, 2], [zs(t)[0] for t in te], atol=1e-9)
    r = traj.reactions["pen"]
    assert r.kind == "frame" and r.body_b == "link2"
    for k in range(len(te)):
        F = np.zeros(3)
        F[[0, 2]] = r.multipliers[k]  # the force on the tip along x and z
        J = pin.computeFrameJacobian(model.pin_model, model.pin_model.createData(), traj.q[k],
                                     model.pin_model.getFrameId("link2"), pin.LOCAL_WORLD_ALIGNED)  # fmt: skip
        Jtip = J[:3] - np.cross(  # the tip point: v_p = v_o + ω × (p − o)
            model.frame_placement(traj.q[k], "pen:b")[:3, 3] - model.frame_placement(traj.q[k], "link2")[:3, 3],
            J[3:].T,
        ).T
        np.testing.assert_allclose(Jtip.T @ F, traj.f_c[k], atol=1e-9 * max(1.0, np.abs(traj.f_c[k]).max()))
        # the world force on the tip, in the link2 frame
        R2 = model.frame_placement(traj.q[k], "pen:b")[:3, :3]
        np.testing.assert_allclose(r.force_b[k], R2.T @ F, atol=1e-12 * max(1.0, np.abs(F).max()))
        inv = nonmin.inverse_dynamics(free, traj.q[k], traj.qd[k], traj.qdd[k], t=te[k])
        assert inv.ok, inv.message
        np.testing.assert_allclose(inv.u, Jtip.T @ F, atol=1e-7 * max(1.0, np.abs(F).max()))


def test_distance_driver_lifts_the_arm_by_the_law_of_cosines(tmp_path: Path) -> None:
    """One link (the 2R arm's elbow held by a weld-free joint driver would do; here link1 alone)
    lifted by an actuator from the world point (a, 0, 0) to the link point at s: its length
    ℓ(t) gives the angle cos θ = (a² + s² − ℓ²)/(2 a s)."""
    from nonmin.model.robots import JointDriver

    free = _arm2(tmp_path)
    a, s = 0.6, 0.5
    ell = Expression("0.5 + 0.2*t")
    model = free.replace(robot_constraints=(
        DistanceDriver("cylinder", "universe", "link1", ell, placement_a=[a, 0.0, 0.0], placement_b=[s, 0.0, 0.0]),
        JointDriver("elbow_fixed", "elbow", 0.0),
    ))  # fmt: skip
    assert model.engine_program() is not None
    th0 = np.arccos((a * a + s * s - 0.25) / (2 * a * s))
    te = np.linspace(0.0, 1.0, 11)
    # the link turns towards −z (negative angle about y lifts it: z = −s sin θ > 0 for θ < 0)
    traj = nonmin.simulate(model, 1.0, assemble(model, [-th0, 0.0], t=0.0), dt=1e-3, t_eval=te)
    L = 0.5 + 0.2 * te
    np.testing.assert_allclose(traj.q[:, 0], -np.arccos((a * a + s * s - L * L) / (2 * a * s)), atol=1e-9)
    with pytest.raises(InputError, match="> 0"):
        DistanceDriver("bad", "universe", "link1", 0.0)
    with pytest.raises(InputError, match="at least one"):
        PathDriver("bad", "link1")


def test_engine_rows_equal_pinocchio_with_a_floating_body() -> None:
    """Path and distance rows on the two-arm grasp (a free-floating box: quaternion coordinates):
    A, γ, φ and A q̇ + φ_t of the engine program equal the Pinocchio evaluation; Ȧ equals the
    finite difference of A along q̇."""
    from nonmin.model.robots import two_arm_grasp

    grasp, st = two_arm_grasp()
    cons = (
        *grasp.robot_constraints,
        PathDriver("hold", "box_right", x=Expression("0.3 + 0.1*sin(t)"), y=Spline([0, 1, 2], [0.1, 0.0, 0.2]),
                   z=Polynomial([0.5, 0.1, -0.05]), point=[0.01, 0.02, -0.03]),
        PathDriver("lift", "box_left", z=Expression("0.4 + 0.1*t*t")),
        DistanceDriver("reach", "left_ee", "box_right", Expression("0.35 + 0.05*cos(3*t)"),
                       placement_a=[0.02, 0.0, 0.01]),
    )
    model = grasp.replace(robot_constraints=cons)
    assert model.engine_program() is not None
    names = frozenset(c.name for c in model.constraints)
    rng = np.random.default_rng(5)
    for t in (0.0, 0.6, 1.7):
        q = st.q + 0.1 * rng.normal(size=model.n)
        qd = rng.normal(size=model.n)
        e = model.evaluate(t, q, qd, names).constraints
        p = model._evaluate_pinocchio(t, q, qd, names).constraints
        for x, y in zip((e.A, e.gamma, e.phi, e.velocity), (p.A, p.gamma, p.phi, p.velocity), strict=True):
            np.testing.assert_allclose(x, y, rtol=1e-10, atol=1e-10)
    # Ȧ from the engine (controllers' jacobian_dot) vs a central difference of A along q̇
    q = st.q + 0.05 * rng.normal(size=model.n)
    qd = rng.normal(size=model.n)
    h = 1e-6
    Ad_fd = (model.constraint_jacobian(0.3, q + h * qd, names) - model.constraint_jacobian(0.3, q - h * qd, names)) / (2 * h)
    Ad = model.constraint_jacobian_dot(0.3, q, qd, names)
    rows = model.row_slices(names)
    for nm in ("hold", "lift", "reach"):
        np.testing.assert_allclose(Ad[rows[nm]], Ad_fd[rows[nm]], atol=1e-6)
