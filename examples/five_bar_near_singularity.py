"""Regulate a five-bar parallel robot 4 mm from its parallel (type-2) singularity.

The five-bar (library ``five_bar``: 12 absolute coordinates, 10 pin rows, 2 DOF, motors at
the two base joints) loses actuation where the distal links are collinear (end effector at
y = √3/2 ≈ 0.866): there rank(PB) = 1 < n − rank(A) = 2 and the controller raises
InfeasibleActuationError. The target puts the end effector at y = 0.87, where σ_min(PB) ≈ 4e-3:
still feasible, and the regulator converges to 1e-6 with a monotone Lyapunov function —
at the price of large motor torques, shown with σ_min(PB) along the motion and along a scan.

Run: python examples/five_bar_near_singularity.py [--out DIR] [--quick]
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _example_common import figure, parse, save

from nonmin.control import Regulator
from nonmin.errors import InfeasibleActuationError
from nonmin.library import five_bar
from nonmin.sim import simulate
from nonmin.viz import plot_snapshot


def main(argv: list[str] | None = None) -> None:
    args = parse("five_bar_near_singularity", __doc__, argv)
    mech = five_bar()
    model = mech.model
    target = five_bar(end_effector=(0.0, 0.87)).state.q
    reg = Regulator(model, target=target, Kp=400.0, Kd=40.0)
    t1 = 0.1 if args.quick else 1.5
    traj = simulate(mech, (0.0, t1), method="dopri5", rtol=1e-10, atol=1e-12, controller=reg)
    infos = [reg.info(t, q, qd) for t, q, qd in zip(traj.t, traj.q, traj.qd)]
    V = np.array([i.lyapunov for i in infos])
    smin = np.array([i.sigma_pb[-1] for i in infos])
    err = np.abs(traj.q - target).max(axis=1)
    print(f"final max|q − q*| = {err[-1]:.3e}; max increase of V = {np.max(np.diff(V)):.3e}; "
          f"σ_min(PB) at the end = {smin[-1]:.3e}; max |u| = {np.abs(traj.u).max():.3g} N·m")
    ys = np.linspace(0.80, 1.3, 11 if args.quick else 101)
    scan = []
    for y in ys:
        q = five_bar(end_effector=(0.0, float(y))).state.q
        try:
            scan.append(reg.info(0.0, q, np.zeros(model.n)).sigma_pb[-1])
        except InfeasibleActuationError:
            scan.append(np.nan)
    try:
        reg(0.0, five_bar(end_effector=(0.0, math.sqrt(3) / 2)).state.q, np.zeros(model.n))
    except InfeasibleActuationError as exc:
        print("at the singularity:", str(exc).split(";")[0])
    fig, ax = figure(4, size=(7, 9))
    ax[0].semilogy(traj.t, err)
    ax[0].set_ylabel("max |q − q*|")
    ax[1].semilogy(traj.t, np.maximum(V, 1e-300))
    ax[1].set_ylabel("V")
    ax[2].plot(traj.t, traj.u)
    ax[2].set_ylabel("base torques (N·m)")
    ax[2].set_xlabel("t (s)")
    ax[3].semilogy(ys, scan, ".-")
    ax[3].axvline(math.sqrt(3) / 2, color="r", ls=":", label="type-2 singularity")
    ax[3].axvline(0.87, color="k", ls="--", label="target")
    ax[3].set_xlabel("end-effector height y (x = 0)")
    ax[3].set_ylabel("σ_min(PB)")
    ax[3].legend()
    ax[0].set_title("Five-bar regulated close to its parallel singularity")
    save(fig, args.out, "regulation.png")
    save(plot_snapshot(model, [traj.q[0], target], title="five-bar: start (light), target (dark)"),
         args.out, "snapshots.png")


if __name__ == "__main__":
    main()
