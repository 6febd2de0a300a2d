"""The validation benchmarks: one function per problem, each returning a :class:`ValidationRecord`.

Every function runs :func:`nonmin.sim.simulate` on a library mechanism with the settings in
:data:`SETTINGS` (chosen as the cheapest that meet the targets, see ``docs/validation.md``),
compares with an independent reference and states each target explicitly. ``quick=True`` runs a
shortened version (used by the default test suite); ``quick=False`` the full benchmark.
"""

from __future__ import annotations

import math
import time
import traceback
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.integrate import solve_ivp

from ..errors import InputError
from ._records import Check, ValidationRecord
from ._references import (
    A02_N2_B0_AT_10S,
    A02_N2_VB0_AT_10S,
    a02_parallelogram_reference,
    load_a01_exact,
    load_a02_n2_exact,
    load_a03_reference,
    significant_digits,
)

__all__ = [
    "BENCHMARKS",
    "SETTINGS",
    "a01_pendulum",
    "a02_n_four_bar",
    "a03_andrews",
    "a04_bricard",
    "arm2r_wall",
    "crossed_four_bar",
    "run_all",
]

FloatArray = NDArray[np.float64]

# ------------------------------------------------------------------------------- targets
#: IFToMM benchmark accuracy rule, high precision (max position error, m).
IFTOMM_HIGH_PRECISION = 1e-3
#: A02 N = 2: |B0(10 s) − reference| (m).
A02_B0_TOL = 1e-8
#: Branch / mode tolerance (rad): largest distance from the intended assembly branch.
BRANCH_TOL = 1e-6
#: Crossed four-bar: closure (m) and energy drift (J) targets.
CFB_CLOSURE_TOL = 1e-10
CFB_ENERGY_TOL = 1e-6
#: A03: Test Set significant digits aimed at.
A03_SCD_TARGET = 8.0
#: A04: closure target (m) of the redundant loop.
A04_CLOSURE_TOL = 1e-8
#: A04: turning points against k·T/2 of the quadrature period (s), issue 18 target 5.
A04_PERIOD_TOL = 1e-10
#: 2R arm: impact time (s), impact law (rad/s), release force (N) tolerances.
IMPACT_TIME_TOL = 1e-10
IMPACT_LAW_TOL = 1e-9
RELEASE_FORCE_TOL = 1e-6

#: Simulator settings per benchmark (full, quick).
SETTINGS: dict[str, dict[str, dict[str, Any]]] = {
    "A01": {
        "full": {"method": "rk4", "dt": 2.5e-3, "stabilization": "projection"},
        "quick": {"method": "rk4", "dt": 5e-3, "stabilization": "projection"},
    },
    "A02_N2": {
        "full": {"method": "rk4", "dt": 1e-3, "stabilization": "projection"},
        "quick": {"method": "rk4", "dt": 1e-3, "stabilization": "projection"},
    },
    "A02_N40": {
        "full": {"method": "rk4", "dt": 2e-3, "stabilization": "projection"},
        "quick": {"method": "rk4", "dt": 1e-3, "stabilization": "projection"},
    },
    "A03": {
        "full": {"method": "dopri5", "rtol": 1e-12, "atol": 1e-12, "stabilization": "projection"},
        "quick": {"method": "dopri5", "rtol": 1e-9, "atol": 1e-9, "stabilization": "projection"},
    },
    "A04": {
        "full": {"method": "dopri5", "rtol": 1e-9, "atol": 1e-11, "stabilization": "projection"},
        "quick": {"method": "dopri5", "rtol": 1e-9, "atol": 1e-11, "stabilization": "projection"},
    },
    "crossed_four_bar": {
        "full": {"method": "rk4", "dt": 2.5e-4, "stabilization": "projection"},
        "quick": {"method": "rk4", "dt": 5e-4, "stabilization": "projection"},
    },
    "arm2r_wall": {
        "full": {"method": "dopri5", "rtol": 1e-12, "atol": 1e-12, "stabilization": "projection"},
        "quick": {"method": "dopri5", "rtol": 1e-10, "atol": 1e-10, "stabilization": "projection"},
    },
}

#: Horizons (s): quick versions, and full versions that differ from the benchmark's default.
QUICK_T = {"A01": 2.5, "A02_N2": 1.0, "A02_N40": 0.05, "A03": 0.03, "A04": 0.05,
           "crossed_four_bar": 0.5, "arm2r_wall": 0.4}
