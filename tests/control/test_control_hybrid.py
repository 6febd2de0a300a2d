"""Tracking, hybrid force/motion control through a topology switch, and the dual-arm grasp."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

from nonmin.control import (
    ForceControl,
    Reference,
    Regulator,
    Switched,
    Tracker,
    constraint_force_components,
    project_configuration,
)
from nonmin.core import impact_map, solve_dynamics
from nonmin.errors import InfeasibleActuationError, UnknownNameError
from nonmin.library import arm2r_wall
from nonmin.model.planar import PlanarBuilder
from nonmin.sim import Event, Reset, simulate

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "examples"))
from control_scenes import (
    arm2r_configuration,
    crank_four_bar,
    crank_four_bar_configuration,
    dual_arm_grasp_configuration,
    dual_arm_with_fixture,
    oblique_pendulum,
    pendulum_configuration,
    wall_tip_path,
)

#: Tolerance on the commanded contact force (N).
FORCE_TOL = 1e-6


def _active(model, mask_row) -> frozenset[str]:
    return frozenset(c for c, a in zip(model.constraint_names, mask_row) if a)


# ----------------------------------------------------------------------------- tracking
@pytest.mark.parametrize("method", ["passivity", "computed_torque"])
def test_tracker_follows_crank_trajectory(method: str) -> None:
    model = crank_four_bar()

    def crank(t: float) -> float:
        return 1.0 + 0.8 * math.sin(2.0 * t)

    ref = Reference.from_functions(lambda t: crank_four_bar_configuration(model, crank(t)))
    trk = Tracker(model, ref, Kp=400.0, Kd=40.0, lambda_=10.0, method=method)
    q0 = crank_four_bar_configuration(model, 0.6)  # starts 0.4 rad off
    traj = simulate(model, (0.0, 1.5), q0, method="rk4", dt=5e-3, controller=trk)
    err = np.abs(traj.q[:, 2] - np.array([crank(t) for t in traj.t]))
    assert err[0] == pytest.approx(0.4)
    assert err[traj.t >= 1.2].max() < 1e-5  # numerical reference derivatives limit this


def test_passivity_set_point_lyapunov_non_increasing() -> None:
    """For a set-point and scalar Kp, W = ½ sᵀM̄s + ½ eᵀKp e never increases."""
    model = oblique_pendulum(0.3)
    target = pendulum_configuration(0.8)
    trk = Tracker(model, target, Kp=100.0, Kd=20.0, lambda_=5.0)
    traj = simulate(model, (0.0, 1.5), pendulum_configuration(-1.2), method="dopri5",
                    rtol=1e-10, atol=1e-12, controller=trk)
    W = np.array([trk.lyapunov(q, qd, t=t) for t, q, qd in zip(traj.t, traj.q, traj.qd)])
    assert np.max(np.diff(W)) <= 1e-9 * W[0]
    assert np.abs(traj.q[-1] - target).max() < 1e-6


def test_reference_projection_consistent() -> None:
    model = oblique_pendulum(0.3)
    ref = Reference.from_functions(lambda t: 1.3 * pendulum_configuration(t))  # off the circle
    trk = Tracker(model, ref)
    q, v, a = trk.desired(0.4)
    assert np.linalg.norm(q) == pytest.approx(1.0, abs=1e-12)
    assert abs(q @ v) < 1e-12  # tangent
    assert abs(q @ a + v @ v) < 1e-12  # A qdd + γ = 0


# ----------------------------------------------------------------------------- force control
def test_force_law_matches_corrected_fc_fp() -> None:
    """c₀ used by ForceControl equals −S h + S M Ω qd for admissible qd (corrected fc_fp)."""
    mech = arm2r_wall()
    m = mech.model
    act = frozenset({"shoulder", "elbow", "wall"})
    q = arm2r_configuration((1.5, 0.2))
    rng = np.random.default_rng(0)
    A = m.constraint_jacobian(0.0, q, act)
    P = np.eye(6) - np.linalg.pinv(A) @ A
    qd = P @ rng.normal(size=6)
    terms = m.evaluate(0.0, q, qd, act)
    c0 = solve_dynamics(terms.M, terms.h, A, terms.constraints.gamma).f_c
    Adot = m.constraint_jacobian_dot(0.0, q, qd, act)
    Lam = -np.linalg.pinv(A) @ Adot
    Om = Lam - Lam.T
    M = terms.M
    mu = np.trace(P @ M @ P) / np.trace(P)
    Mbar = P @ M @ P + mu * (np.eye(6) - P)
    S = np.eye(6) - M @ np.linalg.solve(Mbar, P)
    np.testing.assert_allclose(c0, -S @ terms.h + S @ M @ Om @ qd, atol=1e-10)


def test_contact_force_commanded_through_impact() -> None:
    """One controller, unchanged: free motion → impact on the wall → 5 N contact force held
    to 1e-6 while the tip slides along the wall to its target."""
    mech = arm2r_wall()
    m = mech.model

    def path(t: float) -> np.ndarray:
        return wall_tip_path(t, t_reach=0.6, t_settle=0.3, t_slide=1.0)

    ref = Reference.from_functions(lambda t: arm2r_configuration(path(t)))
    ctl = ForceControl(Tracker(m, ref, Kp=400.0, Kd=40.0, method="computed_torque"), {"wall": 5.0})
    traj = simulate(mech, (0.0, 2.0), method="rk4", dt=4e-3, controller=ctl)
    impacts = [e for e in traj.events if "wall" in e.name]
    assert len(impacts) == 1 and 0.3 < impacts[0].t < 0.6
    in_contact = [i for i in range(traj.t.size) if "wall" in _active(m, traj.active_mask[i])]
    assert in_contact and traj.t[in_contact[0]] == pytest.approx(impacts[0].t)
    assert all("wall" in _active(m, traj.active_mask[i]) for i in range(in_contact[0], traj.t.size))
    lam = np.array([
        ctl.measured_force(traj.t[i], traj.q[i], traj.f_c[i], active=_active(m, traj.active_mask[i]))["wall"][0]
        for i in in_contact
    ])
    assert np.abs(lam - 5.0).max() < FORCE_TOL
    tip = m.outputs(traj.t[-1], traj.q[-1], traj.qd[-1])["tip.position"]
    np.testing.assert_allclose(tip, path(2.0), atol=1e-6)
    # free phase: the same controller is just the tracker (no force rows active)
    i = in_contact[0] - 5
    free = _active(m, traj.active_mask[i])
    np.testing.assert_allclose(
        ctl(traj.t[i], traj.q[i], traj.qd[i], active=free),
        ctl.motion(traj.t[i], traj.q[i], traj.qd[i], active=free),
    )


def test_force_needs_actuators_reaching_the_constraint() -> None:
    """A pendulum pushed only tangentially cannot command the rod tension."""
    model = oblique_pendulum(math.pi / 2)  # push along +y
    q = pendulum_configuration(0.0)  # rod along x, push ⟂ rod
    ctl = ForceControl(Regulator(model, target=pendulum_configuration(0.3)), {"rod": 1.0})
    with pytest.raises(InfeasibleActuationError, match="constraint directions"):
        ctl(0.0, q, np.zeros(2))
    # with a second actuator, motion and rod force are commanded together
    b = PlanarBuilder("pendulum_xy", gravity=(0.0, -9.81))
    b.point_mass("bob", mass=1.0, points=["P"])
    b.ground_point("O", (0.0, 0.0))
    b.rod("rod", "O", "P", length=1.0)
    b.force("fx", "P", direction=(1.0, 0.0))
    b.force("fy", "P", direction=(0.0, 1.0))
    two = b.build()
    ok = ForceControl(Regulator(two, target=pendulum_configuration(0.5), Kp=5.0, Kd=1.0), {"rod": -2.0})
    qd = np.array([0.0, 0.5])
    info = ok.info(0.0, q, qd)
    terms = two.evaluate(0.0, q, qd)
    f = terms.B @ info.u
    sol = solve_dynamics(terms.M, terms.h, terms.constraints.A, terms.constraints.gamma, f)
    lam = constraint_force_components(two, 0.0, q, sol.f_c, ["rod"])["rod"]
    assert lam[0] == pytest.approx(-2.0, abs=1e-12)
    np.testing.assert_allclose(sol.P @ f, info.f_par, atol=1e-12)  # motion part untouched


# ----------------------------------------------------------------------------- dual-arm grasp
def test_dual_arm_grasp_then_regulate_object_pose() -> None:
    model, q0 = dual_arm_with_fixture()
    pins = frozenset({"L_shoulder", "L_elbow", "R_shoulder", "R_elbow"})
    pre, post = pins | {"fixture"}, pins | {"grasp_L", "grasp_R"}
    q_grasp = dual_arm_grasp_configuration(model)
    pose = np.array([0.2, 1.0, 0.3])
    q_goal_guess = q_grasp.copy()
    q_goal_guess[12:15] = pose
    carry = Regulator(model, target=q_goal_guess, Kp=400.0, Kd=40.0, fixed=[12, 13, 14])
    ctl = Switched(model, {pre: Regulator(model, target=q_grasp, Kp=400.0, Kd=40.0), post: carry})
    # after the grasp: 3 DOF, 4 actuators (redundant); BᵀPB is singular, (PB)⁺ is not needed to be
    info = carry.info(0.0, q_grasp, np.zeros(15), active=post)
    assert info.feasible and info.sigma_pb.size == 4 and info.sigma_pb[-1] < 1e-10

    def distance(t, q, qd, f_c):
        out = model.outputs(t, q, qd)
        half = 0.3 * np.array([math.cos(q[14]), math.sin(q[14])])
        return max(np.linalg.norm(out["L_tip.position"] - (q[12:14] - half)),
                   np.linalg.norm(out["R_tip.position"] - (q[12:14] + half))) - 1e-4

    def grasp(t, q, qd, active):
        act = (frozenset(active) - {"fixture"}) | {"grasp_L", "grasp_R"}
        qn = project_configuration(model, q, active=act, metric="mass")
        return qn, impact_map(model.mass_matrix(qn), model.constraint_jacobian(t, qn, act), qd), act

    traj = simulate(model, (0.0, 2.2), q0, active=pre, method="rk4", dt=5e-3, controller=ctl,
                    events=[Event(distance, direction=-1, transition=Reset(grasp), name="grasp")])
    assert [e.name for e in traj.events] == ["grasp"]
    assert _active(model, traj.active_mask[-1]) == post
    assert np.abs(traj.q[-1, 12:15] - pose).max() < 1e-6
    assert np.abs(traj.q[-1] - carry.target_for(post)).max() < 1e-6
    assert traj.phi_norm.max() < 1e-9
    with pytest.raises(UnknownNameError, match="no controller for active set"):
        ctl(0.0, q0, np.zeros(15), active=pins)


def test_passivity_terms_match_core_kernels() -> None:
    """The tracker's inline Ṗ and C̄ agree with nonmin.core (one shared pseudo-inverse)."""
    from nonmin.control._common import evaluate, mbar
    from nonmin.core import coriolis_bar, projector_derivative

    model = crank_four_bar()
    q = crank_four_bar_configuration(model, 0.7)
    A = model.constraint_jacobian(0.0, q)
    P = np.eye(model.n) - np.linalg.pinv(A) @ A
    qd = P @ np.linspace(-1.0, 1.0, model.n)
    trk = Tracker(model, crank_four_bar_configuration(model, 1.0), Kp=3.0, Kd=2.0, lambda_=1.5)
    act = model.resolve_active(None)
    ev = evaluate(model, 0.0, q, qd, act, None)
    out = trk.law(0.0, q, qd, ev, act)
    # recompute the law with the core kernels
    Adot = model.constraint_jacobian_dot(0.0, q, qd)
    Mb, mu = mbar(ev)
    Pdot = projector_derivative(A, Adot)
    Cbar = coriolis_bar(ev.M, model.coriolis_matrix(q, qd), A, Adot, mu)
    qs = trk.desired(0.0, q)[0]
    e = q - qs
    x = -1.5 * e
    qr_d, qr_dd = ev.P @ x, Pdot @ x + ev.P @ (-1.5 * qd)
    s = qd - qr_d
    expect = ev.P @ (Mb @ qr_dd + Cbar @ qr_d - ev.f_g - 2.0 * s - 3.0 * e)
    np.testing.assert_allclose(out.f_par, expect, atol=1e-10)
