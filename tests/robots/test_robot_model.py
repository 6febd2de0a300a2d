"""RobotModel: dependent quaternion coordinates, Pinocchio terms, frame constraints, errors."""

from __future__ import annotations

import numpy as np
import pytest

pin = pytest.importorskip("pinocchio")

from nonmin import check_model  # noqa: E402
from nonmin.core import forward_dynamics  # noqa: E402
from nonmin.errors import InputError, ShapeError, UnknownNameError  # noqa: E402
from nonmin.model import Model  # noqa: E402
from nonmin.model.robots import (  # noqa: E402
    FrameConstraint,
    JointCoupling,
    RobotModel,
    data_path,
)
from nonmin.model.robots._examples import two_arm_grasp  # noqa: E402

FD_EPS = 1e-6
FD_TOL = 1e-6  # relative accuracy of central differences


def _fd(fun, x, direction, eps=FD_EPS):
    return (fun(x + eps * direction) - fun(x - eps * direction)) / (2 * eps)


def _rel_err(a, b):
    return float(np.abs(a - b).max() / max(1.0, np.abs(b).max()))


@pytest.fixture(scope="module")
def humanoid() -> RobotModel:
    return RobotModel.from_pinocchio(pin.buildSampleModelHumanoidRandom(), name="humanoid")


def _free_pendulum() -> RobotModel:
    """A free-floating box carrying a spherical pendulum (two quaternions, nq = 11, nv = 9)."""
    pm = pin.Model()
    j0 = pm.addJoint(0, pin.JointModelFreeFlyer(), pin.SE3.Identity(), "base")
    pm.appendBodyToJoint(j0, pin.Inertia(2.0, np.array([0.01, 0.0, 0.02]),
                                         np.diag([0.02, 0.03, 0.04])), pin.SE3.Identity())
    j1 = pm.addJoint(j0, pin.JointModelSpherical(), pin.SE3(np.eye(3), np.array([0.1, 0, 0])),
                     "ball")
    pm.appendBodyToJoint(j1, pin.Inertia(0.5, np.array([0.0, 0.0, -0.3]),
                                         np.diag([0.01, 0.012, 0.002])), pin.SE3.Identity())
    pm.addFrame(pin.Frame("tip", j1, pin.SE3(np.eye(3), np.array([0.0, 0.0, -0.4])),
                          pin.FrameType.OP_FRAME))
    return RobotModel.from_pinocchio(pm, name="free_pendulum")


# --------------------------------------------------------------------------- coordinates


def test_quaternion_coordinates_and_velocity_map(humanoid: RobotModel) -> None:
    r = humanoid
    assert (r.n, r.nv) == (r.pinocchio_model.nq, r.pinocchio_model.nv)
    assert r.coordinate_names[:7] == tuple(f"root_joint.{s}" for s in
                                           ("x", "y", "z", "qx", "qy", "qz", "qw"))
    assert r.structural_constraints == {"root_joint.unit_quaternion"}
    # structural constraints are always active, whatever the user asks for
    assert r.resolve_active(()) == {"root_joint.unit_quaternion"}
    assert "root_joint" not in r.actuator_names and r.k == r.nv - 6
    rng = np.random.default_rng(0)
    q = r.random_configuration(rng)
    T = r.velocity_map(q)
    np.testing.assert_allclose(T @ np.array(pin.tangentMap(r.pinocchio_model, q)),
                               np.eye(r.nv), atol=1e-14)
    v = rng.normal(size=r.nv)
    np.testing.assert_allclose(r.to_pinocchio_velocity(q, r.from_pinocchio_velocity(q, v)), v,
                               atol=1e-14)
    # M is singular only along the radial quaternion direction
    M = r.mass_matrix(q)
    radial = np.zeros(r.n)
    radial[3:7] = q[3:7]
    np.testing.assert_allclose(M @ radial, 0.0, atol=1e-12)
    assert np.linalg.matrix_rank(M) == r.nv