FULL_T = {"A02_N40": 20.0, "A04": 10.0}
FULL_T_NOTE = {
    "A02_N40": "The specified 20 s at RK4 dt = 2e-3 s (243 coordinates, 10000 steps). The "
    "compiled engine took 41.6 s on 2026-11-22 at 03:21 UTC (57.7 s at 00:12 UTC, before the "
    "projection's cutoff rule was refined; the general driver took 1180 s at 23 UTC on "
    "2026-11-21). Step choice over 1.5 s (horizontal configurations at 0.7216 s and 1.2440 s), "
    "dt = 1e-3 / 2e-3 s: both stay in the mode, closure 7.1e-15 m, B0(1.5 s) within 2.3e-9 / "
    "1.5e-8 m of the exact reduction and 1.2e-8 m of each other. Energy: an earlier build gained "
    "2.19 J over the 20 s, from a step ending 1.6e-6 s before the 19th horizontal configuration "
    "(t = 18.41200 s): near a horizontal configuration 40 singular values of the equilibrated A "
    "are 1e-7…1.5e-6 and phi along them is round-off, which the full-rank Gauss-Newton "
    "projection divided by them (a 24.5 J kick in one step). The projection's first steps now "
    "leave out singular values below 1e-2 where A has one below 1e-4 (nonmin.sim."
    "_stabilization: POSITION_CUT_RTOL, SINGULAR_CUT_RTOL; full rank only if they stall above "
    "the round-off floor; until 2026-11-26 also where the residual was round-off): that "
    "step gains 2.1e-5 J. Drift over the 20 s (E = 620.34 J): 3.0e-3 J (5.1e-3 J at 00:12 UTC "
    "with the cutoff at every first step; 3.6e-3 J in the general driver at 23 UTC). Steps "
    "ending within ~1e-7 s of a configuration can still gain energy (RK4 error of the "
    "right-hand side there; measured on N = 2).",
    "A04": "The specified 10 s. Earlier engine builds needed steps of ~2e-4 s here (stage "
    "points off the manifold made the redundant row's vanishing singular value look like a "
    "constraint); the drift-aware rank tolerance of nonmin.sim removed that: 374 DOPRI5 steps. "
    "Period: the turning points (a user event on dV/dt = −f_g·q̇ falling through zero, located "
    "by Brent's method on the method's own partial steps) against k·T/2 of the period from the "
    "energy integral (nonmin.validation.a04_bricard_period, joint-angle loop independent of the "
    "spatial model; converged to ~2e-12 s); DOP853 at rtol 1e-12 gives 1.8e-12 s.",
}


def _settings(key: str, quick: bool) -> dict[str, Any]:
    return dict(SETTINGS[key]["quick" if quick else "full"])


def _simulate(mech: Any, t_final: float, settings: Mapping[str, Any], **kw: Any) -> tuple[Any, float]:
    from ..sim import simulate

    opts = dict(settings)
    if opts.get("method") not in ("rk4", "midpoint"):
        opts.pop("dt", None)
    start = time.perf_counter()
    traj = simulate(mech, (0.0, float(t_final)), progress=False, **opts, **kw)
    return traj, time.perf_counter() - start


def _wrap(a: FloatArray) -> FloatArray:
    return (np.asarray(a) + np.pi) % (2.0 * np.pi) - np.pi


def _count_crossings(angle: FloatArray) -> int:
    """Number of times an angle passes a multiple of π (a collinear configuration)."""
    k = np.floor(np.asarray(angle) / np.pi)
    return int(np.sum(np.abs(np.diff(k))))


def _error_record(name: str, quick: bool, settings: Mapping[str, Any], exc: BaseException) -> ValidationRecord:
    tb = traceback.format_exception_only(type(exc), exc)[-1].strip()
    return ValidationRecord(name=name, checks=(), settings=settings, quick=quick, error=tb,
                            notes="The benchmark raised; see the error above.")


# ------------------------------------------------------------------------------- A01
def a01_pendulum(quick: bool = False) -> ValidationRecord:
    """IFToMM A01 simple pendulum against the exact (Jacobi elliptic) solution.

    Full: 2000 s compared at every 0.5 s (4001 points); quick: 2.5 s every 0.01 s. Target: the
    IFToMM high-precision rule (max position error ≤ 1e-3 m); P1(T) error, velocity error,
    energy drift and constraint residual reported.
    """
    from ..library import get

    horizon = QUICK_T["A01"] if quick else 2000.0
    name = f"A01 pendulum ({horizon:g} s)"
    st = _settings("A01", quick)
    try:
        ref = load_a01_exact(10.0 if quick else 2000.0)
        ref = ref[ref[:, 0] <= horizon + 1e-9]
        mech = get("A01_pendulum", t_final=horizon)
        traj, wall = _simulate(mech, horizon, st, t_eval=ref[:, 0])
        out = traj.outputs(mech.model)
        p, v = out["P1.position"], out["P1.velocity"]
        ep = np.linalg.norm(p - ref[:, 1:3], axis=1)
        ev = np.linalg.norm(v - ref[:, 3:5], axis=1)
        checks = (
            Check("max |P1 − P1_exact| over the run", float(ep.max()), IFTOMM_HIGH_PRECISION, "<=", "m"),
            Check(f"|P1({horizon:g} s) − P1_exact|", float(ep[-1]), unit="m"),
            Check("max |v1 − v1_exact|", float(ev.max()), unit="m/s"),
            Check("energy drift max |E − E0|", traj.energy_drift, unit="J"),
            Check("max |φ| (rod length residual)", float(np.max(traj.phi_norm)), unit="m"),
            Check("accepted steps", traj.n_steps),
        )
        return ValidationRecord(
            name=name, checks=checks, settings={**st, "t_final": horizon}, wall_time=wall,
            quick=quick,
            reference="exact solution (Jacobi elliptic functions), "
            f"A01_pendulum_exact_0-{10 if quick else 2000}s.csv",
        )
    except Exception as exc:
        return _error_record(name, quick, st, exc)


