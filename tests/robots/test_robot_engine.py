"""The compiled engine's rigid-body algorithms (engine/include/nonmin/rbd) against Pinocchio.

Every quantity the engine computes for a robot — joint and frame placements, frame Jacobians
(LOCAL_WORLD_ALIGNED), frame velocities and classical accelerations, CRBA, RNEA, potential
energy, and RobotModel.evaluate's M, h, f_p, B, A, γ, φ, A qd with every constraint type — is
compared with Pinocchio at random states, to ``REL`` relative to the quantity's magnitude, on
the example robots of nonmin.model.robots (URDF, MJCF, free-flyer box, spherical pendulum),
Pinocchio's random humanoid, an MJCF tree with free, ball, slide and unaligned hinge joints, and
the robots of example-robot-data (fixed-base arms and free-flyer legged robots and humanoids).
"""

from __future__ import annotations

import zlib
from pathlib import Path

import numpy as np
import pytest

# the example robots' URDF joint limits are not what these tests are about
pytestmark = pytest.mark.filterwarnings("ignore::nonmin.errors.JointLimitWarning")

pin = pytest.importorskip("pinocchio")

from nonmin.errors import InputError, NonFiniteError  # noqa: E402
from nonmin.model.robots import FrameConstraint, JointCoupling, RobotModel, data_path  # noqa: E402
from nonmin.model.robots._examples import (  # noqa: E402
    fourbar,
    fourbar_mjcf,
    serial_arm,
    two_arm_grasp,
)

REL = 1e-12  # relative agreement with Pinocchio (to the largest entry of the quantity)
LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
ERD = Path(pin.__file__).resolve().parents[4] / "share" / "example-robot-data" / "robots"

#: example-robot-data robots: (URDF below ERD, free-flyer base)
ERD_ROBOTS = {
    "ur5": ("ur_description/urdf/ur5_robot.urdf", False),
    "panda": ("panda_description/urdf/panda.urdf", False),
    "baxter": ("baxter_description/urdf/baxter.urdf", False),
    "hyq": ("hyq_description/robots/hyq_no_sensors.urdf", True),
    "solo12": ("solo_description/robots/solo12.urdf", True),
    "anymal": ("anymal_b_simple_description/robots/anymal.urdf", True),
    "go1": ("go1_description/urdf/go1.urdf", True),
    "talos": ("talos_data/robots/talos_full_v2.urdf", True),
    "romeo": ("romeo_description/urdf/romeo.urdf", True),
}

FREE_MJCF = """
<mujoco model="free_ball">
  <option gravity="0.3 -0.2 -9.81"/>
  <worldbody>
    <body name="base" pos="0.1 0.2 1.0" quat="0.9 0.1 0.3 -0.2">
      <freejoint name="root"/>
      <geom type="box" size="0.1 0.2 0.05" density="800" pos="0.02 0 0.01"/>
      <body name="arm" pos="0.1 0 0" euler="0.2 0.1 0.4">
        <joint name="ball" type="ball" pos="0.01 0.02 0" armature="0.002" damping="0.1"/>
        <geom type="capsule" fromto="0 0 0 0 0 -0.3" size="0.02"/>
        <body name="hand" pos="0 0 -0.3">
          <joint name="slide" type="slide" axis="0.3 0.5 1" damping="0.3"/>
          <joint name="twist" type="hinge" axis="1 0.2 0" pos="0 0.01 0.02" armature="0.01"/>
          <geom type="sphere" size="0.04" pos="0.01 0 -0.02"/>
          <site name="tip" pos="0 0 -0.05"/>
        </body>
      </body>
    </body>
  </worldbody>
</mujoco>
"""


def _rel(x, y) -> float:
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    assert x.shape == y.shape, (x.shape, y.shape)
    if x.size == 0:
        return 0.0
    scale = float(np.abs(y).max())
    err = float(np.abs(x - y).max())
    return err / scale if scale > 0.0 else err


