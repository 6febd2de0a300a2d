"""Reactions by name against closed forms, an independent Newton–Euler solve and Pinocchio."""

from __future__ import annotations

import numpy as np
import pytest

import nonmin
from nonmin.core import solve_dynamics
from nonmin.model import assemble
from nonmin.model.planar import PlanarBuilder
from nonmin.model.spatial import SpatialBuilder

TOL = 1e-9


def _bar_pendulum(m=2.0, L=1.2, duplicate=False):
    b = PlanarBuilder("pendulum")
    b.body("bar", mass=m, inertia=m * L**2 / 12, points={"end": (-L / 2, 0.0)})
    b.revolute("pivot", ("ground", (0.0, 0.0)), "end")
    if duplicate:
        b.revolute("pivot2", ("ground", (0.0, 0.0)), "end")
    return b.build()


def _pendulum_closed_form(theta, omega, m, L, g=9.81):
    """Force on the bar at the pin in the bar frame (x from pin to COM): (−T, F_t)."""
    l = L / 2
    Ic = m * L**2 / 12
    alpha = -m * g * l * np.sin(theta) / (Ic + m * l * l)
    T = m * g * np.cos(theta) + m * l * omega**2
    Ft = m * l * alpha + m * g * np.sin(theta)
    return np.stack([-T, Ft], axis=-1)


def _pendulum_state(theta, omega, L):
    l = L / 2
    r = np.array([l * np.sin(theta), -l * np.cos(theta)])
    rd = omega * np.array([l * np.cos(theta), l * np.sin(theta)])
    return np.array([*r, theta - np.pi / 2]), np.array([*rd, omega])


def test_pendulum_pin_reaction_closed_form_along_a_trajectory() -> None:
    m, L = 2.0, 1.2
    model = _bar_pendulum(m, L)
    q0, qd0 = _pendulum_state(1.1, 0.5, L)
    traj = nonmin.simulate(model, 1.5, q0, qd0, dt=1e-3).with_reactions(model)
    r = traj.reactions["pivot"]
    assert r.kind == "planar" and (r.body_a, r.body_b) == ("ground", "bar")
    theta = traj.q[:, 2] + np.pi / 2
    omega = traj.qd[:, 2]
    ref = _pendulum_closed_form(theta, omega, m, L)
    scale = m * 9.81
    np.testing.assert_allclose(r.force_b, ref, atol=1e-8 * scale)
    np.testing.assert_allclose(r.torque_b, 0.0, atol=1e-8 * scale * L)  # a pin takes no moment
    # the ground gets the opposite force, in world axes, about the pivot
    c, s = np.cos(traj.q[:, 2]), np.sin(traj.q[:, 2])
    world_b = np.stack(
        [c * r.force_b[:, 0] - s * r.force_b[:, 1], s * r.force_b[:, 0] + c * r.force_b[:, 1]], -1
    )
    np.testing.assert_allclose(r.force_a, -world_b, atol=1e-8 * scale)
    np.testing.assert_allclose(r.torque_a, 0.0, atol=1e-8 * scale * L)
    assert r.determined.all() and r.multipliers_determined.all()
    np.testing.assert_allclose(r.generalized, traj.f_c, atol=1e-10 * scale)


def test_reactions_survive_save_and_load(tmp_path) -> None:
    model = _bar_pendulum()
    q0, qd0 = _pendulum_state(0.4, 0.0, 1.2)
    traj = nonmin.simulate(model, 0.2, q0, qd0, dt=1e-2).with_reactions(model)
    traj.save(tmp_path / "p.npz")
    back = nonmin.load_trajectory(tmp_path / "p.npz")
    r0, r1 = traj.reactions["pivot"], back.reactions["pivot"]
    assert r1.body_b == "bar" and r1.kind == "planar"
    np.testing.assert_array_equal(r0.force_b, r1.force_b)
    np.testing.assert_array_equal(r0.determined_a, r1.determined_a)


