"""Regulator (corrected paper law): regulation to 1e-6 with a Lyapunov function that never increases.

Scenes: Cartesian pendulum with one oblique actuator, crank-driven four-bar (absolute
coordinates), five-bar parallel robot regulated 4 mm from its parallel singularity. Closed loops
run with ``nonmin.sim.simulate`` (adaptive Dormand–Prince, rtol 1e-10): the Lyapunov increase
allowed between samples is tied to that accuracy (``LYAP_RTOL · V0``).
"""

from __future__ import annotations

import math
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from nonmin.control import Regulator
from nonmin.core import actuation_projectors
from nonmin.errors import AssemblyError, InfeasibleActuationError, InputError
from nonmin.library import five_bar
from nonmin.sim import simulate

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "examples"))
from control_scenes import (
    crank_four_bar,
    crank_four_bar_configuration,
    oblique_pendulum,
    pendulum_configuration,
)

#: Integration tolerance of the closed-loop runs.
SIM_RTOL = 1e-10
#: Allowed increase of V between samples, relative to V(0) (integration error only).
LYAP_RTOL = 1e-9
#: Required final accuracy of the regulation.
REG_TOL = 1e-6


def _lyapunov_series(reg: Regulator, traj) -> np.ndarray:
    return np.array([reg.lyapunov(traj.q[i], traj.qd[i]) for i in range(traj.t.size)])


def _check_lyapunov(V: np.ndarray) -> None:
    assert V[-1] < 1e-9 * V[0]
    assert np.max(np.diff(V)) <= LYAP_RTOL * V[0], f"V increased by {np.max(np.diff(V)):.3g}"


@pytest.fixture(scope="module")
def pendulum():
    return oblique_pendulum(0.3)