# ------------------------------------------------------------------------------- A02
def _a02_mode_distance(q: FloatArray, n: int) -> FloatArray:
    """Distance (rad) from the parallelogram mode: crank angles equal, couplers horizontal."""
    cranks = q[:, [3 * i + 2 for i in range(n + 1)]]
    couplers = q[:, [3 * (n + 1 + i) + 2 for i in range(n)]]
    d1 = np.max(np.abs(_wrap(cranks - cranks[:, :1])), axis=1)
    d2 = np.max(np.abs(_wrap(couplers)), axis=1)
    return np.maximum(d1, d2)


def _a02_horizontal_times(n: int, horizon: float) -> FloatArray:
    """Times in ``(0, horizon]`` of the horizontal (singular) configurations, ``sin θ = 0``.

    Located on the exact 1-DOF reduction ``I θ̈ = −g c cos θ`` (the one of
    :func:`a02_parallelogram_reference`) by DOP853 (rtol = atol = 1e-13) with an event
    function, independently of the simulated motion.
    """
    inertia = (n + 1) / 3.0 + n
    c = (n + 1) / 2.0 + n

    def rhs(_t: float, y: FloatArray) -> list[float]:
        return [y[1], -9.81 * c * math.cos(y[0]) / inertia]

    def horizontal(_t: float, y: FloatArray) -> float:
        return math.sin(y[0])

    sol = solve_ivp(rhs, (0.0, float(horizon)), [math.pi / 2.0, -1.0], method="DOP853",
                    rtol=1e-13, atol=1e-13, events=horizontal)
    if not sol.success:  # pragma: no cover - smooth ODE
        raise RuntimeError(f"A02 reference integration failed: {sol.message}")
    return np.asarray(sol.t_events[0], dtype=np.float64)