def test_accelerations_equal_aba_mapped_through_T(humanoid: RobotModel) -> None:
    r = humanoid
    rng = np.random.default_rng(1)
    for _ in range(3):
        q = r.random_configuration(rng)
        v = rng.normal(size=r.nv)
        tau = rng.normal(size=r.nv)
        qd = r.from_pinocchio_velocity(q, v)
        mt = r.evaluate(0.0, q, qd)
        T = r.velocity_map(q)
        qdd = forward_dynamics(mt.M, mt.h, mt.constraints.A, mt.constraints.gamma, T.T @ tau)
        a = pin.aba(r.pinocchio_model, r.pinocchio_model.createData(), q, v, tau)
        assert _rel_err(r.to_pinocchio_acceleration(q, qd, qdd), a) < 1e-10
        # the quaternion part of qdd keeps ε·ε = 1 at second order: ε·ε̈ + ε̇·ε̇ = 0
        assert abs(q[3:7] @ qdd[3:7] + qd[3:7] @ qd[3:7]) < 1e-12


def test_christoffel_coriolis_gravity_and_skew(humanoid: RobotModel) -> None:
    """C is the Christoffel matrix of M(q) in the dependent coordinates (finite differences)."""
    r = humanoid
    rng = np.random.default_rng(2)
    q = r.random_configuration(rng)
    qd = r.from_pinocchio_velocity(q, rng.normal(size=r.nv))
    n = r.n
    dM = [_fd(r.mass_matrix, q, e) for e in np.eye(n)]
    C_ref = np.zeros((n, n))
    for k in range(n):
        C_ref += 0.5 * (dM[k] * qd[k])
    G = np.array(dM)  # G[k, i, j] = ∂M_ij/∂q_k
    C_ref += 0.5 * (np.einsum("jik,k->ij", G, qd) - np.einsum("ijk,k->ij", G, qd))
    C = r.coriolis_matrix(q, qd)
    assert _rel_err(C, C_ref) < FD_TOL
    Mdot = np.einsum("kij,k->ij", G, qd)
    S = Mdot - 2 * C
    assert np.abs(S + S.T).max() < FD_TOL * np.abs(Mdot).max()
    grad_V = np.array([_fd(r.potential_energy, q, e) for e in np.eye(n)])
    assert _rel_err(r.conservative_force(q), -grad_V) < FD_TOL


def test_energy_conservation_free_floating_rk4() -> None:
    """Free-floating box + spherical pendulum under gravity: T + V conserved by RK4."""
    r = _free_pendulum()
    rng = np.random.default_rng(3)
    q = r.random_configuration(rng)
    qd = r.from_pinocchio_velocity(q, rng.normal(size=r.nv))

    def rhs(x):
        qq, vv = x[: r.n], x[r.n :]
        mt = r.evaluate(0.0, qq, vv)
        ct = mt.constraints
        return np.concatenate([vv, forward_dynamics(mt.M, mt.h, ct.A, ct.gamma)])

    x = np.concatenate([q, qd])
    E0 = r.energy(q, qd)
    dt, steps = 2e-3, 250
    for _ in range(steps):
        k1 = rhs(x)
        k2 = rhs(x + 0.5 * dt * k1)
        k3 = rhs(x + 0.5 * dt * k2)
        k4 = rhs(x + dt * k3)
        x = x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    q1, qd1 = x[: r.n], x[r.n :]
    assert abs(r.energy(q1, qd1) - E0) < 1e-7 * max(1.0, abs(E0))
    for sl in (slice(3, 7), slice(7, 11)):
        assert abs(np.linalg.norm(q1[sl]) - 1.0) < 1e-9
    # the free body's centre of mass falls freely: p_com(t) = p0 + v0 t + ½ g t²
    pm = r.pinocchio_model
    com0 = pin.centerOfMass(pm, pm.createData(), r.pinocchio_configuration(q),
                            r.to_pinocchio_velocity(q, qd))
    d = pm.createData()
    pin.centerOfMass(pm, d, r.pinocchio_configuration(q), r.to_pinocchio_velocity(q, qd))
    vcom0 = np.array(d.vcom[0])
    com1 = pin.centerOfMass(pm, pm.createData(), r.pinocchio_configuration(q1))
    t = dt * steps
    np.testing.assert_allclose(com1, com0 + vcom0 * t + 0.5 * np.array([0, 0, -9.81]) * t**2,
                               atol=1e-9)


# --------------------------------------------------------------------------- constraints


