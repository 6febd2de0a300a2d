"""Analytic derivatives of robots with quaternion joints (free flyer, spherical).

A tree with a free-flyer or spherical joint takes δ(M q̈ − g), δ(A q̈ + γ) and δ(Aᵀλ) from the
velocity-space derivatives of the RNEA and of the frames' kinematics (Pinocchio's tangent
convention) carried to nonmin's coordinates by the chain rule through v = T(q) q̇ and
a_v = T a + Ṫ q̇ (``TreeProgram::quat_dynamics``, ``quat_rows``; docs/theory.md). Checked on the
two-arm grasp (free-flying box: weld + point, 15 coordinates) and on a spherical-joint chain
with its tip pinned, against

* the dual-number evaluation (``backend="numpy"``: every term's tangent from
  ``evaluate_tangent``) to 1e-10 relative, off the manifold (quaternions not of unit norm,
  velocities off the null space, inputs);
* central differences of the engine's q̈ (step 1e-6) to 1e-7 relative;
* Pinocchio's ``computeConstraintDynamicsDerivatives`` to 1e-7 relative: its ∂a/∂q (along
  q ⊕ δ at fixed v), ∂a/∂v and ∂a/∂τ are nonmin's ∂q̈ composed with the coordinate maps
  (q(δ) = integrate(q, δ), q̇ = E(q) v, f = T(q)ᵀ τ, a = T q̈ + Ṫ q̇), whose own derivatives
  are central differences of those smooth maps (no dynamics in them). In full for the chain
  (a point held in the world); for the box held between two moving bodies along the
  admissible states (Pinocchio's LOCAL contact rows differ from nonmin's off them: there the
  two models differ, not their derivatives; measured 1.0 relative off, 1e-10 along).
"""

import numpy as np
import pytest

from nonmin.linear import dynamics_derivatives

pin = pytest.importorskip("pinocchio")

#: Asked agreement with Pinocchio's analytical derivatives (relative to the largest entry).
PIN_RTOL = 1e-7


def _two_arm():
    from nonmin.model.robots._examples import two_arm_grasp

    robot, state = two_arm_grasp()
    return robot, np.array(state.q), [(6, "grasp_left"), (3, "grasp_right")]


def _spherical_chain():
    """A ball joint at the root, a revolute elbow, the tip pinned where it is (3 rows, 1 DOF)."""
    from nonmin.model.robots import FrameConstraint, RobotModel

    pm = pin.Model()
    j1 = pm.addJoint(
        0, pin.JointModelSpherical(), pin.SE3(np.eye(3), np.array([0.0, 0.0, 1.0])), "ball"
    )
    pm.appendBodyToJoint(
        j1,
        pin.Inertia(1.2, np.array([0.05, 0.02, -0.3]), np.diag([0.05, 0.04, 0.02])),
        pin.SE3.Identity(),
    )
    j2 = pm.addJoint(
        j1, pin.JointModelRY(), pin.SE3(np.eye(3), np.array([0.0, 0.0, -0.6])), "elbow"
    )
    pm.appendBodyToJoint(
        j2,
        pin.Inertia(0.8, np.array([0.01, 0.0, -0.25]), np.diag([0.03, 0.03, 0.01])),
        pin.SE3.Identity(),
    )
    pm.addFrame(
        pin.Frame(
            "tip", j2, 0, pin.SE3(np.eye(3), np.array([0.1, 0.0, -0.5])), pin.FrameType.OP_FRAME
        )
    )
    eps = np.array([0.2, -0.1, 0.3, 1.0])
    q0 = np.r_[eps / np.linalg.norm(eps), 0.7]
    base = RobotModel.from_pinocchio(pm, joint_limits="ignore")
    tip = base.frame_placement(q0, "tip")[:3, 3]
    robot = base.replace(robot_constraints=(FrameConstraint.point("pin", "tip", placement_b=tip),))
    return robot, q0, [(3, "pin")]


MODELS = {"two_arm_free_box": _two_arm, "spherical_chain": _spherical_chain}


def _admissible_velocity(robot, q, rng):
    A = robot.constraint_jacobian(0.0, q)
    _, s, Vt = np.linalg.svd(A)
    r = int(np.sum(s > 1e-10 * max(1.0, s[0])))
    return Vt[r:].T @ rng.standard_normal(A.shape[1] - r)


def _rel(a, b):
    return float(np.abs(a - b).max()) / max(1.0, float(np.abs(b).max()))


@pytest.mark.parametrize("name", sorted(MODELS))
def test_quaternion_derivatives_match_dual_numbers_and_differences(name):
    robot, q0, _ = MODELS[name]()
    n = robot.n
    rng = np.random.default_rng(23)
    for _ in range(2):
        q = q0 + 0.05 * rng.standard_normal(n)  # quaternions off the unit sphere, off the closure
        qd = rng.standard_normal(n)
        f = rng.standard_normal(n)
        u = rng.standard_normal(robot.k) if robot.k else None
        ours = dynamics_derivatives(robot, q, qd, f=f, u=u)
        dual = dynamics_derivatives(robot, q, qd, f=f, u=u, backend="numpy")
        for key in ("qdd", "dqdd_dq", "dqdd_dqd", "dqdd_df", "dfc_dq", "dfc_dqd"):
            assert _rel(getattr(ours, key), getattr(dual, key)) <= 1e-10, key
        h = 1e-6
        fd_q = np.empty((n, n))
        fd_v = np.empty((n, n))
        for k in range(n):
            e = np.zeros(n)
            e[k] = h
            fd_q[:, k] = (dynamics_derivatives(robot, q + e, qd, f=f, u=u).qdd
                          - dynamics_derivatives(robot, q - e, qd, f=f, u=u).qdd) / (2 * h)  # fmt: skip
            fd_v[:, k] = (dynamics_derivatives(robot, q, qd + e, f=f, u=u).qdd
                          - dynamics_derivatives(robot, q, qd - e, f=f, u=u).qdd) / (2 * h)  # fmt: skip
        assert _rel(ours.dqdd_dq, fd_q) <= 1e-7
        assert _rel(ours.dqdd_dqd, fd_v) <= 1e-7