def a02_n_four_bar(n: int = 2, quick: bool = False) -> ValidationRecord:
    """IFToMM A02 N four-bar through its horizontal (singular) configurations.

    N = 2: 10 s (quick: 1 s), B0 against the exact file and, at 10 s, against the stated value
    (within 1e-8). N = 40: the specified 20 s (quick: 0.05 s). Both against the exact 1-DOF
    reduction ``I θ̈ = −g c cos θ``. The times of the horizontal configurations (``sin θ = 0``)
    are located on the reduction and added to the output samples (every 0.01 s), so the mode
    is checked at each singular configuration itself as well as at every sample: the motion
    must stay in the parallelogram mode (all cranks parallel, couplers horizontal) everywhere,
    and the simulated crank must pass as many horizontal configurations as the reduction.
    """
    from ..library import get

    key = "A02_N2" if n == 2 else "A02_N40" if n == 40 else f"A02_N{n}"
    st = _settings(key if key in SETTINGS else "A02_N40", quick)
    full_t = FULL_T.get(key, 10.0 if n == 2 else 20.0)
    horizon = QUICK_T.get(key, 1.0) if quick else full_t
    name = f"A02 N four-bar, N = {n} ({horizon:g} s)"
    try:
        mech = get("A02_n_four_bar", N=n, t_final=horizon)
        t_grid = np.round(np.arange(0.0, horizon + 1e-9, 0.01), 10)
        t_sing = _a02_horizontal_times(n, horizon)
        t_eval = np.union1d(t_grid, t_sing)
        on_grid = np.isin(t_eval, t_grid)
        at_sing = np.isin(t_eval, t_sing)
        traj, wall = _simulate(mech, horizon, st, t_eval=t_eval)
        t_out = np.asarray(traj.t)
        if t_out.shape != t_eval.shape or not np.allclose(t_out, t_eval, rtol=0.0, atol=1e-12):
            raise InputError("A02: the trajectory samples are not the requested output times")
        out = traj.outputs(mech.model)
        b0, vb0 = out["B0.position"], out["B0.velocity"]
        theta, _omega = a02_parallelogram_reference(n, t_eval)
        bref = np.stack([np.cos(theta), np.sin(theta)], axis=1)
        err = np.linalg.norm(b0 - bref, axis=1)
        q = np.asarray(traj.q)
        mode = _a02_mode_distance(q, n)
        crank = np.unwrap(q[:, 2])
        n_sim = _count_crossings(crank)
        n_ref = int(t_sing.size)
        mode_sing = float(mode[at_sing].max()) if n_ref else 0.0
        checks: list[Check] = [
            Check("stays in the parallelogram mode (max mode distance ≤ "
                  f"{BRANCH_TOL:g} rad, every sample and every horizontal configuration)",
                  bool(np.all(mode <= BRANCH_TOL)), True, "=="),
            Check("singular (horizontal) configurations passed", n_sim, n_ref, "=="),
            Check("max mode distance", float(mode.max()), unit="rad"),
            Check("max mode distance at the horizontal configurations", mode_sing, unit="rad"),
            Check("max |B0 − B0_ref| over the run", float(err.max()), IFTOMM_HIGH_PRECISION, "<=", "m"),
            Check(f"|B0({horizon:g} s) − B0_ref|", float(err[-1]), unit="m"),
        ]
        reference = ("exact 1-DOF reduction I θ̈ = −g c cos θ (DOP853, rtol = atol = 1e-13; "
                     "horizontal configurations sin θ = 0 located on it as events)")
        if n == 2:
            data = load_a02_n2_exact()
            k = len(t_grid)
            if not np.allclose(data[:k, 0], t_grid, atol=1e-9):
                raise InputError("A02 data file times do not match the output grid")
            ef = np.linalg.norm(b0[on_grid] - data[:k, 1:3], axis=1)
            checks.append(Check("max |B0 − B0_file| (A02_NfourBar_N2_exact_0-20s.csv)",
                                float(ef.max()), unit="m"))
            if not quick:
                d10 = float(np.linalg.norm(b0[on_grid][-1] - np.asarray(A02_N2_B0_AT_10S)))
                dv10 = float(np.linalg.norm(vb0[on_grid][-1] - np.asarray(A02_N2_VB0_AT_10S)))
                checks.insert(0, Check("|B0(10 s) − (0.3284581115, 0.9445185382)|", d10,
                                       A02_B0_TOL, "<=", "m"))
                checks.append(Check("|vB0(10 s) − (1.4230514702, −0.4948688455)|", dv10,
                                    unit="m/s"))
            reference += "; A02_NfourBar_N2_exact_0-20s.csv; B0(10 s) from the benchmark statement"
        checks += [
            Check("energy drift max |E − E0|", traj.energy_drift, unit="J"),
            Check("max ‖φ‖∞ (closure)", float(np.max(traj.phi_norm)), unit="m"),
            Check("min rank of A at the output samples",
                  int(np.min(traj.rank))),
            Check("accepted steps", traj.n_steps),
        ]
        return ValidationRecord(name=name, checks=tuple(checks), settings={**st, "t_final": horizon},
                                wall_time=wall, quick=quick, reference=reference,
                                notes="" if quick else FULL_T_NOTE.get(key, ""))
    except Exception as exc:
        return _error_record(name, quick, st, exc)


# ------------------------------------------------------------------------------- A03
def a03_andrews(quick: bool = False) -> ValidationRecord:
    """Andrews' squeezing mechanism: y(0.03) against the Test Set reference (PSIDE, 1e-14).

    Score: ``min_i −log10(|y_i − ref_i| / (atol/rtol + |ref_i|))`` over the 7 angles, with
    the tolerances the run used; target ≥ 8 significant digits (full run).
    """
    from ..library import get

    st = _settings("A03", quick)
    name = "A03 Andrews' squeezing mechanism (0.03 s)"
    try:
        names, ref = load_a03_reference()
        mech = get("A03_andrews")
        traj, wall = _simulate(mech, 0.03, st, t_eval=np.array([0.0, 0.03]))
        q_end = np.asarray(traj.q[-1])
        qd_end = np.asarray(traj.qd[-1])
        score, per = significant_digits(q_end[:7], ref[:7], rtol=st["rtol"], atol=st["atol"])
        vscore, _ = significant_digits(qd_end[:7], ref[7:14], rtol=st["rtol"], atol=st["atol"])
        target = 6.0 if quick else A03_SCD_TARGET
        checks = (
            Check("significant digits over the angles (Test Set score)", score, target, ">=", "digits"),
            Check("worst angle", names[int(np.argmin(per))]),
            Check("|β(0.03) − 15.81077119629904|", float(abs(q_end[0] - ref[0])), unit="rad"),
            Check("significant digits over the angular velocities", vscore, unit="digits"),
            Check("max ‖φ‖∞", float(np.max(traj.phi_norm)), unit="m"),
            Check("accepted steps", traj.n_steps),
        )
        return ValidationRecord(
            name=name, checks=checks, settings={**st, "t_final": 0.03}, wall_time=wall, quick=quick,
            reference="Test Set for IVP Solvers (Mazzia & Magherini), problem andrews, PSIDE rtol = atol = 1e-14",
        )
    except Exception as exc:
        return _error_record(name, quick, st, exc)