def test_actuation_is_min_norm_gamma_and_realizes_f_par(pendulum) -> None:
    """u = (PB)⁺ f_∥ equals core's Γ f_∥ and P B u = f_∥ (ERRATA 4)."""
    q = pendulum_configuration(-1.0)
    reg = Regulator(pendulum, target=pendulum_configuration(0.5), Kp=10.0, Kd=3.0)
    qd = np.array([0.2, 0.2 * math.tan(-1.0) ** -1 * -1])  # any velocity
    info = reg.info(0.0, q, qd)
    B = pendulum.input_matrix(q)
    A = pendulum.constraint_jacobian(0.0, q)
    P = np.eye(2) - A.T @ np.linalg.pinv(A.T)
    _, Gamma = actuation_projectors(B, P)
    np.testing.assert_allclose(info.u, Gamma @ info.f_par, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(P @ B @ info.u, info.f_par, atol=1e-12)
    np.testing.assert_allclose(P @ info.f_par, info.f_par, atol=1e-12)
    # f_∥ = −P(f_g + Kp e + Kd qd)
    e = q - pendulum_configuration(0.5)
    expect = -P @ (pendulum.conservative_force(q) + 10.0 * e + 3.0 * qd)
    np.testing.assert_allclose(info.f_par, expect, atol=1e-12)


def test_pendulum_oblique_actuator_regulates_with_monotone_lyapunov(pendulum) -> None:
    target = pendulum_configuration(0.8)
    reg = Regulator(pendulum, target=target, Kp=100.0, Kd=20.0)
    traj = simulate(pendulum, (0.0, 2.5), pendulum_configuration(-math.pi / 2), method="dopri5",
                    rtol=SIM_RTOL, atol=1e-12, controller=reg)
    assert np.abs(traj.q[-1] - target).max() < REG_TOL
    _check_lyapunov(_lyapunov_series(reg, traj))


def test_sigma_above_one_sticks(pendulum) -> None:
    """ERRATA 5: with σ = 1.5 the loop sticks far from the target; with σ = 0 it converges."""
    target = pendulum_configuration(0.8)
    q0 = pendulum_configuration(-math.pi / 2)
    err = {}
    for sigma in (0.0, 1.5):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            reg = Regulator(pendulum, target=target, Kp=20.0, Kd=6.0, sigma=sigma)
        traj = simulate(pendulum, (0.0, 6.0), q0, method="rk4", dt=1e-2, controller=reg)
        th = np.arctan2(traj.q[:, 1], traj.q[:, 0])
        err[sigma] = abs(th[-1] - 0.8)
    assert err[0.0] < 1e-5
    # σ = 1.5 sticks near the start (initial error 2.37 rad); what little it moves is the
    # discretization chattering across qd = 0 (it shrinks with dt)
    assert err[1.5] > 1.5


def test_sigma_warning() -> None:
    with pytest.warns(RuntimeWarning, match="ERRATA 5"):
        Regulator(oblique_pendulum(), target=[1.0, 0.0], sigma=1.5)


def test_crank_four_bar_regulates(tmp_path) -> None:
    model = crank_four_bar()
    q0 = crank_four_bar_configuration(model, 0.3)
    target = crank_four_bar_configuration(model, 2.0)
    reg = Regulator(model, target=target, Kp=200.0, Kd=30.0)
    traj = simulate(model, (0.0, 2.0), q0, method="dopri5", rtol=SIM_RTOL, atol=1e-12, controller=reg)
    assert np.abs(traj.q[-1] - target).max() < REG_TOL
    _check_lyapunov(_lyapunov_series(reg, traj))


def test_five_bar_near_parallel_singularity() -> None:
    mech = five_bar()
    target = five_bar(end_effector=(0.0, 0.87)).state.q  # singular at y = √3/2 ≈ 0.866
    reg = Regulator(mech.model, target=target, Kp=400.0, Kd=40.0)
    info = reg.info(0.0, target, np.zeros(mech.model.n))
    assert info.feasible and info.sigma_pb[-1] < 5e-3  # close to the actuation singularity
    traj = simulate(mech, (0.0, 1.5), method="dopri5", rtol=SIM_RTOL, atol=1e-12, controller=reg)
    assert np.abs(traj.q[-1] - target).max() < REG_TOL
    _check_lyapunov(_lyapunov_series(reg, traj))
    # at the singularity itself the actuation condition fails
    q_sing = five_bar(end_effector=(0.0, math.sqrt(3) / 2)).state.q
    with pytest.raises(InfeasibleActuationError, match="rank\\(PB\\) = 1 < n − rank\\(A\\) = 2"):
        reg(0.0, q_sing, np.zeros(mech.model.n))
    lsq = Regulator(mech.model, target=target, Kp=400.0, Kd=40.0, on_infeasible="least_squares")
    inf = lsq.info(0.0, q_sing, np.zeros(mech.model.n))
    assert not inf.feasible and np.isfinite(inf.u).all()


def test_pendulum_infeasible_where_rod_parallel_to_actuator(pendulum) -> None:
    q = pendulum_configuration(0.3)  # rod along the force direction: PB = 0
    reg = Regulator(pendulum, target=pendulum_configuration(1.0))
    with pytest.raises(InfeasibleActuationError):
        reg(0.0, q, np.zeros(2))


def test_off_manifold_target_projected_or_rejected(pendulum) -> None:
    reg = Regulator(pendulum, target=[2.0, 2.0], Kp=4.0, Kd=2.0)
    np.testing.assert_allclose(reg.target_for(), [math.sqrt(0.5)] * 2, atol=1e-12)
    massreg = Regulator(pendulum, target=[2.0, 2.0], metric="mass")
    np.testing.assert_allclose(massreg.target_for(), [math.sqrt(0.5)] * 2, atol=1e-12)
    strict = Regulator(pendulum, target=[2.0, 2.0], target_policy="reject")
    with pytest.raises(AssemblyError, match="off the constraint manifold"):
        strict(0.0, pendulum_configuration(0.0), np.zeros(2))
    # at the projected target, the regulator holds still: u balances gravity exactly
    q = reg.target_for()
    traj = simulate(pendulum, (0.0, 0.5), q, method="rk4", dt=1e-2, controller=reg)
    assert np.abs(traj.q - q).max() < 1e-10


def test_four_bar_fixed_projection_keeps_crank_angle() -> None:
    model = crank_four_bar()
    q = crank_four_bar_configuration(model, 1.0)
    guess = q + 0.05
    proj = Regulator(model, target=guess, fixed=[2]).target_for()
    assert proj[2] == pytest.approx(guess[2], abs=1e-12)
    assert np.linalg.norm(model.constraint_residual(0.0, proj)) < 1e-10


def test_saturation_respected_and_reported(pendulum) -> None:
    target = pendulum_configuration(0.8)
    reg = Regulator(pendulum, target=target, Kp=100.0, Kd=20.0, u_min=-30.0, u_max=30.0)
    traj = simulate(pendulum, (0.0, 3.0), pendulum_configuration(-math.pi / 2), method="rk4",
                    dt=5e-3, controller=reg)
    assert np.all(np.abs(traj.u) <= 30.0 + 1e-12)
    state = reg.initial_state()
    for i in range(traj.t.size):
        state = reg.update(traj.t[i], traj.q[i], traj.qd[i], state)
    assert state.saturated_steps[0] > 0 and state.max_abs_u[0] > 30.0
    assert state.steps == traj.t.size
    assert np.abs(traj.q[-1] - target).max() < 1e-4  # still gets there, more slowly


def test_bad_arguments(pendulum) -> None:
    with pytest.raises(InputError, match="Kp must be positive definite"):
        Regulator(pendulum, target=[1.0, 0.0], Kp=-1.0)
    with pytest.raises(InputError, match="target must be a finite vector"):
        Regulator(pendulum, target=[1.0, 0.0, 0.0])
    with pytest.raises(InputError, match="u_min must be ≤ u_max"):
        Regulator(pendulum, target=[1.0, 0.0], u_min=1.0, u_max=0.0)
    with pytest.raises(InputError, match="on_infeasible"):
        Regulator(pendulum, target=[1.0, 0.0], on_infeasible="ignore")  # type: ignore[arg-type]