def test_duplicated_pivot_is_reported_undetermined() -> None:
    """Two identical pins share the load in any proportion: each pin's force is undetermined,
    their sum is the closed form."""
    m, L = 2.0, 1.2
    model = _bar_pendulum(m, L, duplicate=True)
    q, qd = _pendulum_state(0.7, -1.3, L)
    sol = model.forward_dynamics(q, qd)
    rs = nonmin.reactions(model, q, sol.f_c)
    r1, r2 = rs["pivot"], rs["pivot2"]
    assert not r1.determined_b[:2].any() and not r2.determined_b[:2].any()
    assert not r1.multipliers_determined.any()
    # the minimum-norm split shares equally, and the sum is physical
    np.testing.assert_allclose(
        r1.force_b + r2.force_b, _pendulum_closed_form(0.7, -1.3, m, L), atol=1e-9 * m * 9.81
    )
    np.testing.assert_allclose(r1.force_b, r2.force_b, atol=1e-9)


# --------------------------------------------------------------------------- four-bar vs Newton–Euler
def _fourbar():
    b = PlanarBuilder("fourbar")
    Ls = {"crank": 0.4, "coupler": 1.0, "rocker": 0.8}
    ms = {"crank": 1.0, "coupler": 2.0, "rocker": 1.5}
    for nm, L in Ls.items():
        b.body(
            nm,
            mass=ms[nm],
            inertia=ms[nm] * L**2 / 12,
            points={f"{nm}.0": (-L / 2, 0.0), f"{nm}.1": (L / 2, 0.0)},
        )
    b.revolute("A", ("ground", (0.0, 0.0)), "crank.0")
    b.revolute("B", "crank.1", "coupler.0")
    b.revolute("C", "coupler.1", "rocker.1")
    b.revolute("D", "rocker.0", ("ground", (1.2, 0.0)))
    b.actuator("motor", "A")
    m = b.build()
    guess = [0.1, 0.18, 1.15, 0.55, 0.6, -0.35, 1.15, 0.35, 1.7]
    return m, assemble(m, guess), Ls, ms


GRAVITY = np.array([0.0, -9.81])


def _newton_euler(model, q, qd, tau, Ls, ms, g=GRAVITY):
    """Independent Newton–Euler + pin acceleration equations (own geometry).

    Unknowns: body accelerations (ẍ, ÿ, θ̈) ×3 and the force F_j on the *second* body of each
    pin (A: crank, B: coupler, C: rocker, D: ground), −F_j on the first.
    """
    bodies = ["crank", "coupler", "rocker"]
    idx = {b: 3 * i for i, b in enumerate(bodies)}
    pins = [
        ("A", None, (0.0, 0.0), "crank", -1),
        ("B", "crank", 1, "coupler", -1),
        ("C", "coupler", 1, "rocker", 1),
        ("D", "rocker", -1, None, (1.2, 0.0)),
    ]

    def arm(body, end):
        th = q[idx[body] + 2]
        return end * Ls[body] / 2 * np.array([np.cos(th), np.sin(th)])

    nu = 9 + 8
    K = np.zeros((nu, nu))
    rhs = np.zeros(nu)
    for bname in bodies:  # Newton–Euler rows
        i = idx[bname]
        m = ms[bname]
        K[i, i] = K[i + 1, i + 1] = m
        K[i + 2, i + 2] = m * Ls[bname] ** 2 / 12
        rhs[i : i + 2] = m * g
        if bname == "crank":
            rhs[i + 2] = tau
    for k, (_, ba, ea, bb, eb) in enumerate(pins):
        col = 9 + 2 * k
        for body, end, sign in ((ba, ea, -1.0), (bb, eb, 1.0)):
            if body is None:
                continue
            i = idx[body]
            s = arm(body, end)
            K[i, col] -= sign
            K[i + 1, col + 1] -= sign
            K[i + 2, col] -= sign * -s[1]
            K[i + 2, col + 1] -= sign * s[0]
        # acceleration of the pin point equal on both sides: a_a − a_b = 0
        row = 9 + 2 * k
        for body, end, sign in ((ba, ea, 1.0), (bb, eb, -1.0)):
            if body is None:
                continue
            i = idx[body]
            s = arm(body, end)
            om = qd[i + 2]
            K[row, i] += sign
            K[row + 1, i + 1] += sign
            K[row, i + 2] += sign * -s[1]
            K[row + 1, i + 2] += sign * s[0]
            rhs[row : row + 2] -= sign * -(om**2) * s
    sol = np.linalg.solve(K, rhs)
    F = {p[0]: sol[9 + 2 * k : 11 + 2 * k] for k, p in enumerate(pins)}
    return sol[:9], F