# ------------------------------------------------------------------------------- A04
def a04_bricard(quick: bool = False) -> ValidationRecord:
    """Bricard's mechanism (one redundant constraint) run as is: energy and closure reported."""
    from ..library import get

    st = _settings("A04", quick)
    horizon = QUICK_T["A04"] if quick else FULL_T["A04"]
    name = f"A04 Bricard ({horizon:g} s)"
    try:
        from ..sim import Event
        from ._references import a04_bricard_period

        mech = get("A04_bricard", t_final=horizon)
        model = mech.model

        def turning(_t: float, q: FloatArray, qd: FloatArray, _fc: FloatArray) -> float:
            # dV/dt = −f_g·q̇ falls through zero at every turning point (at rest, V'(s) ≠ 0)
            return -float(model.conservative_force(q) @ qd)

        t_eval = np.round(np.arange(0.0, horizon + 1e-9, 0.01), 10)
        events = [] if quick else [Event(turning, direction=-1, name="turning point")]
        traj, wall = _simulate(mech, horizon, st, t_eval=t_eval, events=events)
        n_rows = int(np.asarray(
            mech.model.constraint_terms(0.0, mech.state.q, mech.state.qd, mech.state.active).A
        ).shape[0])
        period: tuple[Check, ...] = ()
        if not quick:
            t_ref = a04_bricard_period()
            te = np.array([e.t for e in traj.events if e.name == "turning point"])
            k = np.round(te / (0.5 * t_ref))
            dev = float(np.max(np.abs(te - 0.5 * t_ref * k))) if te.size else float("inf")
            measured = abs(float(te[1]) - t_ref) if te.size >= 2 else float("inf")
            period = (
                Check("period T (quadrature of the 1-DOF energy integral)", f"{t_ref:.12f}", unit="s"),
                Check("|second turning point − T|", measured, unit="s"),
                Check(f"turning points {te.size}: max |t_k − k·T/2| ≤ {A04_PERIOD_TOL:g}", dev,
                      A04_PERIOD_TOL, "<=", "s"),
            )  # fmt: skip
        checks = (
            Check("reached t_final", bool(traj.success and abs(traj.t[-1] - horizon) < 1e-9), True, "=="),
            Check(f"max ‖φ‖∞ (closure) ≤ {A04_CLOSURE_TOL:g}", float(np.max(traj.phi_norm)),
                  A04_CLOSURE_TOL, "<=", "m"),
            Check("max ‖A qd‖∞", float(np.max(traj.velocity_residual_norm)), unit="m/s"),
            Check("energy drift max |E − E0|", traj.energy_drift, unit="J"),
            Check("constraint rows / rank of A (min, max)",
                  f"{n_rows} / {int(np.min(traj.rank))}, {int(np.max(traj.rank))}"),
            Check("accepted steps", traj.n_steps),
            *period,
        )
        return ValidationRecord(
            name=name, checks=checks, settings={**st, "t_final": horizon}, wall_time=wall, quick=quick,
            reference="IFToMM A04 (no closed form): residuals, energy conservation and the period "
            "(nonmin.validation._references.a04_bricard_period: product-of-exponentials loop in joint "
            "angles, energy integral by Gauss–Legendre)",
            notes="Run with the redundant constraint in place and no special handling. "
            + ("" if quick else FULL_T_NOTE["A04"]),
        )
    except Exception as exc:
        return _error_record(name, quick, st, exc)


# ------------------------------------------------------------------------------- crossed four-bar
def crossed_four_bar(quick: bool = False) -> ValidationRecord:
    """Crossed four-bar (change point) for 10 s: branch, closure ≤ 1e-10, energy ≤ 1e-6 J."""
    from ..library import crossed_four_bar_reference, get

    st = _settings("crossed_four_bar", quick)
    horizon = QUICK_T["crossed_four_bar"] if quick else 10.0
    name = f"crossed four-bar ({horizon:g} s)"
    try:
        mech = get("crossed_four_bar", t_final=horizon)
        t_eval = np.round(np.arange(0.0, horizon + 1e-9, 0.01), 10)
        traj, wall = _simulate(mech, horizon, st, t_eval=t_eval)
        out = traj.outputs(mech.model)
        resid = np.abs(out["anti_branch_residual"])
        ref = crossed_four_bar_reference(t_eval)
        th_err = np.abs(np.asarray(out["crank_angle"]) - _wrap(ref["theta"]))
        th_err = np.abs(_wrap(th_err))
        q_err = np.max(np.abs(np.asarray(traj.q) - ref["q"]), axis=1)
        checks = (
            Check(f"stays on the anti-parallelogram branch (residual ≤ {BRANCH_TOL:g} rad)",
                  bool(np.all(resid <= BRANCH_TOL) and traj.success), True, "=="),
            Check("max branch residual |ψ − ψ_anti(θ)|", float(resid.max()), unit="rad"),
            Check("change points passed (reference)", _count_crossings(ref["theta"])),
            Check("max ‖φ‖∞ (closure)", float(np.max(traj.phi_norm)), CFB_CLOSURE_TOL, "<=", "m"),
            Check("energy drift max |E − E0|", traj.energy_drift, CFB_ENERGY_TOL, "<=", "J"),
            Check("max |θ − θ_ref| (crank angle)", float(th_err.max()), unit="rad"),
            Check("max |q − q_ref|∞", float(q_err.max())),
            Check("accepted steps", traj.n_steps),
        )
        return ValidationRecord(
            name=name, checks=checks, settings={**st, "t_final": horizon}, wall_time=wall, quick=quick,
            reference="exact 1-DOF reduction along the branch (nonmin.library.crossed_four_bar_reference)",
        )
    except Exception as exc:
        return _error_record(name, quick, st, exc)