def _central(fun, x, h=1e-6):
    cols = []
    for k in range(x.size):
        e = np.zeros(x.size)
        e[k] = h
        cols.append((fun(x + e) - fun(x - e)) / (2 * h))
    return np.stack(cols, axis=-1)


@pytest.mark.parametrize("name", sorted(MODELS))
def test_quaternion_derivatives_match_pinocchio(name, pin_frame_constraints):
    robot, q0, specs = MODELS[name]()
    pm = robot.pinocchio_model
    pd = pm.createData()
    cms, cds = pin_frame_constraints(robot, specs)
    pin.initConstraintDynamics(pm, pd, cms, cds)
    prox = pin.ProximalSettings(1e-14, 1e-14, 1)
    nv = pm.nv
    rng = np.random.default_rng(29)
    for trial in range(2):
        qd0 = _admissible_velocity(robot, q0, rng)
        v = robot.to_pinocchio_velocity(q0, qd0)
        tau = rng.standard_normal(nv)
        if name == "two_arm_free_box":
            tau[:6] = 0.0  # the box is not actuated (f = Tᵀ τ stays in B's range either way)
        a_pin = np.array(pin.constraintDynamics(pm, pd, q0, v, tau, cms, cds, prox))
        da_dq, da_dv, da_dtau = (
            np.array(x)
            for x in pin.computeConstraintDynamicsDerivatives(pm, pd, cms, cds, prox)[:3]
        )
        _check_against_pinocchio(robot, q0, name, v, tau, a_pin, da_dq, da_dv, da_dtau, trial)


def _check_against_pinocchio(robot, q0, name, v, tau, a_pin, da_dq, da_dv, da_dtau, trial):
    pm = robot.pinocchio_model
    nv = pm.nv
    T = robot.velocity_map(q0)
    qd = robot.from_pinocchio_velocity(q0, v)
    f = T.T @ tau
    d = dynamics_derivatives(robot, q0, qd, f=f)
    a_ours = robot.to_pinocchio_acceleration(q0, qd, d.qdd)
    assert _rel(a_ours, a_pin) <= 1e-9

    # the coordinate maps along Pinocchio's tangent δ (q ⊕ δ, v held) and their derivatives
    def q_of(dl):
        return np.array(pin.integrate(pm, q0, dl))

    dq = _central(q_of, np.zeros(nv))
    dqd = _central(lambda dl: robot.from_pinocchio_velocity(q_of(dl), v), np.zeros(nv))
    df = _central(lambda dl: robot.velocity_map(q_of(dl)).T @ tau, np.zeros(nv))
    P_q = _central(lambda x: robot.to_pinocchio_acceleration(x, qd, d.qdd), q0)  # q̈ held
    P_qd = _central(lambda x: robot.to_pinocchio_acceleration(q0, x, d.qdd), qd)
    Ev = np.stack([robot.from_pinocchio_velocity(q0, e) for e in np.eye(nv)], axis=1)
    ours_dq = P_q @ dq + P_qd @ dqd + T @ (d.dqdd_dq @ dq + d.dqdd_dqd @ dqd + d.dqdd_df @ df)
    ours_dv = P_qd @ Ev + T @ d.dqdd_dqd @ Ev
    ours_dtau = T @ d.dqdd_df @ T.T
    assert _rel(ours_dtau, da_dtau) <= PIN_RTOL, trial
    if name == "spherical_chain":  # a point held in the world: the same rows everywhere
        assert _rel(ours_dq, da_dq) <= PIN_RTOL, trial
        assert _rel(ours_dv, da_dv) <= PIN_RTOL, trial

    # Between two moving bodies Pinocchio's LOCAL contact rows and nonmin's world rows agree
    # on the admissible states (q on the closure, v in its tangent) only, so their
    # derivatives agree along that set: δ in the null space Z of the closure's Jacobian in
    # v (A E), with v moved by δv = −(A E)⁺ ∂(A E v)/∂δ δ to stay admissible, and δv ∈ Z.
    def AE(q):
        return robot.constraint_jacobian(0.0, q) @ np.stack(
            [robot.from_pinocchio_velocity(q, e) for e in np.eye(nv)], axis=1
        )

    A0 = AE(q0)
    _, s, Vt = np.linalg.svd(A0)
    Z = Vt[int(np.sum(s > 1e-10 * s[0])) :].T
    dV = -np.linalg.pinv(A0) @ _central(lambda dl: AE(q_of(dl)) @ v, np.zeros(nv)) @ Z
    assert _rel(ours_dq @ Z + ours_dv @ dV, da_dq @ Z + da_dv @ dV) <= PIN_RTOL, trial
    assert _rel(ours_dv @ Z, da_dv @ Z) <= PIN_RTOL, trial