def test_fourbar_pin_forces_match_newton_euler() -> None:
    model, state, Ls, ms = _fourbar()
    rng = np.random.default_rng(5)
    q = state.q
    A = model.constraint_jacobian(0.0, q)
    z = np.linalg.svd(A)[2][-1]
    for w in (0.0, 2.5, -4.0):
        qd = w * z
        tau = rng.normal()
        sol = model.forward_dynamics(q, qd, f=model.input_matrix(q) @ [tau])
        qdd_ne, F = _newton_euler(model, q, qd, tau, Ls, ms)
        np.testing.assert_allclose(sol.qdd, qdd_ne, atol=1e-9)
        rs = nonmin.reactions(model, q, sol.f_c)
        for pin, second in (("A", "crank"), ("B", "coupler"), ("C", "rocker")):
            r = rs[pin]
            assert r.body_b == second and r.determined.all()
            th = q[3 * ["crank", "coupler", "rocker"].index(second) + 2]
            Rt = np.array([[np.cos(th), np.sin(th)], [-np.sin(th), np.cos(th)]])
            np.testing.assert_allclose(r.force_b, Rt @ F[pin], atol=1e-9 * 30)
            np.testing.assert_allclose(r.torque_b, 0.0, atol=1e-9 * 30)
        # D: rocker is body a, the ground body b (world axes): the ground gets F_D
        np.testing.assert_allclose(rs["D"].force_b, F["D"], atol=1e-9 * 30)


# --------------------------------------------------------------------------- spatial
def test_spatial_revolute_pendulum_and_overconstrained_fourbar() -> None:
    m, L = 2.0, 1.2
    b = SpatialBuilder("pend3")
    b.add_body(
        "bar", mass=m, inertia=[1e-3, m * L**2 / 12, m * L**2 / 12], position=[L / 2, 0.0, 0.0]
    )
    b.add_revolute("hinge", "ground", "bar", point=[0.0, 0.0, 0.0], axis=[0.0, 1.0, 0.0])
    model = b.build()
    q = model.reference_configuration()
    # rotate about y by the angle that puts the bar at θ from the downward vertical
    theta, omega = 0.9, 1.7
    ang = theta - np.pi / 2  # bar initially along +x (θ = π/2)
    Rq = np.array([np.cos(-ang / 2), 0.0, np.sin(-ang / 2), 0.0])
    l = L / 2
    q = np.array([l * np.sin(theta), 0.0, -l * np.cos(theta), *Rq])
    w = np.array([0.0, -omega, 0.0])  # body rotates about −y when θ grows (x-z plane, z up)
    from nonmin.model.spatial._quaternion import E_matrix

    rd = np.cross(w, q[:3])
    ed = 0.5 * E_matrix(Rq).T @ w
    qd = np.concatenate([rd, ed])
    sol = model.forward_dynamics(q, qd)
    r = nonmin.reactions(model, q, sol.f_c)["hinge"]
    assert r.kind == "spatial" and r.body_b == "bar"
    ref = _pendulum_closed_form(theta, omega, m, L)
    # bar frame: x along the bar from the hinge (the joint point is at local (−L/2, 0, 0))
    np.testing.assert_allclose(r.force_b[[0, 2]], [ref[0], ref[1]], atol=1e-8 * m * 9.81)
    assert abs(r.force_b[1]) < 1e-8 * m * 9.81
    np.testing.assert_allclose(r.torque_b, 0.0, atol=1e-8 * m * 9.81 * L)
    assert r.determined.all()