# ------------------------------------------------------------------------------- 2R arm and wall
def _arm_minimal(l1: float, l2: float, m1: float, m2: float, g: float) -> Callable[..., Any]:
    """Joint-space dynamics of the 2R arm with uniform bars (independent of nonmin's model)."""
    lc1, lc2 = l1 / 2, l2 / 2
    i1, i2 = m1 * l1 * l1 / 12, m2 * l2 * l2 / 12

    def terms(q: FloatArray, qd: FloatArray) -> tuple[FloatArray, FloatArray]:
        c2, s2 = math.cos(q[1]), math.sin(q[1])
        m11 = m1 * lc1**2 + i1 + m2 * (l1**2 + lc2**2 + 2 * l1 * lc2 * c2) + i2
        m12 = m2 * (lc2**2 + l1 * lc2 * c2) + i2
        m22 = m2 * lc2**2 + i2
        hh = -m2 * l1 * lc2 * s2
        cor = np.array([hh * qd[1] * (2 * qd[0] + qd[1]), -hh * qd[0] ** 2])
        c1, c12 = math.cos(q[0]), math.cos(q[0] + q[1])
        grav = np.array([(m1 * lc1 + m2 * l1) * g * c1 + m2 * lc2 * g * c12, m2 * lc2 * g * c12])
        return np.array([[m11, m12], [m12, m22]]), -(cor + grav)

    return terms


#: Tip force (N) pushing the 2R arm towards the wall: ``F(t) = F0 (1 − t / T_OFF)`` along +x.
ARM_PUSH_F0 = 20.0
ARM_PUSH_T_OFF = 1.0


def _arm_tip_jacobian(qj: FloatArray, l1: float, l2: float) -> FloatArray:
    s1, s12 = math.sin(qj[0]), math.sin(qj[0] + qj[1])
    c1, c12 = math.cos(qj[0]), math.cos(qj[0] + qj[1])
    return np.array([[-l1 * s1 - l2 * s12, -l2 * s12], [l1 * c1 + l2 * c12, l2 * c12]])


def _arm_push_torque(t: float, qj: FloatArray, l1: float, l2: float) -> FloatArray:
    """Joint torques ``Jᵀ (F(t), 0)`` of the decaying tip push."""
    f = ARM_PUSH_F0 * (1.0 - t / ARM_PUSH_T_OFF)
    return _arm_tip_jacobian(qj, l1, l2).T @ np.array([f, 0.0])