def _all_types_robot() -> RobotModel:
    cons = [
        FrameConstraint.point("pt", "left_ee", "box_left", placement_a=[0.01, 0.02, 0.0]),
        FrameConstraint.weld("wd", "right_ee", "box_right"),
        FrameConstraint.hinge("hg", "left_ee", "right_ee", axis=(0.2, 1.0, 0.1)),
        FrameConstraint.planar_point("pp", "left_ee", normal=(0.0, 1.0, 0.0)),
        FrameConstraint.planar_weld("pw", "right_ee", "box", normal=(0.1, 0.2, 1.0)),
        FrameConstraint.point_on_plane("pop", "box", "left_ee", normal=(1.0, 0.5, 0.0),
                                       plane_placement=[0.0, 0.0, 0.1]),
        FrameConstraint.contact("ct", "right_ee", normal=(0.0, 0.3, 1.0)),
        JointCoupling("cp", "left_elbow", "right_elbow", polycoef=(0.1, -1.0, 0.2, 0.05, 0.01),
                      reference1=0.2, reference2=-0.1),
        JointCoupling("fix", "left_yaw", polycoef=(0.3,)),
    ]
    return RobotModel.from_urdf(data_path("two_arms.urdf"), constraints=cons, joint_limits="ignore")


def test_constraint_rows_gamma_is_time_derivative_of_A_qd() -> None:
    """γ = d(A qd)/dt at fixed qd for every constraint type (free-flyer coordinates)."""
    r = _all_types_robot()
    every = r.constraint_names
    assert r.num_rows(every) == 1 + 3 + 6 + 5 + 2 + 3 + 1 + 1 + 1 + 1
    rng = np.random.default_rng(4)
    for _ in range(2):
        q = r.random_configuration(rng)
        qd = rng.normal(size=r.n)
        ct = r.constraint_terms(0.0, q, qd, every)
        Aqd = _fd(lambda x, v=qd: r.constraint_terms(0.0, x, v, every).A @ v, q, qd)
        assert _rel_err(ct.gamma, Aqd) < FD_TOL
        np.testing.assert_allclose(ct.velocity, ct.A @ qd)
        assert ct.holonomic.all()


def test_constraint_jacobian_is_gradient_of_residual() -> None:
    """A = ∂φ/∂q everywhere for the exact types (weld rotations: on φ = 0, below)."""
    r = _all_types_robot()
    exact = [n for n in r.constraint_names if n not in ("wd", "pw")]
    rng = np.random.default_rng(5)
    q = r.random_configuration(rng)
    A = r.constraint_jacobian(0.0, q, exact)
    for k in range(r.n):
        e = np.zeros(r.n)
        e[k] = 1.0
        col = _fd(lambda x: r.constraint_residual(0.0, x, exact), q, e)
        assert _rel_err(A[:, k], col) < FD_TOL, r.coordinate_names[k]


def test_weld_jacobian_on_the_constraint_manifold() -> None:
    robot, state = two_arm_grasp()
    q = state.q
    act = robot.default_active
    A = robot.constraint_jacobian(0.0, q, act)
    rng = np.random.default_rng(6)
    for _ in range(4):
        d = rng.normal(size=robot.n)
        col = _fd(lambda x: robot.constraint_residual(0.0, x, act), q, d)
        assert _rel_err(A @ d, col) < FD_TOL
    assert np.abs(robot.constraint_residual(0.0, q, act)).max() < 1e-10


def test_switching_constraints_is_data() -> None:
    r = _all_types_robot()
    assert "ct" not in r.default_active  # unilateral contacts are off by default
    rows = r.row_slices({"pt", "ct"})
    assert list(rows) == ["box.unit_quaternion", "pt", "ct"]
    q = r.random_configuration(0)
    assert r.constraint_terms(0.0, q, np.zeros(r.n), {"pt", "ct"}).A.shape == (5, r.n)
    with pytest.raises(UnknownNameError, match="nope"):
        r.constraint_terms(0.0, q, np.zeros(r.n), {"nope"})
    assert r.constraint("ct").kind == "unilateral"


