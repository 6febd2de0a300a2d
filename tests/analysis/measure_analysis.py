"""Print the residuals quoted in docs/theory.md and docs/contact.md for reactions, drivers and
inverse dynamics (``python tests/analysis/measure_analysis.py``; ~20 s)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "model"))

from closed_chains import admissible_velocity, five_bar, three_rrr
from scipy.linalg import null_space
from test_reactions import _fourbar, _newton_euler

import nonmin


def inverse() -> None:
    worst_kkt = worst_ns = worst_u0 = 0.0
    for build in (five_bar, three_rrr, lambda: three_rrr(redundant=True)):
        model, st = build()
        rng = np.random.default_rng(0)
        for _ in range(20):
            qd = admissible_velocity(model, st.q, rng)
            mt = model.evaluate(0.0, st.q, qd)
            M, g, A, B = mt.M, mt.h + mt.f_passive, mt.constraints.A, mt.B
            u0 = rng.normal(size=model.k)
            qdd = model.forward_dynamics(st.q, qd, f=B @ u0).qdd
            res = nonmin.inverse_dynamics(model, st.q, qd, qdd)
            Z = null_space(A)
            u_ns = np.linalg.pinv(Z.T @ B) @ (Z.T @ (M @ qdd - g))
            worst_ns = max(worst_ns, np.abs(res.u - u_ns).max() / max(1.0, np.abs(u_ns).max()))
            if res.redundancy == 0:
                sol = np.linalg.lstsq(np.hstack([A.T, B]), M @ qdd - g, rcond=None)[0]
                worst_kkt = max(
                    worst_kkt, np.abs(res.u - sol[A.shape[0] :]).max() / max(1.0, np.abs(u0).max())
                )
                worst_u0 = max(worst_u0, np.abs(res.u - u0).max() / max(1.0, np.abs(u0).max()))
    print(
        f"inverse dynamics: u vs KKT {worst_kkt:.1e}, vs the input {worst_u0:.1e}, vs null-space min-norm {worst_ns:.1e}"
    )


def fourbar() -> None:
    model, state, Ls, ms = _fourbar()
    q = state.q
    z = np.linalg.svd(model.constraint_jacobian(0.0, q))[2][-1]
    worst = 0.0
    for w in np.linspace(-5, 5, 11):
        qd = w * z
        sol = model.forward_dynamics(q, qd, f=model.input_matrix(q) @ [0.7])
        _, F = _newton_euler(model, q, qd, 0.7, Ls, ms)
        rs = nonmin.reactions(model, q, sol.f_c)
        for pin, body in (("A", "crank"), ("B", "coupler"), ("C", "rocker")):
            th = q[3 * ["crank", "coupler", "rocker"].index(body) + 2]
            Rt = np.array([[np.cos(th), np.sin(th)], [-np.sin(th), np.cos(th)]])
            worst = max(worst, np.abs(rs[pin].force_b - Rt @ F[pin]).max() / np.abs(F[pin]).max())
    print(f"four-bar pin forces vs Newton-Euler: {worst:.1e} (relative)")


def pinocchio() -> None:
    try:
        import pinocchio as pin
    except ImportError:
        print("pinocchio not installed")
        return
    from nonmin.core import solve_dynamics
    from nonmin.model.robots._examples import two_arm_grasp

    robot, state = two_arm_grasp()
    q = state.q
    worst = 0.0
    rng = np.random.default_rng(8)
    for _ in range(10):
        A = robot.constraint_jacobian(0.0, q)
        _, s, Vt = np.linalg.svd(A)
        r = int(np.sum(s > 1e-10 * s[0]))
        qd = Vt[r:].T @ rng.normal(size=robot.n - r)
        tau = np.concatenate([np.zeros(6), rng.normal(size=robot.nv - 6)])
        mt = robot.evaluate(0.0, q, qd)
        T = robot.velocity_map(q)
        sol = solve_dynamics(mt.M, mt.h, mt.constraints.A, mt.constraints.gamma, T.T @ tau)
        rs = nonmin.reactions(robot, q, sol.f_c)
        pm = robot.pinocchio_model
        data = pm.createData()
        models = pin.StdVec_RigidConstraintModel()
        datas = pin.StdVec_RigidConstraintData()
        for name, ct in (
            ("grasp_left", pin.ContactType.CONTACT_6D),
            ("grasp_right", pin.ContactType.CONTACT_3D),
        ):
            fa = pm.frames[robot.frame_id(f"{name}:a")]
            fb = pm.frames[robot.frame_id(f"{name}:b")]
            cm = pin.RigidConstraintModel(
                ct,
                pm,
                fa.parentJoint,
                fa.placement,
                fb.parentJoint,
                fb.placement,
                pin.ReferenceFrame.LOCAL,
            )
            models.append(cm)
            datas.append(cm.createData())
        pin.initConstraintDynamics(pm, data, models, datas)
        pin.constraintDynamics(
            pm,
            data,
            robot.pinocchio_configuration(q),
            robot.to_pinocchio_velocity(q, qd),
            tau,
            models,
            datas,
            pin.ProximalSettings(1e-12, 0.0, 1),
        )
        lam = np.array(data.lambda_c)
        ours = np.concatenate(
            [rs["grasp_left"].force_a, rs["grasp_left"].torque_a, rs["grasp_right"].force_a]
        )
        worst = max(worst, np.abs(ours - lam).max() / np.abs(lam).max())
    print(f"two-arm grasp closures vs Pinocchio lambda_c (LOCAL): {worst:.1e} (relative)")


if __name__ == "__main__":
    inverse()
    fourbar()
    pinocchio()