def arm2r_wall(quick: bool = False, *, restitution: float = 0.0) -> ValidationRecord:
    """2R arm thrown and pushed against a frictionless wall: impact time, impact law, release.

    The arm (library ``arm2r_wall``) starts with the tip at (1, 0) moving towards the wall
    x = 1.5, while the joint torques ``Jᵀ(F(t), 0)`` push the tip towards the wall with a force
    ``F(t) = 20 N (1 − t / 1 s)`` that decays and reverses. The impact time is compared with an
    independent joint-space model of the same arm (DOP853, rtol = atol = 1e-13, event located
    by SciPy); the post-impact joint rates with the classical impact law
    ``q̇⁺ = q̇⁻ − (1 + e) M⁻¹Jᵀ (J M⁻¹ Jᵀ)⁻¹ J q̇⁻`` in joint space; the release with the KKT
    multiplier of the wall row (an independent computation): compressive while the contact is
    on, zero at the release, and the tip leaves the wall afterwards.
    """
    from ..library import get

    st = _settings("arm2r_wall", quick)
    horizon = QUICK_T["arm2r_wall"] if quick else 1.0
    name = f"2R arm hitting a wall (e = {restitution:g}, {horizon:g} s)"
    l1 = l2 = m1 = m2 = 1.0
    g = 9.81
    wall_x = 1.5
    q_joint0 = np.array([-math.pi / 3, 2 * math.pi / 3])
    qd_joint0 = ARM_JOINT_RATES0
    try:
        mech = get("arm2r_wall", t_final=horizon)
        model: Any = mech.model
        qd0 = _arm_absolute_rates(q_joint0, qd_joint0, l1, l2)

        def push(t: float, q: FloatArray, qd: FloatArray, state: Any = None,
                 active: Any = None) -> FloatArray:
            return _arm_push_torque(t, _arm_joint_state(q, qd)[0], l1, l2)

        traj, wall = _simulate(mech, horizon, st, qd0=qd0, restitution=restitution,
                               controller=push)
        # --- reference impact time in joint space
        terms = _arm_minimal(l1, l2, m1, m2, g)

        def rhs(t: float, y: FloatArray) -> FloatArray:
            m, h = terms(y[:2], y[2:])
            return np.concatenate([y[2:], np.linalg.solve(m, h + _arm_push_torque(t, y[:2], l1, l2))])

        def gap(_t: float, y: FloatArray) -> float:
            return wall_x - (l1 * math.cos(y[0]) + l2 * math.cos(y[0] + y[1]))

        gap.terminal = True  # type: ignore[attr-defined]
        gap.direction = -1  # type: ignore[attr-defined]
        sol = solve_ivp(rhs, (0.0, horizon), np.concatenate([q_joint0, qd_joint0]),
                        method="DOP853", rtol=1e-13, atol=1e-13, events=gap)
        if not sol.t_events[0].size:
            raise InputError("arm2r_wall: the reference arm does not reach the wall")
        t_ref = float(sol.t_events[0][0])
        impacts = [e for e in traj.events if e.name.startswith("impact")]
        releases = [e for e in traj.events if e.name.startswith("release")]
        if not impacts:
            raise InputError(f"arm2r_wall: no impact event fired (events: {[e.name for e in traj.events]})")
        imp = impacts[0]
        # --- impact law in joint space from nonmin's pre-impact state
        qj, qdj = _arm_joint_state(imp.q_before, imp.qd_before)
        m, _ = terms(qj, qdj)
        jac = np.array([[l1 * math.sin(qj[0]) + l2 * math.sin(qj[0] + qj[1]),
                         l2 * math.sin(qj[0] + qj[1])]])  # ∂gap/∂q
        minv_jt = np.linalg.solve(m, jac.T)
        qd_plus = qdj - (1 + restitution) * (minv_jt @ np.linalg.solve(jac @ minv_jt, jac @ qdj))
        _, qdj_after = _arm_joint_state(imp.q_after, imp.qd_after)
        law_err = float(np.max(np.abs(qdj_after - qd_plus)))
        gap_at_impact = float(wall_x - model.point_position("tip", imp.q_before)[0])
        checks: list[Check] = [
            Check("|t_impact − t_ref|", abs(imp.t - t_ref), IMPACT_TIME_TOL, "<=", "s"),
            Check("t_impact", imp.t, unit="s"),
            Check("gap at the located impact", abs(gap_at_impact), unit="m"),
            Check("post-impact joint rates vs classical impact law", law_err, IMPACT_LAW_TOL, "<=", "rad/s"),
        ]
        # --- release: KKT multiplier of the wall row along the contact phase
        if restitution == 0.0:
            if not releases:
                checks.append(Check("contact released", False, True, "=="))
            else:
                rel = releases[0]
                lam_rel = _kkt_wall_force(model, rel.t, rel.q_before, rel.qd_before,
                                          rel.active_before, push)
                t = np.asarray(traj.t)
                in_contact = (t > imp.t) & (t < rel.t)
                act = traj.active
                lam_min = math.inf
                for i in np.nonzero(in_contact)[0]:
                    if "wall" in act[i]:
                        lam_min = min(lam_min, _kkt_wall_force(model, float(t[i]), traj.q[i],
                                                               traj.qd[i], act[i], push))
                after = t > rel.t
                gaps = np.array([wall_x - model.point_position("tip", qq)[0] for qq in traj.q[after]])
                checks += [
                    Check("contact released", True, True, "=="),
                    Check("t_release", rel.t, unit="s"),
                    Check("KKT wall force at release |λ|", abs(lam_rel), RELEASE_FORCE_TOL, "<=", "N"),
                    Check("min KKT wall force while in contact (≥ 0: compressive)",
                          lam_min if math.isfinite(lam_min) else 0.0, -RELEASE_FORCE_TOL, ">=", "N"),
                    Check("tip leaves the wall after release (min gap > 0)",
                          bool(gaps.size == 0 or np.min(gaps[1:]) > 0.0 if gaps.size > 1 else True),
                          True, "=="),
                ]
        checks.append(Check("events", ", ".join(f"{e.name}@{e.t:.6f}" for e in traj.events)))
        return ValidationRecord(
            name=name, checks=tuple(checks), settings={**st, "t_final": horizon,
                                                       "restitution": restitution},
            wall_time=wall, quick=quick,
            reference="independent joint-space model of the same arm (DOP853, 1e-13) and KKT multipliers",
        )
    except Exception as exc:
        return _error_record(name, quick, st, exc)


