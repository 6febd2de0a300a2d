"""A projected semi-implicit (symplectic) Euler in dependent coordinates (issue 18, target 4).

The scheme class that Pinocchio's and MuJoCo's users run — one dynamics evaluation per step —
done the nonmin way, as a probe: does it beat Pinocchio's semi-implicit Euler at dt 5e-2 on
A02 N = 2 at equal or better error? (It does not; numbers in benchmarks/README.md, "A02 N = 2
against Pinocchio's dt 5e-2".) Two projections of the same kick–drift step

    q̈_k = F(q_k, q̇_k)                 (the projection dynamics, eq. (ddq_sim) corrected)
    q̇* = q̇_k + h q̈_k,   q* = q_k + h q̇*

are compared:

``naive``  the run's usual projection of (q*, q̇*): Gauss–Newton on φ = 0 in the mass metric
           (corrections along M⁻¹A(q)ᵀ at the iterates, i.e. at the new position), then q̇* onto
           N(A(q_{k+1})). This is what a custom ``Integrator`` gets from ``simulate`` and what
           diverged when it was first tried: for a point on a circle of radius L at angular
           rate ω (a bar turning about a pin), the new normal direction makes the angle step
           tan Δθ = hω/(1 − h²ω²) and the projected speed grows by (1 + h²ω²/2) per step,
           exponentially at the rate hω³/2 — energy is pumped in at every step, more the
           faster the bar turns (A02 N = 2, dt 1e-2: 35.8 J → 16 000 J in 10 s).
``shake``  the position corrected along the *old* normals, M⁻¹A(q_k)ᵀ (SHAKE: chord steps
           on the factorization of A(q_k)), and the velocity from the chord,
           q̇_{k+1} = P_M(q_{k+1}) (q_{k+1} − q_k)/h (RATTLE's velocity step: the mass-metric
           projection onto N(A(q_{k+1}))). The constraint part of h q̈_k lies in R(M⁻¹A(q_k)ᵀ)
           and is absorbed by the correction, so with constant M and velocity-independent
           applied forces the q sequence is that of SHAKE (Störmer–Verlet on the manifold:
           positions of order 2, the velocity a half-step one: energy error O(h), bounded, not
           drifting). Same circle: tan Δθ = hω/√(1 − h²ω²), the speed is kept exactly. Where the
           chord steps do not contract by 0.1 per step (next to a singular configuration, or
           very coarse steps) the step falls back to the Gauss–Newton projection from the last
           iterate (counted).

The steps run in the general (Python) driver through a custom ``Integrator``: this script
measures accuracy, not time (one SHAKE step costs one factorization — the velocity projection
at q_{k+1}, which the next F reuses — plus chord solves on the held one: about a quarter of an
RK4 step).

    python benchmarks/coarse_se.py [--mechanisms A02_N2,crossed_four_bar] [--dts 0.05,0.02,0.01]
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

import sim_bench as sb

from nonmin.sim import Projection, simulate
from nonmin.sim._integrators import Integrator, StepperState, StepResult, _fixed_step
from nonmin.sim._stabilization import ROUNDOFF_FLOOR, _correction

CHORD_RATE = 0.1  # each chord step must cut ‖φ‖∞ by this (as the projection's chord steps)
STATS: dict[str, int] = {"shake": 0, "fallback": 0, "chord_steps": 0}


def se_step(system: Any, t: float, y: np.ndarray, f: np.ndarray | None, h: float, variant: str) -> np.ndarray:
    """One kick–drift step from (t, y) (``system``: the general driver's ``_System``); the
    ``shake`` variant returns the projected state, ``naive`` the raw one (the driver projects)."""
    n = system.n
    model, act = system.model, system.active
    q, v = y[:n], y[n:]
    a = (system.rhs(t, y) if f is None else f)[n:]
    vs = v + h * a
    qs = q + h * vs
    stab = system.stab
    if variant == "naive" or not isinstance(stab, Projection) or not act:
        return np.concatenate((qs, vs))
    t1 = t + h
    M = model.mass_matrix(q)
    ct0 = model.constraint_terms(t, q, v, act)
    hol = ct0.holonomic
    A_k = ct0.A[hol]
    qi = qs.copy()
    ok = True
    prev = np.inf
    for _ in range(30):
        ct = model.constraint_terms(t1, qi, vs, act)
        phi = ct.phi[hol]
        err = float(np.max(np.abs(phi))) if phi.size else 0.0
        floor = ROUNDOFF_FLOOR * (1.0 + np.abs(ct.A[hol]) @ np.abs(qi))
        if err == 0.0 or bool(np.all(np.abs(phi) <= floor)):
            break
        if err > CHORD_RATE * prev:
            ok = False
            break
        prev = err
        qi = qi + _correction(M, A_k, phi, system.rank_rtol)  # along M⁻¹A(q_k)ᵀ
        STATS["chord_steps"] += 1
    else:
        ok = False
    STATS["shake" if ok else "fallback"] += 1
    if not ok:
        qi, _ = stab.project(model, t1, qi, vs, act, system.rank_rtol)
    return np.concatenate((qi, (qi - q) / h))  # the driver then projects q̇ onto N(A(q_{k+1}))


@dataclass(frozen=True)
class SymplecticEulerProbe(Integrator):
    """The probe as a custom integrator (general driver only)."""

    dt: float | None = None
    variant: str = "shake"
    passages: bool = True

    name: ClassVar[str] = "symplectic_euler_probe"
    order: ClassVar[int] = 1
    adaptive: ClassVar[bool] = False
    passage_fractions: ClassVar[tuple[float, ...]] = (0.5,)  # F only at step ends

    def advance(self, fun: Any, t: float, y: np.ndarray, f: np.ndarray | None, h: float) -> np.ndarray:
        return se_step(fun.__self__, t, y, f, h, self.variant)

    def step(self, fun: Any, state: StepperState, t_bound: float, project: Any = None,
             place: Any = None) -> StepResult:  # fmt: skip
        return _fixed_step(self, fun, state, t_bound, None, place)  # (no projected RK4 stages)


def run(mech_name: str, dt: float, variant: str) -> dict[str, Any]:
    bar = sb.a02_mechanism(2) if mech_name == "A02_N2" else sb.crossed_four_bar_mechanism(
        sb.library_four_bar_params())
    mech = sb.nonmin_mechanism(bar)
    for k in STATS:
        STATS[k] = 0
    tr = simulate(mech, (0.0, bar.t_final), method=SymplecticEulerProbe(dt=dt, variant=variant),
                  engine="python", throw=False, progress=False)  # fmt: skip
    com = sb._nonmin_to_com(bar, mech.model, np.asarray(tr.q), np.asarray(tr.qd))
    row = sb.summarize(bar, sb.RunResult("nonmin", variant, bar.name, dt, np.asarray(tr.t), com,
                                         [], "ok" if tr.success else "failed"), sb.reference_for(bar))
    return {"mechanism": mech_name, "dt": dt, "variant": variant, "steps": tr.n_steps, **dict(STATS),
            **{k: row.get(k) for k in ("on_branch", "closure_max", "energy_drift", "error_vs_reference_max")}}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mechanisms", default="A02_N2,crossed_four_bar")
    ap.add_argument("--dts", default="0.05,0.02,0.01,0.005")
    ap.add_argument("--variants", default="naive,shake")
    args = ap.parse_args()
    print("| mechanism | variant | dt | on branch | err [m] | dE [J] | closure [m] | steps | SHAKE / fallback steps |")
    print("|---|---|---|---|---|---|---|---|---|")
    for m in args.mechanisms.split(","):
        for variant in args.variants.split(","):
            for dt in (float(x) for x in args.dts.split(",")):
                r = run(m, dt, variant)
                print(f"| {m} | {variant} | {dt:g} | {'yes' if r['on_branch'] else 'no'} | "
                      f"{r['error_vs_reference_max']:.2g} | {r['energy_drift']:.2g} | {r['closure_max']:.1e} | "
                      f"{r['steps']} | {r['shake']} / {r['fallback']} |", flush=True)  # fmt: skip


if __name__ == "__main__":
    main()