def test_matches_pinocchio_terms_fixed_base_and_check_model() -> None:
    r = RobotModel.from_urdf(data_path("arm4.urdf"), damping=[0.1, 0.2, 0.3, 0.4])
    assert isinstance(r, Model)
    pm = r.pinocchio_model
    rng = np.random.default_rng(7)
    q, qd = r.random_configuration(rng), rng.normal(size=4)
    mt = r.evaluate(0.0, q, qd)
    np.testing.assert_allclose(mt.M, pin.crba(pm, pm.createData(), q), atol=1e-14)
    np.testing.assert_allclose(mt.h, -pin.nonLinearEffects(pm, pm.createData(), q, qd), atol=1e-13)
    np.testing.assert_allclose(mt.f_passive, -np.array([0.1, 0.2, 0.3, 0.4]) * qd)
    np.testing.assert_allclose(mt.B, np.eye(4))
    assert r.actuator_names == ("yaw", "shoulder", "elbow", "wrist")
    report = check_model(r, r.state(q, qd), duration=0.0)
    assert report.passed, report.format()


def test_geometry_and_replace() -> None:
    robot, state = two_arm_grasp()
    g = robot.geometry(state.q)
    assert g.dim == 3 and g.segments.shape[1:] == (2, 3) and g.frames.shape[1:] == (4, 3)
    assert len(g.labels) == g.points.shape[0]
    i = g.labels.index("grasp_right:a")
    np.testing.assert_allclose(g.points[i], g.points[g.labels.index("grasp_right:b")], atol=1e-9)
    fewer = robot.replace(robot_constraints=robot.robot_constraints[:1])
    assert fewer.constraint_names == ("box.unit_quaternion", "grasp_left")
    with pytest.raises(InputError, match="unknown field"):
        robot.replace(nonsense=1)


def test_bad_input_raises_typed_errors() -> None:
    path = data_path("arm4.urdf")
    with pytest.raises(UnknownNameError, match="frame_a 'nope'"):
        RobotModel.from_urdf(path, constraints=[FrameConstraint.point("c", "nope")])
    with pytest.raises(UnknownNameError, match="scalar joint"):
        RobotModel.from_urdf(path, constraints=[JointCoupling("c", "nope")])
    with pytest.raises(InputError, match="unique"):
        RobotModel.from_urdf(path, constraints=[FrameConstraint.point("c", "ee"),
                                                FrameConstraint.contact("c", "ee")])
    with pytest.raises(UnknownNameError, match="actuated"):
        RobotModel.from_urdf(path, actuated=["nope"])
    with pytest.raises(InputError, match="root_joint"):
        RobotModel.from_urdf(path, root_joint="planar")
    with pytest.raises(InputError, match="does not exist"):
        RobotModel.from_urdf(path.with_name("missing.urdf"))
    with pytest.raises(InputError, match="expected a URDF file, got the folder"):  # (said "does not exist")
        RobotModel.from_urdf(path.parent)
    with pytest.raises(ShapeError, match="placement_a"):
        FrameConstraint.point("c", "ee", placement_a=np.eye(3))
    with pytest.raises(InputError, match="axis"):
        FrameConstraint.hinge("c", "ee", axis=(0.0, 0.0, 0.0))
    r = RobotModel.from_urdf(path)
    with pytest.raises(ShapeError, match=r"q must have shape \(4,\)"):
        r.mass_matrix(np.zeros(3))
    with pytest.raises(ShapeError, match="gravity"):
        RobotModel.from_urdf(path, gravity=[0.0, 9.81])
    with pytest.raises(InputError, match="quaternion"):
        _free_pendulum().mass_matrix(np.zeros(11))


def test_exact_jacobian_derivative() -> None:
    """Ȧ (Pinocchio Jacobian time variations) equals dA/dt by central differences and Ȧ qd = γ."""
    r = _all_types_robot()
    every = r.constraint_names
    rng = np.random.default_rng(8)
    q = r.random_configuration(rng)
    qd = rng.normal(size=r.n)
    Ad = r.constraint_jacobian_dot(0.0, q, qd, every)
    Ad_fd = _fd(lambda x: r.constraint_jacobian(0.0, x, every), q, qd)
    assert _rel_err(Ad, Ad_fd) < FD_TOL
    np.testing.assert_allclose(Ad @ qd, r.constraint_bias(0.0, q, qd, every), atol=1e-11)