#: Initial joint rates (rad/s) that throw the tip of the 2R arm towards the wall.
ARM_JOINT_RATES0 = np.array([1.0, -2.5])


def _arm_absolute_rates(qj: FloatArray, qdj: FloatArray, l1: float, l2: float) -> FloatArray:
    """Absolute-coordinate velocities (x, y, θ per link, COM) from joint angles and rates."""
    a1, a2 = qj[0], qj[0] + qj[1]
    w1, w2 = qdj[0], qdj[0] + qdj[1]
    u1p = np.array([-math.sin(a1), math.cos(a1)])
    u2p = np.array([-math.sin(a2), math.cos(a2)])
    v1 = 0.5 * l1 * w1 * u1p
    v2 = l1 * w1 * u1p + 0.5 * l2 * w2 * u2p
    return np.array([v1[0], v1[1], w1, v2[0], v2[1], w2])


def _arm_joint_state(q: FloatArray, qd: FloatArray) -> tuple[FloatArray, FloatArray]:
    q = np.asarray(q)
    qd = np.asarray(qd)
    return np.array([q[2], q[5] - q[2]]), np.array([qd[2], qd[5] - qd[2]])


def _kkt_wall_force(model: Any, t: float, q: Any, qd: Any, active: frozenset[str],
                    controller: Callable[..., FloatArray]) -> float:
    """Multiplier of the wall row from the KKT system ``M q̈ − Aᵀλ = h + B u, A q̈ = −γ``."""
    q = np.asarray(q, dtype=float)
    qd = np.asarray(qd, dtype=float)
    terms = model.evaluate(t, q, qd, active)
    u = controller(t, q, qd)
    ct = terms.constraints
    a = np.asarray(ct.A)
    n, m = a.shape[1], a.shape[0]
    kkt = np.zeros((n + m, n + m))
    kkt[:n, :n] = terms.M
    kkt[:n, n:] = -a.T
    kkt[n:, :n] = a
    rhs = np.concatenate([terms.h + terms.f_passive + terms.B @ u, -np.asarray(ct.gamma)])
    sol = np.linalg.lstsq(kkt, rhs, rcond=None)[0]
    lam = sol[n:]
    row = model.row_slices(active)["wall"]
    return float(lam[row][0])


# ------------------------------------------------------------------------------- registry
BENCHMARKS: dict[str, Callable[[bool], ValidationRecord]] = {
    "A01": a01_pendulum,
    "A02_N2": lambda quick: a02_n_four_bar(2, quick),
    "A02_N40": lambda quick: a02_n_four_bar(40, quick),
    "A03": a03_andrews,
    "A04": a04_bricard,
    "crossed_four_bar": crossed_four_bar,
    "arm2r_wall": arm2r_wall,
}


def _run_one(key: str, quick: bool) -> ValidationRecord:
    return BENCHMARKS[key](quick)


def run_all(quick: bool = True, *, only: list[str] | None = None, jobs: int = 1,
            log: Callable[[str], None] | None = None) -> list[ValidationRecord]:
    """Run the validation benchmarks.

    Parameters
    ----------
    quick : bool, default True
        Shortened versions (seconds) instead of the full benchmarks (minutes to an hour).
    only : list of str, optional
        Subset of :data:`BENCHMARKS` keys.
    jobs : int, default 1
        Worker processes (benchmarks are independent; wall times are then measured under
        each other's load).
    log : callable, optional
        Called with a one-line summary after each benchmark.

    Returns
    -------
    list of ValidationRecord
        In the order of :data:`BENCHMARKS` (or ``only``).
    """
    keys = list(BENCHMARKS) if only is None else list(only)
    unknown = [k for k in keys if k not in BENCHMARKS]
    if unknown:
        from ..errors import UnknownNameError

        raise UnknownNameError(f"only: unknown benchmark(s) {unknown}; known: {list(BENCHMARKS)}")
    if int(jobs) < 1:
        raise InputError(f"jobs must be a positive integer, got {jobs!r}")

    def report(rec: ValidationRecord) -> None:
        if log is not None:
            log(f"{rec.name}: {'pass' if rec.passed else 'FAIL'} ({rec.wall_time:.1f} s)")

    if int(jobs) == 1 or len(keys) < 2:
        records = []
        for k in keys:
            rec = _run_one(k, quick)
            report(rec)
            records.append(rec)
        return records
    from concurrent.futures import ProcessPoolExecutor, as_completed

    done: dict[str, ValidationRecord] = {}
    with ProcessPoolExecutor(max_workers=int(jobs)) as pool:
        futures = {pool.submit(_run_one, k, quick): k for k in keys}
        for fut in as_completed(futures):
            rec = fut.result()
            done[futures[fut]] = rec
            report(rec)
    return [done[k] for k in keys]
