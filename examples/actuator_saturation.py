"""Actuator limits: the controller clips u to [u_min, u_max] and reports it.

The oblique-actuator pendulum passes near θ = 0.3, where the rod is parallel to the force and
u = (PB)⁺ f_∥ grows without bound. With limits ±30 N the controller clips the force, flags
the saturated actuator in ``info(...)`` and counts the saturated accepted steps in its state
(``ControlState.saturated_steps``); the pendulum still reaches the target, more slowly (the
Lyapunov guarantee holds only while no actuator saturates).

Run: python examples/actuator_saturation.py [--out DIR] [--quick]
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _example_common import figure, parse, save
from control_scenes import oblique_pendulum, pendulum_configuration

from nonmin.control import Regulator
from nonmin.sim import simulate

LIMIT = 30.0  # N


def main(argv: list[str] | None = None) -> None:
    args = parse("actuator_saturation", __doc__, argv)
    model = oblique_pendulum(0.3)
    target = pendulum_configuration(0.8)
    t1, dt = (0.2, 1e-2) if args.quick else (4.0, 2e-3)
    fig, ax = figure(3, size=(7, 7))
    for limit in (None, LIMIT):
        reg = Regulator(model, target=target, Kp=100.0, Kd=20.0,
                        u_min=None if limit is None else -limit, u_max=limit)
        traj = simulate(model, (0.0, t1), pendulum_configuration(-math.pi / 2), method="rk4", dt=dt,
                        controller=reg)
        state = reg.initial_state()
        sat = np.zeros(traj.t.size, dtype=bool)
        for i, (t, q, qd) in enumerate(zip(traj.t, traj.q, traj.qd)):
            state = reg.update(t, q, qd, state)
            sat[i] = state.saturated[0]
        label = "no limit" if limit is None else f"|u| ≤ {limit:g} N"
        err = np.linalg.norm(traj.q - target, axis=1)
        print(f"{label}: max |u| applied = {np.abs(traj.u).max():.3g} N, largest requested = "
              f"{state.max_abs_u[0]:.3g} N, saturated steps = {state.saturated_steps[0]}/{state.steps}, "
              f"final error = {err[-1]:.2e}")
        ax[0].plot(traj.t, traj.u[:, 0], label=label)
        ax[1].semilogy(traj.t, np.maximum(err, 1e-16), label=label)
        if limit is not None:
            ax[2].plot(traj.t, sat.astype(float), drawstyle="steps-post")
    ax[0].set_ylabel("u (N)")
    ax[0].set_ylim(-200, 200)
    ax[0].legend()
    ax[1].set_ylabel("|q − q*|")
    ax[1].legend()
    ax[2].set_ylabel("saturated")
    ax[2].set_xlabel("t (s)")
    ax[0].set_title("Actuator limits respected and reported")
    save(fig, args.out, "saturation.png")


if __name__ == "__main__":
    main()
