"""Hybrid position/force control through a topology switch, without multipliers.

A 2R arm (library ``arm2r_wall``, absolute coordinates) tracks a tip path that reaches behind a
wall. One controller, unchanged for the whole run — ``ForceControl(Tracker(...), {"wall": 5})``:
while the wall constraint is inactive it is the tracker; the simulator detects the contact and
applies the impact map; from then on the same controller commands a 5 N contact force through
the corrected eq. (fc_fp) (f_⊥ chosen so that the force carried by the wall row is 5 N) while
the motion part tracks the path projected onto the wall, sliding up along it.

Run: python examples/wall_force_control.py [--out DIR] [--quick]
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _example_common import figure, parse, save
from control_scenes import arm2r_configuration, wall_tip_path

from nonmin.control import ForceControl, Reference, Tracker
from nonmin.library import arm2r_wall
from nonmin.sim import simulate
from nonmin.viz import plot_snapshot

FORCE = 5.0  # N, commanded normal contact force


def main(argv: list[str] | None = None) -> None:
    args = parse("wall_force_control", __doc__, argv)
    mech = arm2r_wall()
    model = mech.model

    def path(t: float) -> np.ndarray:
        return wall_tip_path(t, t_reach=1.0, t_settle=0.4, t_slide=2.0)

    ref = Reference.from_functions(lambda t: arm2r_configuration(path(t)))
    ctl = ForceControl(Tracker(model, ref, Kp=400.0, Kd=40.0, lambda_=10.0), {"wall": FORCE})
    t1, dt = (0.2, 1e-2) if args.quick else (3.5, 2e-3)
    traj = simulate(mech, (0.0, t1), method="rk4", dt=dt, controller=ctl)
    names = model.constraint_names
    in_contact = np.array([traj.active_mask[i, names.index("wall")] for i in range(traj.t.size)])
    lam = np.full(traj.t.size, np.nan)
    for i in np.flatnonzero(in_contact):
        act = frozenset(c for c, a in zip(names, traj.active_mask[i]) if a)
        lam[i] = ctl.measured_force(traj.t[i], traj.q[i], traj.f_c[i], active=act)["wall"][0]
    tip = np.array([model.outputs(t, q, qd)["tip.position"] for t, q, qd in zip(traj.t, traj.q, traj.qd)])
    goal = np.array([path(t) for t in traj.t])
    for e in traj.events:
        print(f"event {e.name!r} at t = {e.t:.4f} s")
    if in_contact.any():
        print(f"contact force error max |λ − {FORCE}| = {np.nanmax(np.abs(lam - FORCE)):.3e} N over "
              f"{in_contact.sum()} samples in contact")
    print(f"final tip = {tip[-1]}, path = {goal[-1]}")
    fig, ax = figure(4, size=(7, 9))
    ax[0].plot(traj.t, tip[:, 0], label="tip x")
    ax[0].plot(traj.t, goal[:, 0], "k:", label="path x (reaches behind the wall)")
    ax[0].axhline(1.5, color="r", lw=0.8, label="wall")
    ax[0].plot(traj.t, tip[:, 1], label="tip y")
    ax[0].plot(traj.t, goal[:, 1], "k--", label="path y")
    ax[0].legend(fontsize=8)
    ax[0].set_ylabel("m")
    ax[1].plot(traj.t, lam, label="measured (rows of (Aᵀ)⁺ f_c)")
    ax[1].axhline(FORCE, color="k", ls=":", label="commanded")
    ax[1].set_ylabel("wall force λ (N)")
    ax[1].legend(fontsize=8)
    ax[2].semilogy(traj.t, np.maximum(np.abs(lam - FORCE), 1e-17))
    ax[2].set_ylabel("|λ − λ*| (N)")
    ax[3].plot(traj.t, traj.u)
    ax[3].set_ylabel("joint torques (N·m)")
    ax[3].set_xlabel("t (s)")
    for a in ax:
        for e in traj.events:
            a.axvline(e.t, color="0.6", lw=0.8)
    ax[0].set_title("2R arm: free motion → impact → 5 N contact while sliding (one controller)")
    save(fig, args.out, "force_control.png")
    idx = np.searchsorted(traj.t, np.linspace(0.0, traj.t[-1], 7)).clip(0, traj.t.size - 1)
    fig = plot_snapshot(model, traj.q[idx], title="2R arm and wall (x = 1.5)")
    fig.axes[0].axvline(1.5, color="r")
    save(fig, args.out, "snapshots.png")


if __name__ == "__main__":
    main()