def test_hinge_and_point_on_plane_admissible_motions() -> None:
    """Null-space motions of a hinge rotate only about its axis; point-on-plane slides in-plane."""
    robot, state = two_arm_grasp()
    weld, point = robot.robot_constraints[:2]  # then the joint limits
    k = np.array([0.0, 0.6, 0.8])
    hinge = FrameConstraint.hinge("grasp_left", weld.frame_a, weld.frame_b, axis=k,
                                  placement_a=weld.placement_a, placement_b=weld.placement_b)
    plane = FrameConstraint.point_on_plane("grasp_right", point.frame_b, point.frame_a,
                                           normal=(0.0, 0.0, 1.0))
    r = robot.replace(robot_constraints=(hinge, plane))
    q = state.q
    A = r.constraint_jacobian(0.0, q)
    assert np.abs(r.constraint_residual(0.0, q)).max() < 1e-9
    _, s, Vt = np.linalg.svd(A)
    N = Vt[int(np.sum(s > 1e-10)):].T
    pm = r.pinocchio_model
    LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
    rng = np.random.default_rng(9)
    for _ in range(3):
        qd = N @ rng.normal(size=N.shape[1])
        v = r.to_pinocchio_velocity(q, qd)
        d = pm.createData()
        pin.forwardKinematics(pm, d, r.pinocchio_configuration(q), v)
        pin.updateFramePlacements(pm, d)

        def vel(name, d=d):
            return pin.getFrameVelocity(pm, d, r.frame_id(name), LWA)

        va, vb = vel("grasp_left:a"), vel("grasp_left:b")
        axis = d.oMf[r.frame_id("grasp_left:a")].rotation @ k
        dw = va.angular - vb.angular
        np.testing.assert_allclose(va.linear, vb.linear, atol=1e-12)
        np.testing.assert_allclose(dw - (dw @ axis) * axis, 0.0, atol=1e-12)
        normal = d.oMf[r.frame_id("grasp_right:a")].rotation @ np.array([0.0, 0.0, 1.0])
        rel = vel("grasp_right:b").linear - vel("grasp_right:a").linear
        # the two points coincide, so the plane's rotation does not move the point
        assert abs(rel @ normal) < 1e-12


def test_frame_constraint_vectors_must_be_finite_numbers() -> None:
    """normal="y" was a raw ValueError from NumPy; a NaN placement was accepted."""
    from nonmin.errors import InputError, NonFiniteError
    from nonmin.model.robots import FrameConstraint

    with pytest.raises(InputError, match="normal must be a numeric array, got text"):
        FrameConstraint.planar_point("loop", "a", "b", normal="y")
    with pytest.raises(NonFiniteError, match="placement_a must be finite"):
        FrameConstraint.point("loop", "a", "b", placement_a=(np.nan, 0.0, 0.0))


def test_negative_joint_damping_is_a_model_error() -> None:
    """damping=[-1, -1, -1] (energy injected) was accepted; the planar builder's dampers refuse it."""
    from nonmin.errors import ModelError
    from nonmin.model.robots import RobotModel, data_path

    with pytest.raises(ModelError, match=r"damping must be finite and ≥ 0"):
        RobotModel.from_urdf(data_path("fourbar.urdf"), damping=[0.1, -1.0, 0.0])
    with pytest.raises(ModelError, match=r"damping must be finite and ≥ 0"):
        RobotModel.from_urdf(data_path("fourbar.urdf"), damping=[np.nan, 0.0, 0.0])
    RobotModel.from_urdf(data_path("fourbar.urdf"), damping=[0.1, 0.0, 0.2])


def test_a_folder_is_not_an_mjcf_file(tmp_path):
    """RobotModel.from_mjcf(folder) said the path "does not exist"."""
    pytest.importorskip("mujoco")
    from nonmin.errors import FileFormatError

    with pytest.raises(FileFormatError, match="expected a MJCF file, got the folder"):
        RobotModel.from_mjcf(tmp_path)
    with pytest.raises(FileFormatError, match="which does not exist"):
        RobotModel.from_mjcf(tmp_path / "missing.xml")