def test_spatial_fourbar_of_revolutes_has_undetermined_axial_forces() -> None:
    """A planar four-bar built from 3D revolute joints is over-constrained (4 × 5 joint rows +
    3 quaternion norms = 23 rows of rank 20 on 21 coordinates, 1 dof): the forces along the
    joint axes are not decided by the dynamics; the in-plane forces are."""
    b = SpatialBuilder("fourbar3d", gravity=(0.0, -9.81, 0.0))
    pts = [
        np.array(p) for p in ([0.0, 0.0, 0.0], [0.0, 0.4, 0.0], [1.0, 0.7, 0.0], [1.2, 0.0, 0.0])
    ]
    names = ["crank", "coupler", "rocker"]
    for i, nm in enumerate(names):
        p0, p1 = pts[i], pts[i + 1]
        d = p1 - p0
        ang = np.arctan2(d[1], d[0])
        Lb = np.linalg.norm(d)
        b.add_body(
            nm,
            mass=1.0 + i,
            inertia=[1e-3, Lb**2 / 12, Lb**2 / 12],
            position=0.5 * (p0 + p1),
            quaternion=[np.cos(ang / 2), 0.0, 0.0, np.sin(ang / 2)],
        )
    ax = [0.0, 0.0, 1.0]
    b.add_revolute("A", "ground", "crank", point=pts[0], axis=ax)
    b.add_revolute("B", "crank", "coupler", point=pts[1], axis=ax)
    b.add_revolute("C", "coupler", "rocker", point=pts[2], axis=ax)
    b.add_revolute("D", "rocker", "ground", point=pts[3], axis=ax)
    model = b.build()
    q = model.reference_configuration()
    sol = model.forward_dynamics(q, np.zeros(model.n))
    assert int(sol.rank) < model.num_rows()
    rs = nonmin.reactions(model, q, sol.f_c)
    rB = rs["B"]
    # body frame of the coupler: z is the joint axis
    assert not rB.determined_b[2]  # axial force
    assert rB.determined_b[0] and rB.determined_b[1]  # in-plane forces
    assert rB.determined_b[5]  # moment about the axis (zero: a hinge)
    assert not rB.multipliers_determined.all()
    # the determined in-plane forces satisfy the coupler's own Newton equation at rest
    # (q̇ = 0): the sum over its two joints equals m a − m g
    mc = 2.0
    i = model.body_index("coupler")
    acc = sol.qdd[7 * i : 7 * i + 3]
    Rc = model.rotation(q, "coupler")
    total = Rc @ (rs["B"].force_b + rs["C"].force_a)
    np.testing.assert_allclose(
        total[:2], (mc * acc - mc * np.array([0.0, -9.81, 0.0]))[:2], atol=1e-9
    )


# --------------------------------------------------------------------------- robots vs Pinocchio
def test_robot_loop_closures_match_pinocchio_lambda(pin_frame_constraints) -> None:
    pin = pytest.importorskip("pinocchio")
    from nonmin.model.robots._examples import two_arm_grasp

    robot, state = two_arm_grasp()
    q = state.q
    rng = np.random.default_rng(8)
    A = robot.constraint_jacobian(0.0, q)
    _, s, Vt = np.linalg.svd(A)
    r = int(np.sum(s > 1e-10 * s[0]))
    qd = Vt[r:].T @ rng.normal(size=robot.n - r)
    tau = np.concatenate([np.zeros(6), rng.normal(size=robot.nv - 6)])
    mt = robot.evaluate(0.0, q, qd)
    T = robot.velocity_map(q)
    ct = mt.constraints
    sol = solve_dynamics(mt.M, mt.h, ct.A, ct.gamma, T.T @ tau)
    rs = nonmin.reactions(robot, q, sol.f_c)
    # Pinocchio: the same closures as RigidConstraintModels in frame a's LOCAL axes
    pm = robot.pinocchio_model
    data = pm.createData()
    models, datas = pin_frame_constraints(robot, [(6, "grasp_left"), (3, "grasp_right")])
    pin.initConstraintDynamics(pm, data, models, datas)
    prox = pin.ProximalSettings(1e-12, 0.0, 1)
    pin.constraintDynamics(
        pm,
        data,
        robot.pinocchio_configuration(q),
        robot.to_pinocchio_velocity(q, qd),
        tau,
        models,
        datas,
        prox,
    )
    lam = np.array(data.lambda_c)
    scale = max(1.0, np.abs(lam).max())
    left, right = rs["grasp_left"], rs["grasp_right"]
    assert left.kind == "frame" and left.determined.all() and right.determined.all()
    np.testing.assert_allclose(
        np.concatenate([left.force_a, left.torque_a]), lam[:6], atol=1e-8 * scale
    )
    np.testing.assert_allclose(right.force_a, lam[6:9], atol=1e-8 * scale)
    np.testing.assert_allclose(right.torque_a, 0.0, atol=1e-8 * scale)


