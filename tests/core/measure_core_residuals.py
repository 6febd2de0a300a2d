"""Measure the residuals quoted in docs/theory.md (not a test; run it directly).

    python tests/core/measure_core_residuals.py [--samples N]

Draws N seeded random systems per kind (the same generators as the property tests) and prints
the worst residual of every identity / cross-check, then the skewness numbers of the three
mechanisms of test_core_skew.py.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from core_testlib import (
    KINDS,
    basis_of_nullspace,
    classical_impact,
    kkt_solve,
    random_A,
    random_spd,
    rel,
    singular_mass_pd_on_nullspace,
    udwadia_kalaba,
)

from nonmin.core import (
    actuation_projectors,
    constraint_force,
    constraint_force_projector,
    constraint_inertia,
    coriolis_bar,
    forward_dynamics,
    impact_map,
    lambda_matrix,
    nullspace_projector,
    optimal_virtual_mass,
    position_correction,
    projector_derivative,
    solve_dynamics,
)


def _systems(samples: int):
    for kind in KINDS:
        for i in range(samples):
            rng = np.random.default_rng([i, KINDS.index(kind)])
            n = int(rng.integers(2, 8))
            m = int(rng.integers(0, 10))
            A, r = random_A(rng, kind, n, m)
            singular = bool(i % 2) and r >= 1
            M = singular_mass_pd_on_nullspace(rng, A, r) if singular else (
                random_spd(rng, n) * 10.0 ** rng.uniform(-3, 3))
            yield kind, singular, M, A, r, rng


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--samples", type=int, default=200)
    args = ap.parse_args()
    worst: dict[str, float] = {}

    def rec(key: str, val: float) -> None:
        worst[key] = max(worst.get(key, 0.0), float(val))

    mu_outside = 0
    for kind, singular, M, A, r, rng in _systems(args.samples):
        n, m = A.shape[1], A.shape[0]
        P, rank = nullspace_projector(A)
        assert int(rank) == r, (kind, int(rank), r)
        Q = np.eye(n) - P
        rec("P: |P²−P|max", np.abs(P @ P - P).max())
        rec("P: |P−Pᵀ|max", np.abs(P - P.T).max())
        if m:
            rec("P: |AP|max/|A|max", np.abs(A @ P).max() / max(np.abs(A).max(), 1e-300))
        mu = float(optimal_virtual_mass(M, P))
        S = constraint_force_projector(M, P, mu)
        s2 = max(np.linalg.norm(S), 1.0) ** 2
        rec("S: |S²−S|max/‖S‖²", np.abs(S @ S - S).max() / s2)
        rec("S: |QS−S|max/‖S‖²", np.abs(Q @ S - S).max() / s2)
        rec("S: |SQ−Q|max/‖S‖²", np.abs(S @ Q - Q).max() / s2)
        rec("S: |PS|max/‖S‖²", np.abs(P @ S).max() / s2)
        rec("S: |MSᵀ−SM|max/(|M|‖S‖)",
            np.abs(M @ S.T - S @ M).max() / (max(np.abs(M).max(), 1e-300) * np.sqrt(s2)))
        Z = basis_of_nullspace(A, r)
        Mbar = constraint_inertia(M, P, mu)
        if n - r:
            pinv_pmp = Z @ np.linalg.solve(Z.T @ M @ Z, Z.T)
            red = np.linalg.eigvalsh(Z.T @ M @ Z)
            if not (red.min() * (1 - 1e-12) <= mu <= red.max() * (1 + 1e-12)):
                mu_outside += 1
        else:
            pinv_pmp = np.zeros((n, n))
            red = np.zeros(0)
        Minv = np.linalg.inv(Mbar)
        rec("M̄⁻¹P vs (PMP)⁺ (rel max-norm)",
            np.abs(Minv @ P - pinv_pmp).max() / max(np.abs(pinv_pmp).max(), 1 / mu))
        ev = np.sort(np.linalg.eigvalsh(Mbar))
        exp = np.sort(np.concatenate([np.full(r, mu), red]))
        rec("eig(M̄) vs {μ}∪eig≠0(PMP) (rel λmax)", np.abs(ev - exp).max() / ev.max())
        # μ-independence, KKT / UK
        ms = np.abs(M).max() or 1.0
        h = rng.standard_normal(n) * ms
        f = rng.standard_normal(n) * ms
        gam = A @ rng.standard_normal(n)
        qdd = forward_dynamics(M, h, A, gam, f)
        s = np.linalg.norm(qdd) + np.linalg.norm(h) / ms
        for fac in (1e-3, 1e3):
            rec("qdd(μ·1e±3) vs qdd(μ*) (rel)", rel(forward_dynamics(M, h, A, gam, f,
                                                                     mu=fac * mu), qdd, s))
        if m:
            rec("|A qdd + γ|/(‖A‖ s)",
                np.linalg.norm(A @ qdd + gam) / max(np.linalg.norm(A) * s, 1e-300))
        if kind in ("full", "empty"):
            gam_k = rng.standard_normal(m)
            qdd = forward_dynamics(M, h, A, gam_k, f)
            qk, lam = kkt_solve(M, A, h + f, gam_k)
            rec("qdd vs KKT (rel) [regular]", rel(qdd, qk))
            rec("f_c vs Aᵀλ (rel to ‖f+h‖) [regular]",
                rel(constraint_force(M, h, A, gam_k, f), A.T @ lam, np.linalg.norm(h + f)))
        elif not singular:
            rec("qdd vs Udwadia–Kalaba (rel) [singular/redundant]",
                rel(qdd, udwadia_kalaba(M, A, h + f, gam)))
        # impact and correction
        v = rng.standard_normal(n)
        vp = impact_map(M, A, v)
        ref = Z @ np.linalg.solve(Z.T @ M @ Z, Z.T @ M @ v) if n - r else np.zeros(n)
        rec("impact vs mass-metric projection (rel ‖v‖)", rel(vp, ref, np.linalg.norm(v)))
        if not singular:
            ec = rel(vp, classical_impact(M, A, v), np.linalg.norm(v))
            rec("impact vs classical (I−M⁻¹Aᵀ(AM⁻¹Aᵀ)⁺A)v (rel)", ec)
            if m:
                G = A @ np.linalg.solve(M, A.T)
                eg = np.linalg.eigvalsh(G)
                nz = eg[eg > 1e-10 * eg.max()] if eg.max() > 0 else np.ones(1)
                rec("  same / (eps·cond≠0(AM⁻¹Aᵀ))", ec / (np.finfo(float).eps * nz.max() / nz.min()))
        d = v - vp
        T = 0.5 * v @ M @ v
        rec("Carnot |ΔT − ½dᵀMd|/T", abs(T - 0.5 * vp @ M @ vp - 0.5 * d @ M @ d) / max(T, 1e-300))
        if m:
            ve = impact_map(M, A, v, restitution=0.5)
            rec("restitution |A v⁺ + e A v⁻|/(‖A‖‖v‖)",
                np.linalg.norm(A @ ve + 0.5 * A @ v)
                / max(np.linalg.norm(A) * np.linalg.norm(v), 1e-300))
        phi = A @ rng.standard_normal(n)
        dq = position_correction(M, A, phi)
        x0 = -np.linalg.lstsq(A, phi, rcond=None)[0] if m else np.zeros(n)
        refq = x0 - Z @ np.linalg.solve(Z.T @ M @ Z, Z.T @ M @ x0) if n - r else x0
        rec("position_correction vs min ½ΔqᵀMΔq (rel)",
            rel(dq, refq, max(np.linalg.norm(x0), 1e-300)))
        # actuation
        B = rng.standard_normal((n, n - r + 1))
        R, _ = actuation_projectors(B, P)
        sR = max(np.linalg.norm(R), 1.0)
        rec("R: |R²−R|, |RP−R|, |PR−P| (max, /‖R‖²)",
            max(np.abs(R @ R - R).max(), np.abs(R @ P - R).max(), np.abs(P @ R - P).max()) / sR**2)

    # errata: printed vs corrected (ddq_sim) and (fc_fp), 200 coupled examples
    from test_core_errata import _example, _qdd

    for seed in range(args.samples):
        ex = _example(seed)
        gam = ex["Adot"] @ ex["qd"]
        g = np.linalg.norm(gam)
        rec("ERRATA1 printed  |A qdd + Ȧqd|/|Ȧqd|", -np.inf)
        worst["ERRATA1 printed  |A qdd + Ȧqd|/|Ȧqd| (min)"] = min(
            worst.get("ERRATA1 printed  |A qdd + Ȧqd|/|Ȧqd| (min)", np.inf),
            np.linalg.norm(ex["A"] @ _qdd(ex, -1.0) + gam) / g)
        rec("ERRATA1 nonmin   |A qdd + Ȧqd|/|Ȧqd|",
            np.linalg.norm(ex["A"] @ forward_dynamics(ex["M"], ex["h"], ex["A"], gam, ex["f"])
                           + gam) / g)
        _, lam = kkt_solve(ex["M"], ex["A"], ex["h"] + ex["f"], gam)
        refc = ex["Q"] @ ex["f"] + ex["A"].T @ lam
        base = -ex["S"] @ (ex["P"] @ ex["f"] + ex["h"])
        pr = base + ex["Q"] @ ex["M"] @ ex["Om"] @ ex["qd"]
        co = base + ex["S"] @ ex["M"] @ ex["Om"] @ ex["qd"]
        worst["ERRATA2 printed (fc_fp) vs KKT (rel, min)"] = min(
            worst.get("ERRATA2 printed (fc_fp) vs KKT (rel, min)", np.inf), rel(pr, refc))
        rec("ERRATA2 corrected (fc_fp) vs KKT (rel)", rel(co, refc))
    worst.pop("ERRATA1 printed  |A qdd + Ȧqd|/|Ȧqd|", None)

    print(f"samples per kind: {args.samples}; kinds: {', '.join(KINDS)}; "
          "M SPD and (odd samples) singular off N(A)")
    print(f"optimal μ outside [λmin≠0(PMP), λmax(PMP)]: {mu_outside} cases")
    for k, v in worst.items():
        print(f"  {k:55s} {v:.2e}")

    # skewness along trajectories
    import test_core_skew as T

    print("skewness along solve_ivp trajectories (4 samples each):")
    for mech in T.MECHANISMS:
        sol = T._trajectory(mech)
        n = mech.q0.size
        P0, _ = nullspace_projector(mech.jac(mech.q0))
        mu = 2.5 * float(optimal_virtual_mass(mech.mass(mech.q0).real, P0))
        sk, fd, cp, ska = [], [], [], []
        for t in T.T_SAMPLES:
            y = sol.sol(t)
            q, qd = y[:n], y[n:]
            Mb = {k: T._mbar_at(mech, sol.sol(t + k * T.DELTA)[:n], mu) for k in (-2, -1, 1, 2)}
            Md = (Mb[-2] - 8 * Mb[-1] + 8 * Mb[1] - Mb[2]) / (12 * T.DELTA)
            M = mech.mass(q).real
            C = T.christoffel(mech, q, qd)
            A, Ad = mech.jac(q), mech.jac_dot(q, qd)
            P, _ = nullspace_projector(A)
            Pd = projector_derivative(A, Ad)
            Mdot = np.einsum("kij,k->ij", T.mass_derivatives(mech, q), qd)
            an = Pd @ M @ P + P @ Mdot @ P + P @ M @ Pd - mu * Pd
            sk.append(T._sym_ratio(Md - 2 * coriolis_bar(M, C, A, Ad, mu)))
            ska.append(T._sym_ratio(an - 2 * coriolis_bar(M, C, A, Ad, mu)))
            fd.append(np.linalg.norm(Md - an) / np.linalg.norm(an))
            Lam = lambda_matrix(A, Ad)
            Om = Lam - Lam.T
            cp.append(T._sym_ratio(Md - 2 * (P @ C + (P @ M - mu * np.eye(n)) @ Om)))
        print(f"  {mech.name:24s} ‖sym(dM̄/dt−2C̄)‖/‖·‖ max {max(sk):.1e}; "
              f"same with analytic dM̄/dt {max(ska):.1e}; "
              f"FD vs ṖMP+PṀP+PMṖ−μṖ max {max(fd):.1e}; "
              f"C̄' (not skew) min {min(cp):.2f}; |A qd| at end {np.linalg.norm(A @ qd):.1e}")

    try:
        import pinocchio as pin
    except ImportError:
        print("pinocchio not installed: mapping check skipped")
        return
    import test_core_pinocchio as TP

    eq, ef = 0.0, 0.0
    for seed in range(20):
        model, data, q, v, tau = TP._state(seed)
        fid = model.nframes - 1
        J = TP._jac(model, data, q, fid)
        pin.forwardKinematics(model, data, q, v, np.zeros(model.nv))
        gamma = np.array(
            pin.getFrameClassicalAcceleration(model, data, fid, pin.LOCAL_WORLD_ALIGNED).linear)
        pin.computeAllTerms(model, data, q, v)
        M = np.triu(data.M) + np.triu(data.M, 1).T
        a = pin.forwardDynamics(model, data, q, v, tau, J, gamma).copy()
        sol = solve_dynamics(M, -data.nle, J, gamma, tau)
        eq = max(eq, rel(sol.qdd, a))
        ef = max(ef, rel(sol.f_c, J.T @ data.lambda_c))
    print(f"Pinocchio {pin.__version__} forwardDynamics, sample manipulator, 20 states: "
          f"qdd rel {eq:.1e}, f_c vs Jᵀλ_c rel {ef:.1e}")


if __name__ == "__main__":
    main()