def _every_constraint_type(robot: RobotModel, rng: np.random.Generator) -> RobotModel:
    """The robot with one constraint of every frame type between two of its frames."""
    pm = robot.pin_model  # without the constraint frames
    names = [pm.frames[i].name for i in range(1, len(pm.frames))]
    fa, fb = names[-1], names[len(names) // 2]
    off = rng.normal(size=3) * 0.1
    scalar = [b.joint for b in robot._blocks if b.kind == "vector" and b.nq == 1]
    cons: list = [
        FrameConstraint.point("pt", fa, fb, placement_a=off),
        FrameConstraint.weld("wd", fa, placement_b=[0.1, 0.2, 0.3]),
        FrameConstraint.hinge("hg", fb, fa, axis=rng.normal(size=3)),
        FrameConstraint.planar_point("pp", fa, normal=rng.normal(size=3)),
        FrameConstraint.planar_weld("pw", fb, fa, normal=rng.normal(size=3)),
        FrameConstraint.point_on_plane("pop", fb, fa, normal=rng.normal(size=3),
                                       plane_placement=off),
        FrameConstraint.contact("ct", fa, normal=(0.1, 0.2, 1.0)),
    ]
    if len(scalar) >= 2:
        cons += [JointCoupling("cp", scalar[0], scalar[-1], polycoef=(0.1, -1.0, 0.2, 0.05, 0.01),
                               reference1=0.2, reference2=-0.1)]
    return robot.replace(robot_constraints=tuple(robot.robot_constraints) + tuple(cons))


def _check_algorithms(robot: RobotModel, rng: np.random.Generator, states: int = 2,
                      frames: int = 12) -> None:
    prog = robot.engine_program()
    assert prog is not None, f"{robot.name}: no engine program"
    pm = robot.pinocchio_model
    d = pm.createData()
    nf = len(pm.frames)
    pick = rng.choice(nf, size=min(frames, nf), replace=False)
    for _ in range(states):
        q = robot.pinocchio_configuration(robot.random_configuration(rng))
        v, a = rng.normal(size=pm.nv), rng.normal(size=pm.nv)
        pin.forwardKinematics(pm, d, q, v, a)
        pin.updateFramePlacements(pm, d)
        pin.computeJointJacobians(pm, d, q)
        oMi, oMf = prog.placements(q)
        for j in range(1, pm.njoints):
            assert _rel(oMi[j - 1], d.oMi[j].homogeneous) < REL, (robot.name, pm.names[j])
        for f in range(nf):
            assert _rel(oMf[f], d.oMf[f].homogeneous) < REL, (robot.name, pm.frames[f].name)
        for f in pick:
            f = int(f)
            J = prog.frame_jacobian(q, f)
            assert _rel(J, pin.getFrameJacobian(pm, d, f, LWA)) < REL, (robot.name, f)
            mot = prog.frame_motion(q, v, a, f)
            vel = pin.getFrameVelocity(pm, d, f, LWA)
            acc = pin.getFrameClassicalAcceleration(pm, d, f, LWA)
            ref = np.array([vel.linear, vel.angular, acc.linear, acc.angular])
            assert _rel(mot, ref) < REL, (robot.name, pm.frames[f].name)
        assert _rel(prog.crba(q), pin.crba(pm, pm.createData(), q)) < REL, robot.name
        if not robot._structural:  # q = Pinocchio's q, qd = v: C is Pinocchio's C_v
            Cv = pin.computeCoriolisMatrix(pm, pm.createData(), q, v)
            assert _rel(prog.coriolis_matrix(q, v), Cv) < REL, robot.name
        assert _rel(prog.rnea(q, v, a), pin.rnea(pm, pm.createData(), q, v, a)) < REL, robot.name
        nle = prog.rnea(q, v, np.zeros(pm.nv))
        assert _rel(nle, pin.nonLinearEffects(pm, pm.createData(), q, v)) < REL, robot.name
        V = pin.computePotentialEnergy(pm, pm.createData(), q)
        assert abs(prog.potential_energy(q) - V) <= REL * max(1.0, abs(V)), robot.name


def _accurate_log3(R: np.ndarray) -> np.ndarray:
    """log3 through the quaternion (accurate near π, where pin.log3 loses up to ~1e-11)."""
    from scipy.spatial.transform import Rotation

    return Rotation.from_matrix(R).as_rotvec()


def _accurate_log_rows(robot: RobotModel, q: np.ndarray, act, phi: np.ndarray) -> np.ndarray:
    """φ with the rotation rows of weld / planar_weld recomputed by :func:`_accurate_log3`."""
    phi = phi.copy()
    rows = robot.row_slices(act)
    for c in robot.robot_constraints:
        if c.name not in rows or getattr(c, "type", None) not in ("weld", "planar_weld"):
            continue
        Ra = robot.frame_placement(q, f"{c.name}:a")[:3, :3]
        Rb = robot.frame_placement(q, f"{c.name}:b")[:3, :3]
        w = _accurate_log3(Ra @ Rb.T)
        sl = rows[c.name]
        if c.type == "weld":
            phi[sl.start + 3 : sl.stop] = w
        else:
            phi[sl.start + 2] = c.axis @ w
    return phi


def _check_evaluate(robot: RobotModel, rng: np.random.Generator, states: int = 2) -> None:
    """RobotModel.evaluate through the engine vs the same terms from Pinocchio's algorithms."""
    every = frozenset(robot.constraint_names)
    pm = robot.pinocchio_model
    for _ in range(states):
        q = robot.random_configuration(rng)
        if robot._structural:  # quaternions off the unit sphere: T uses |ε|
            q = q * 1.0
            for b in robot._blocks:
                if b.kind != "vector":
                    s = b.iq + (3 if b.kind == "freeflyer" else 0)
                    q[s : s + 4] *= 1.3
        qd = rng.normal(size=robot.n)
        for act in (every, robot.default_active):
            mt = robot.evaluate(0.0, q, qd, act)
            ref = robot._evaluate_pinocchio(0.0, q, qd, robot.resolve_active(act))
            for name in ("M", "h", "f_passive", "B"):
                assert _rel(getattr(mt, name), getattr(ref, name)) < REL, (robot.name, name)
            for name in ("A", "gamma", "phi", "velocity"):
                x, y = getattr(mt.constraints, name), getattr(ref.constraints, name)
                if name == "phi":
                    y = _accurate_log_rows(robot, q, act, y)
                assert _rel(x, y) < REL, (robot.name, name)
            assert mt.constraints.holonomic.all()
            np.testing.assert_array_equal(mt.M, mt.M.T)
        # the Christoffel Coriolis matrix and Ȧ (controllers) against Pinocchio's
        every_act = robot.resolve_active(every)
        assert _rel(robot.coriolis_matrix(q, qd), robot._coriolis_matrix_pinocchio(q, qd)) < REL
        assert _rel(robot.constraint_jacobian_dot(0.0, q, qd, every),
                    robot._constraint_jacobian_dot_pinocchio(0.0, q, qd, every_act)) < REL
        part = robot.default_active
        assert _rel(robot.constraint_jacobian_dot(0.0, q, qd, part),
                    robot._constraint_jacobian_dot_pinocchio(0.0, q, qd,
                                                            robot.resolve_active(part))) < REL
        # the single-term methods agree with evaluate
        mt = robot.evaluate(0.0, q, qd, every)
        ct = robot.constraint_terms(0.0, q, qd, every)
        for x, y in zip(ct, mt.constraints):
            np.testing.assert_array_equal(x, y)
        np.testing.assert_array_equal(robot.mass_matrix(q), mt.M)
        qn = robot.pinocchio_configuration(q)
        v = robot.to_pinocchio_velocity(q, qd)
        T = robot.velocity_map(q)
        g_v = pin.computeGeneralizedGravity(pm, pm.createData(), qn)
        assert _rel(robot.conservative_force(q), -T.T @ g_v) < REL
        V = pin.computePotentialEnergy(pm, pm.createData(), qn)
        assert abs(robot.potential_energy(q) - V) <= REL * max(1.0, abs(V))
        Mv = pin.crba(pm, pm.createData(), qn)
        ke = 0.5 * v @ Mv @ v
        assert abs(robot.kinetic_energy(q, qd) - ke) <= REL * max(1.0, ke)
        assert abs(robot.energy(q, qd) - ke - V) <= REL * max(1.0, abs(ke + V))
        for name in ("universe", pm.frames[len(pm.frames) - 1].name):
            d = pm.createData()
            pin.framesForwardKinematics(pm, d, qn)
            H = d.oMf[robot.frame_id(name)].homogeneous
            assert _rel(robot.frame_placement(q, name), H) < REL


def _erd(name: str) -> RobotModel:
    rel, free = ERD_ROBOTS[name]
    path = ERD / rel
    if not path.is_file():
        pytest.skip(f"example-robot-data ({rel}) is not installed")
    return RobotModel.from_urdf(path, root_joint="freeflyer" if free else None,
                                joint_limits="ignore")


def _mjcf_tree(tmp_path: Path) -> RobotModel:
    path = tmp_path / "free_ball.xml"
    path.write_text(FREE_MJCF)
    return RobotModel.from_mjcf(path)


def _example(name: str, tmp_path: Path) -> RobotModel:
    if name == "serial_arm":
        return serial_arm()[0]
    if name == "two_arm_grasp":
        return two_arm_grasp()[0]
    if name == "fourbar_mjcf":
        return fourbar_mjcf()[0]
    if name.startswith("fourbar_"):
        return fourbar(name.removeprefix("fourbar_"))[0]
    if name == "arm4_damped":
        return RobotModel.from_urdf(data_path("arm4.urdf"), damping=[0.1, 0.2, 0.3, 0.4],
                                    joint_limits="ignore")
    if name == "two_arms_free":
        return RobotModel.from_urdf(data_path("two_arms.urdf"), actuated=["box", "left_yaw"],
                                    joint_limits="ignore")
    if name == "humanoid":
        return RobotModel.from_pinocchio(pin.buildSampleModelHumanoidRandom(), name="humanoid")
    if name == "mjcf_free_ball":
        return _mjcf_tree(tmp_path)
    raise AssertionError(name)


EXAMPLES = [
    "serial_arm",
    "two_arm_grasp",
    "fourbar_mjcf",
    "fourbar_point",
    "fourbar_planar_point",
    "fourbar_hinge",
    "fourbar_weld",
    "fourbar_planar_weld",
    "arm4_damped",
    "two_arms_free",
    "humanoid",
    "mjcf_free_ball",
]


@pytest.mark.parametrize("name", EXAMPLES)
def test_example_robots_match_pinocchio(name: str, tmp_path: Path) -> None:
    robot = _example(name, tmp_path)
    rng = np.random.default_rng(zlib.crc32(name.encode()))
    _check_algorithms(robot, rng)
    _check_evaluate(robot, rng)
    _check_evaluate(_every_constraint_type(robot, rng), rng)


@pytest.mark.parametrize("name", sorted(ERD_ROBOTS))
def test_example_robot_data_robots_match_pinocchio(name: str) -> None:
    robot = _erd(name)
    rng = np.random.default_rng(sum(map(ord, name)))
    _check_algorithms(robot, rng, states=1)
    _check_evaluate(_every_constraint_type(robot, rng), rng, states=1)


def test_bad_states_raise_typed_errors() -> None:
    robot, state = two_arm_grasp()
    q = state.q.copy()
    q[3:7] = 0.0
    with pytest.raises(InputError, match="quaternion of joint 'box'"):
        robot.evaluate(0.0, q, state.qd)
    q = state.q.copy()
    q[8] = np.nan
    with pytest.raises(NonFiniteError, match="finite"):
        robot.evaluate(0.0, q, state.qd)
    qd = state.qd.copy()
    qd[0] = np.inf
    with pytest.raises(NonFiniteError, match="finite"):
        robot.constraint_terms(0.0, state.q, qd)


def test_unsupported_joint_types_fall_back_to_pinocchio() -> None:
    """A tree with a joint the engine lacks (SphericalZYX) evaluates through Pinocchio."""
    pm = pin.Model()
    j = pm.addJoint(0, pin.JointModelSphericalZYX(), pin.SE3.Identity(), "zyx")
    pm.appendBodyToJoint(j, pin.Inertia.Random(), pin.SE3.Identity())
    robot = RobotModel.from_pinocchio(pm, name="zyx")
    assert robot.engine_program() is None
    q = np.array([0.1, 0.2, 0.3])
    np.testing.assert_allclose(robot.mass_matrix(q), pin.crba(pm, pm.createData(), q), rtol=1e-14)


def test_tree_program_through_the_program_interface() -> None:
    """The robot's engine program is a Program: evaluate / evaluate_batch (all rows, any mask)
    give RobotModel.evaluate's terms; the energies are ½ qdᵀ M qd and Pinocchio's potential."""
    from nonmin import _engine

    robot, _ = two_arm_grasp()
    prog = robot.engine_program()
    assert isinstance(prog, _engine.Program)
    assert (prog.n, prog.k, prog.m_all) == (robot.n, robot.k, robot.num_rows(robot.constraint_names))
    assert [c[0] for c in prog.constraints] == list(robot.constraint_names)
    rng = np.random.default_rng(11)
    N = 3
    qs = np.array([robot.random_configuration(rng) for _ in range(N)])
    qds = rng.normal(size=(N, robot.n))
    act = robot.resolve_active({"grasp_right"})  # grasp_left and the joint limits off
    mask = np.array([c.name in act for c in robot.constraints], dtype=np.uint8)
    starts = np.cumsum([0] + [c.dim for c in robot.constraints])
    rows = np.concatenate([np.arange(starts[i], starts[i + 1]) for i, c in enumerate(robot.constraints)
                           if c.name in act])
    batch = prog.evaluate_batch(np.zeros(N), qs, qds, mask, _engine.NEED_ALL)
    for i in range(N):
        mt = robot.evaluate(0.0, qs[i], qds[i], act)
        one = prog.evaluate(0.0, qs[i], qds[i], mask, _engine.NEED_ALL)
        for name in ("M", "h", "f_passive", "B"):
            np.testing.assert_array_equal(getattr(one, name), getattr(mt, name))
            np.testing.assert_array_equal(batch[name][i], getattr(mt, name))
        for name in ("A", "gamma", "phi", "velocity"):
            np.testing.assert_array_equal(np.asarray(getattr(one, name))[rows],
                                          getattr(mt.constraints, name))
            np.testing.assert_array_equal(batch[name][i][rows], getattr(mt.constraints, name))
        assert abs(batch["kinetic"][i] - 0.5 * qds[i] @ mt.M @ qds[i]) < REL * batch["kinetic"][i]
        assert batch["potential"][i] == robot.potential_energy(qs[i])


def test_engine_forward_is_model_plus_kernel() -> None:
    """_engine.Forward on the robot's program (evaluation + the engine's solve in one call)
    gives the q̈ of RobotModel.evaluate + nonmin.core.forward_dynamics, for the full and a
    partial active set; Forward.batch on 2 threads is bitwise the single calls (the
    TreeProgram is evaluated from two threads at once)."""
    from nonmin import _engine
    from nonmin.core import forward_dynamics

    robot, _ = two_arm_grasp()
    prog = robot.engine_program()
    assert prog.thread_safe
    rng = np.random.default_rng(12)
    N = 6
    qs = np.array([robot.random_configuration(rng) for _ in range(N)])
    qds = rng.normal(size=(N, robot.n))
    base = tuple(c.name for c in robot.constraints if c.kind != "unilateral")  # not the joint limits
    for names in (base, ("grasp_right",)):
        act = robot.resolve_active(names)
        mask = [c.name in act for c in robot.constraints]
        fwd = _engine.Forward(prog, np.array(mask, dtype=np.uint8))
        qdd = np.empty(robot.n)
        single = np.empty((N, robot.n))
        for i in range(N):
            mt = robot.evaluate(0.0, qs[i], qds[i], names)
            ref = forward_dynamics(mt.M, mt.h + mt.f_passive, mt.constraints.A,
                                   mt.constraints.gamma)
            fwd(0.0, qs[i], qds[i], qdd)
            assert _rel(qdd, ref) < 1e-10
            single[i] = qdd
        np.testing.assert_array_equal(fwd.batch(np.zeros(N), qs, qds, nthreads=2), single)


def test_pickle_and_deepcopy_rebuild_the_engine_program() -> None:
    import copy
    import pickle

    robot, state = two_arm_grasp()
    ref = robot.evaluate(0.0, state.q, state.qd)
    for other in (pickle.loads(pickle.dumps(robot)), copy.deepcopy(robot)):
        assert other.engine_program() is not robot.engine_program()
        assert other.constraint_names == robot.constraint_names
        mt = other.evaluate(0.0, state.q, state.qd)
        np.testing.assert_array_equal(mt.M, ref.M)
        np.testing.assert_array_equal(mt.constraints.A, ref.constraints.A)


@pytest.mark.parametrize("delta", [0.5, 0.05, 0.014, 1e-3, 1e-6])
def test_weld_rotation_residual_near_pi(delta: float) -> None:
    """φ_rot = log3(R_a R_bᵀ) when the frames are turned by π − δ about a known axis: the
    engine's log3 is accurate to round-off there (Pinocchio's log3 is off by up to ~3e-11 for
    δ ~ 1e-2)."""
    robot, state = two_arm_grasp()
    q = state.q
    axis = np.array([0.3, -0.5, 0.8])
    axis /= np.linalg.norm(axis)
    theta = np.pi - delta
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    Rot = np.eye(3) + np.sin(theta) * K + (1 - np.cos(theta)) * (K @ K)
    H = robot.frame_placement(q, "left_ee")
    Hb = np.eye(4)
    Hb[:3, :3] = H[:3, :3] @ Rot
    Hb[:3, 3] = H[:3, 3]
    weld = FrameConstraint.weld("w", "left_ee", placement_b=Hb)
    r = robot.replace(robot_constraints=(weld,))
    phi = r.constraint_residual(0.0, q, {"w"})
    # R_a R_bᵀ = R Rotᵀ Rᵀ with R = R_ee: log = −θ R a
    expected = -theta * (H[:3, :3] @ axis)
    np.testing.assert_allclose(phi[1:4], 0.0, atol=1e-15)
    assert np.abs(phi[4:] - expected).max() < 4 * np.finfo(float).eps / np.sin(theta) + 1e-15
