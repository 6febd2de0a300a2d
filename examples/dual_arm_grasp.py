"""Dual-arm grasp: approach, grasp (topology switch), then regulate the closed chain.

Two 2R arms and a bar object held by a fixture (a weld to the ground). Phase 1 (pins +
fixture active, 4 DOF, 4 motors): a Regulator brings both tips to the object's ends. An event
fires when both tips are within 0.1 mm; its Reset transition deactivates the fixture,
activates the two grasp pins (a closed chain: 3 DOF, 4 motors — redundant actuation, where
Γ = (BᵀPB)⁻¹BᵀP does not exist but Γ = (PB)⁺ does, ERRATA 4), projects the configuration
onto the new constraints (mass metric) and applies the impact map. Phase 2: a Regulator
whose target is assembled around a desired object pose (``fixed`` object coordinates) carries
the object there. A ``Switched`` controller picks the regulator by the active set.

Run: python examples/dual_arm_grasp.py [--out DIR] [--quick]
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _example_common import figure, parse, save
from control_scenes import dual_arm_grasp_configuration, dual_arm_with_fixture

from nonmin.control import Regulator, Switched, project_configuration
from nonmin.core import impact_map
from nonmin.sim import Event, Reset, simulate
from nonmin.viz import plot_snapshot

POSE = np.array([0.2, 1.0, 0.3])  # desired object (x, y, θ)


def main(argv: list[str] | None = None) -> None:
    args = parse("dual_arm_grasp", __doc__, argv)
    model, q0 = dual_arm_with_fixture()
    pins = frozenset({"L_shoulder", "L_elbow", "R_shoulder", "R_elbow"})
    pre, post = pins | {"fixture"}, pins | {"grasp_L", "grasp_R"}
    q_grasp = dual_arm_grasp_configuration(model)
    goal = q_grasp.copy()
    goal[12:15] = POSE
    approach = Regulator(model, target=q_grasp, Kp=200.0, Kd=28.0)
    carry = Regulator(model, target=goal, Kp=200.0, Kd=28.0, fixed=[12, 13, 14])
    ctl = Switched(model, {pre: approach, post: carry})

    def tip_distance(t, q, qd, f_c):
        out = model.outputs(t, q, qd)
        half = 0.3 * np.array([math.cos(q[14]), math.sin(q[14])])
        return max(np.linalg.norm(out["L_tip.position"] - (q[12:14] - half)),
                   np.linalg.norm(out["R_tip.position"] - (q[12:14] + half))) - 1e-4

    def grasp(t, q, qd, active):
        act = (frozenset(active) - {"fixture"}) | {"grasp_L", "grasp_R"}
        qn = project_configuration(model, q, active=act, metric="mass")
        qdn = impact_map(model.mass_matrix(qn), model.constraint_jacobian(t, qn, act), qd)
        return qn, qdn, act

    t1, dt = (0.1, 1e-2) if args.quick else (4.0, 5e-3)
    traj = simulate(model, (0.0, t1), q0, active=pre, method="rk4", dt=dt, controller=ctl,
                    events=[Event(tip_distance, direction=-1, transition=Reset(grasp), name="grasp")])
    for e in traj.events:
        print(f"event {e.name!r} at t = {e.t:.4f} s")
    err = np.abs(traj.q[:, 12:15] - POSE).max(axis=1)
    print(f"final object pose {traj.q[-1, 12:15]}, max error {err[-1]:.3e}; "
          f"max ‖φ‖ = {traj.phi_norm.max():.2e}; σ(PB) after the grasp: "
          f"{np.array2string(carry.info(0.0, carry.target_for(post), np.zeros(15), active=post).sigma_pb, precision=3)}")
    dist = np.array([tip_distance(t, q, qd, None) + 1e-4 for t, q, qd in zip(traj.t, traj.q, traj.qd)])
    fig, ax = figure(3, size=(7, 8))
    ax[0].semilogy(traj.t, np.maximum(dist, 1e-16))
    ax[0].set_ylabel("tip–object distance (m)")
    ax[1].semilogy(traj.t, np.maximum(err, 1e-16))
    ax[1].set_ylabel("object pose error")
    ax[2].plot(traj.t, traj.u)
    ax[2].set_ylabel("joint torques (N·m)")
    ax[2].set_xlabel("t (s)")
    for a in ax:
        for e in traj.events:
            a.axvline(e.t, color="0.6", lw=0.8)
    ax[0].set_title("Dual-arm grasp: approach → grasp (event) → closed-chain regulation")
    save(fig, args.out, "grasp.png")
    tg = traj.events[0].t if traj.events else traj.t[-1]
    idx = np.searchsorted(traj.t, [0.0, 0.5 * tg, tg, tg + 0.5 * (traj.t[-1] - tg), traj.t[-1]])
    save(plot_snapshot(model, traj.q[idx.clip(0, traj.t.size - 1)], title="dual-arm grasp"),
         args.out, "snapshots.png")


if __name__ == "__main__":
    main()