def test_reaction_plot() -> None:
    pytest.importorskip("matplotlib")
    model = _bar_pendulum()
    q0, qd0 = _pendulum_state(0.4, 0.0, 1.2)
    traj = nonmin.simulate(model, 0.2, q0, qd0, dt=1e-2).with_reactions(model)
    fig = traj.reactions["pivot"].plot(traj.t)
    assert len(fig.axes) == 4 and "pivot" in fig._suptitle.get_text()
    import matplotlib.pyplot as plt

    plt.close(fig)


@pytest.mark.parametrize("closure", ["point", "planar_point", "hinge", "weld", "planar_weld"])
def test_robot_frame_wrenches_rebuild_the_generalized_force(closure) -> None:
    """For every frame-constraint type, the reported wrenches on frames a and b, mapped back
    with Pinocchio's LOCAL frame Jacobians (J_aᵀ w_a + J_bᵀ w_b, then Tᵀ), give the
    constraint's own part A_Iᵀλ_I of f_c."""
    pin = pytest.importorskip("pinocchio")
    from nonmin.model.robots._examples import fourbar

    robot, state = fourbar(closure)
    q = state.q
    rng = np.random.default_rng(9)
    A = robot.constraint_jacobian(0.0, q)
    _, s, Vt = np.linalg.svd(A)
    r = int(np.sum(s > 1e-10 * s[0]))
    qd = Vt[r:].T @ rng.normal(size=robot.n - r)
    sol = robot.forward_dynamics(q, qd, f=robot.input_matrix(q) @ [0.8])
    rc = nonmin.reactions(robot, q, sol.f_c)["closure"]
    pm = robot.pinocchio_model
    data = pm.createData()
    qn = robot.pinocchio_configuration(q)
    pin.computeJointJacobians(pm, data, qn)
    pin.framesForwardKinematics(pm, data, qn)
    fv = np.zeros(pm.nv)
    for side in "ab":
        fid = robot.frame_id(f"closure:{side}")
        J = pin.getFrameJacobian(pm, data, fid, pin.ReferenceFrame.LOCAL)
        w = np.concatenate([getattr(rc, f"force_{side}"), getattr(rc, f"torque_{side}")])
        fv += J.T @ w
    T = robot.velocity_map(q)
    np.testing.assert_allclose(
        T.T @ fv, rc.generalized, atol=1e-9 * max(1.0, np.abs(rc.generalized).max())
    )


def test_robot_contact_wrench_rebuilds_the_generalized_force() -> None:
    pin = pytest.importorskip("pinocchio")
    from nonmin.model.robots._examples import serial_arm

    robot, state = serial_arm()
    q = state.q
    act = {"ee_contact"}
    sol = robot.forward_dynamics(q, np.zeros(robot.n), active=act)
    rc = nonmin.reactions(robot, q, sol.f_c, active=act)["ee_contact"]
    assert rc.kind == "frame" and rc.multipliers[0] > 0  # the ground pushes the arm up
    pm = robot.pinocchio_model
    data = pm.createData()
    qn = robot.pinocchio_configuration(q)
    pin.computeJointJacobians(pm, data, qn)
    pin.framesForwardKinematics(pm, data, qn)
    fv = np.zeros(pm.nv)
    for side in "ab":
        J = pin.getFrameJacobian(
            pm, data, robot.frame_id(f"ee_contact:{side}"), pin.ReferenceFrame.LOCAL
        )
        fv += J.T @ np.concatenate([getattr(rc, f"force_{side}"), getattr(rc, f"torque_{side}")])
    np.testing.assert_allclose(robot.velocity_map(q).T @ fv, rc.generalized, atol=1e-9)


def test_simulate_stores_reactions_when_asked() -> None:
    model = _bar_pendulum()
    q0, qd0 = _pendulum_state(0.4, 0.0, 1.2)
    traj = nonmin.simulate(model, 0.1, q0, qd0, dt=1e-2, reactions=True)
    assert set(traj.reactions) == {"pivot"} and traj.reactions["pivot"].force_b.shape == (len(traj), 2)
    ref = traj.with_reactions(model).reactions["pivot"]
    np.testing.assert_array_equal(traj.reactions["pivot"].force_b, ref.force_b)
    plain = nonmin.simulate(model, 0.1, q0, qd0, dt=1e-2)
    assert plain.reactions == {}
    from nonmin.errors import InputError
    from nonmin.sim import Output

    assert Output(reactions=["pivot"]).reactions == ("pivot",)
    with pytest.raises(InputError, match="reactions"):
        Output(reactions="pivot")
