"""Why σ must stay 0: the paper's "σ‖e‖η" term makes the regulator stick (ERRATA 5).

Theorem 2 of the paper claims convergence for σ > 1. The term σ Kp ‖e‖ η (η = qd/‖qd‖) is dry
(Coulomb) friction: every rest state with ‖Pe‖ ≤ σ‖e‖ is an equilibrium in the Filippov sense,
so the pendulum stops far from the target, while σ = 0 converges. On the circle the error
q − q* of a far target is mostly normal to the manifold (‖Pe‖ ≈ 0.38‖e‖ at the start here),
so σ = 0.5 sticks as well. The little motion left is numerical chattering across qd = 0 (it
shrinks with dt).

Run: python examples/sigma_sticking.py [--out DIR] [--quick]
"""

from __future__ import annotations

import math
import sys
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _example_common import figure, parse, save
from control_scenes import oblique_pendulum, pendulum_configuration

from nonmin.control import Regulator
from nonmin.sim import simulate


def main(argv: list[str] | None = None) -> None:
    args = parse("sigma_sticking", __doc__, argv)
    model = oblique_pendulum(0.3)
    theta_star = 0.8
    t1, dt = (0.3, 1e-2) if args.quick else (10.0, 2e-3)
    fig, ax = figure(2, size=(7, 6))
    for sigma in (0.0, 0.5, 1.5):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # the σ > 1 warning is the point here
            reg = Regulator(model, target=pendulum_configuration(theta_star), Kp=20.0, Kd=6.0, sigma=sigma)
        traj = simulate(model, (0.0, t1), pendulum_configuration(-math.pi / 2), method="rk4", dt=dt,
                        controller=reg)
        th = np.arctan2(traj.q[:, 1], traj.q[:, 0])
        err = np.abs(th - theta_star)
        print(f"sigma = {sigma}: |θ − θ*| after {t1:g} s = {err[-1]:.3e} rad")
        ax[0].plot(traj.t, th, label=f"σ = {sigma}")
        ax[1].semilogy(traj.t, np.maximum(err, 1e-16), label=f"σ = {sigma}")
    ax[0].axhline(theta_star, color="k", ls=":", label="θ*")
    ax[0].set_ylabel("θ (rad)")
    ax[0].legend()
    ax[1].set_ylabel("|θ − θ*| (rad)")
    ax[1].set_xlabel("t (s)")
    ax[0].set_title(f"Regulator with the paper's σ‖e‖η term (RK4, dt = {dt:g} s)")
    save(fig, args.out, "sigma_sticking.png")


if __name__ == "__main__":
    main()
