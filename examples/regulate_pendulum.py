"""Regulate a Cartesian pendulum pushed by one oblique force (the paper's law, corrected).

The pendulum has dependent coordinates q = (x, y), one rod constraint and a single actuator
pushing along (cos 0.3, sin 0.3) — not in N(A) nor spanning it everywhere, yet
rank(PB) = n − rank(A) = 1 except where the rod is parallel to the force (ERRATA 4). The law
f_∥ = −P(f_g + Kp e + Kd qd), u = (PB)⁺ f_∥ drives q to q* and V = ½qdᵀM̄qd + ½eᵀKp e never
increases. The path crosses θ = 0.3, where the rod is parallel to the force: there
σ(PB) → 0 and the actuator force spikes (see actuator_saturation.py for limits).

Run: python examples/regulate_pendulum.py [--out DIR] [--quick]
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


def main(argv: list[str] | None = None) -> None:
    args = parse("regulate_pendulum", __doc__, argv)
    model = oblique_pendulum(0.3)
    target = pendulum_configuration(0.8)
    reg = Regulator(model, target=target, Kp=100.0, Kd=20.0)
    t1 = 0.3 if args.quick else 3.0
    traj = simulate(model, (0.0, t1), pendulum_configuration(-math.pi / 2), method="dopri5",
                    rtol=1e-10, atol=1e-12, controller=reg)
    V = np.array([reg.lyapunov(q, qd) for q, qd in zip(traj.q, traj.qd)])
    err = np.linalg.norm(traj.q - target, axis=1)
    print(f"final |q - q*| = {err[-1]:.3e}, max increase of V = {np.max(np.diff(V)):.3e} "
          f"(V0 = {V[0]:.3g})")
    sig = np.array([reg.info(t, q, qd).sigma_pb[-1] for t, q, qd in zip(traj.t, traj.q, traj.qd)])
    print(f"smallest σ(PB) along the run: {sig.min():.3e} (rod parallel to the actuator)")
    fig, ax = figure(4, size=(7, 8))
    ax[0].semilogy(traj.t, err)
    ax[0].set_ylabel("|q − q*|")
    ax[1].semilogy(traj.t, np.maximum(V, 1e-300))
    ax[1].set_ylabel("V = ½qdᵀM̄qd + ½eᵀKp e")
    ax[2].plot(traj.t, traj.u[:, 0])
    ax[2].set_ylabel("u (N)")
    ax[3].semilogy(traj.t, sig)
    ax[3].set_ylabel("σ(PB)")
    ax[3].set_xlabel("t (s)")
    ax[0].set_title("Oblique-actuator pendulum: regulation in dependent coordinates")
    save(fig, args.out, "regulation.png")
    fig, ax = figure(1, size=(5, 5))
    ax[0].plot(traj.q[:, 0], traj.q[:, 1], "-", label="bob path")
    ax[0].plot(*target, "r*", ms=12, label="q*")
    ax[0].quiver(0, 0, math.cos(0.3), math.sin(0.3), angles="xy", scale_units="xy", scale=2,
                 color="C2", label="actuator direction")
    ax[0].set_aspect("equal")
    ax[0].legend()
    save(fig, args.out, "path.png")


if __name__ == "__main__":
    main()
