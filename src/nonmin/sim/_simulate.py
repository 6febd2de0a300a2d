"""The hybrid simulation driver :func:`simulate`.

One accepted step of the driver:

1. the integrator advances ``y = (q, qd)`` with the active set (and controller state) frozen;
   the right-hand side is ``qdd`` of the drift-tolerant projection dynamics (corrected eq.
   (ddq_sim)) from :func:`nonmin.core.solve_dynamics`' kernel, one factorization per call;
2. the stabilization projects the new state (mass metric by default);
3. every guard (user events, and automatic contact guards) is compared with its value at the
   step start; for the earliest crossing the step is re-integrated from its start to the
   located time (Brent's method on the partial step size, |Δt| ≤ 1e-13 s), so the located state
   is exactly what the integrator produces there;
4. the transition is applied (activation with the impact map, deactivation, or a reset) and the
   integration restarts from the event.

Unilateral contact (constraint kind ``"unilateral"``, ``contact=True``): while inactive the
guard is the gap, crossing downward → impact with Newton's restitution; if the bounce is too
small to resolve (separation speed ≤ ``impact_velocity_threshold`` or predicted flight time
≤ ``2·dt``) the impact is plastic and the contact becomes persistent (Zeno accumulation point
handled by truncation). While active the guard is the normal force ``λ = (A⁺)ᵀ f_c`` restricted
to the contact row (compressive ≥ 0, no multipliers in the dynamics); it is released when λ
crosses zero *and* the released gap acceleration is separating (no chattering).

Default stabilization, chosen by measurement (library models, RK4, dt = 1e-3 s, 10 s;
max |q − q_ref| against the exact 1-DOF references, energy drift max|E − E0|):

=================  ===============================  ===============================
stabilization      crossed four-bar                 A02 N four-bar (N = 2)
=================  ===============================  ===============================
projection (mass)  8.0e-6, 2.2e-5 J, on branch      6.4e-11, 6.9e-10 J
projection (eucl)  1.7e-2, 2.5e-2 J                 1.2e-7, 4.5e-8 J
baumgarte (10,10)  blows up at t = 1.985 s          4.0e-8, 1.7e-8 J
none               leaves the branch (53, 34 J)     blows up at t = 3.17 s
=================  ===============================  ===============================

With dt = 5e-4 s the crossed four-bar gives 9.0e-7 and 2.4e-6 J. ``‖φ‖∞ ≤ 2.2e-15``
throughout with the projection.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from functools import cached_property, lru_cache, partial
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._validation import as_float_array
from ..core import forward_dynamics, solve_dynamics
from ..core.linalg import DEFAULT_RTOL, range_basis, row_norms
from ..errors import (
    InputError,
    ModelError,
    NonFiniteError,
    ShapeError,
    SimulationError,
    UnknownNameError,
    ZenoError,
)
from ..model import ConstraintTerms, Model, State
from . import _dop853_tableau, _durable, _engine, _friction, _integrators
from ._events import Activate, Deactivate, Event, EventRecord, Reset, describe_transition
from ._impulses import impact_losses, with_impulses
from ._integrators import (
    _DP_B,
    DOP853,
    METHODS,
    RK4,
    RK8,
    DormandPrince5,
    ImplicitMidpoint,
    Integrator,
    SingularPassages,
    StepperState,
    _clip,
    hermite_quintic,
)
from ._options import EventSet, Output, Solver, resolve_options
from ._progress import Progress
from ._stabilization import Projection, Stabilization, resolve_stabilization
from ._trajectory import Status, Trajectory

__all__ = ["ADAPTIVE_RANK_RTOL", "DEFAULT_DT", "simulate"]

FloatArray = NDArray[np.float64]

#: Default fixed step (s) of fixed-step methods when ``dt`` is not given.
DEFAULT_DT = 1e-3

#: Rank tolerance of A used by default with adaptive methods (fixed-step ones use the core's
#: :data:`nonmin.core.DEFAULT_RTOL`). Measured, 10 s, dopri5 rtol 1e-10: with the core default
#: the step collapses at the first singular configuration (A02 and the crossed four-bar hit
#: max_steps having lost the energy); with 1e-6 both pass (A02: q error 2.4e-7, energy drift
#: 9.9e-8 J, 2043 steps; crossed four-bar: 1.2e-7, 2.6e-7 J, 2635 steps). It changes neither
#: dopri5 at rtol 1e-8, nor RK4 (dt = 1e-3) on these mechanisms, nor A03 Andrews at 0.03 s.
ADAPTIVE_RANK_RTOL = 1e-6

#: Absolute tolerance (s) of event location (Brent's method).
EVENT_XTOL = 1e-13



# --------------------------------------------------------------------------- evaluation


class _Point(NamedTuple):
    """Full evaluation of the dynamics at one state (what a sample records)."""

    t: float
    q: FloatArray
    qd: FloatArray
    qdd: FloatArray
    f_c: FloatArray
    u: FloatArray
    rank: int
    mu: float
    L: FloatArray
    lam: FloatArray
    A: FloatArray
    gamma: FloatArray
    phi: FloatArray
    velocity: FloatArray
    holonomic: NDArray[np.bool_]
    energy: float
    power: float = 0.0  #: q̇ᵀ(B u + f_passive + f_c) = q̇ᵀ(M q̈ − h): the power of W (J/s)
    work: float = float("nan")  #: W here when a partial step's own quadrature gave it


class _WorkQuadrature:
    """W = ∫ q̇ᵀ(B u + f_passive + f_c) dt in the general driver, as the engine's ``wk_*``
    (engine/src/sim_loop.cpp): W at the state reached, and the step being recorded (W and the
    power at both ends; samples inside it read the cubic Hermite interpolant)."""

    def __init__(self) -> None:
        self.W = 0.0
        self.step: tuple[float, float, float, float, float, float] | None = None

    def set_step(self, t0: float, h: float, dW: float, P0: float, P1: float) -> None:
        self.step = (t0, h, self.W, self.W + dW, P0, P1)

    def at(self, t: float) -> float:
        if self.step is None:
            return self.W
        t0, h, W0, W1, P0, P1 = self.step
        if not math.isfinite(P1):  # (no evaluation at the step end: its mean power)
            P1 = (W1 - W0) / h
        u = min(max((t - t0) / h, 0.0), 1.0)
        if u == 1.0:
            return W1
        if u == 0.0:
            return W0
        u2, u3 = u * u, u * u * u
        return ((2 * u3 - 3 * u2 + 1) * W0 + (u3 - 2 * u2 + u) * h * P0 + (-2 * u3 + 3 * u2) * W1
                + (u3 - u2) * h * P1)  # fmt: skip

    def end_power(self, P1: float) -> None:
        """The power at the step end, once known (DOP853's continuous extension evaluates F there)."""
        if self.step is not None and not math.isfinite(self.step[5]):
            self.step = (*self.step[:5], P1)

    def commit(self, W: float) -> None:
        self.W = float(W)
        self.step = None


def _midpoint_work(powers: list[float], times: list[float], t0: float, h: float) -> float:
    """The implicit midpoint rule's work over [t0, t0 + h] taken as sub-steps when the step was
    halved (ImplicitMidpoint._advance): walking back from the step end, the last evaluation
    before the end of the part left is the converged one at the middle m of the last sub-step
    [2m − end, end] (the calls at its start belong to it, the failed attempts come before its
    halves); each sub-step adds its width times that power (the engine's midpoint_advance)."""
    end = t0 + h
    tol = 1e-12 * max(1.0, abs(t0), abs(h))
    dw = 0.0
    i = len(powers) - 1
    while end > t0 + tol and i >= 0:
        while i >= 0 and not (t0 + tol < times[i] < end - tol):
            i -= 1
        if i < 0:
            return float("nan")
        m = times[i]
        dw += 2.0 * (end - m) * powers[i]
        end = 2.0 * m - end
        i -= 1
    return dw


def _step_work(
    integ: Integrator, powers: list[float], f_pow: float | None, h: float, fsal: bool = False,
    times: list[float] | None = None, t0: float | None = None,
) -> float:  # fmt: skip
    """The work's increment over one step (or partial step) of ``integ``, from the powers of
    the right-hand-side evaluations it made (``powers``, in order; ``f_pow``: the power of the
    F it was given), combined with the method's own weights b (the engine's rk4_advance,
    midpoint_solve, dp_step, d8_combine). NaN for a method without known weights."""
    if isinstance(integ, RK4):
        P = ([f_pow, *powers[-3:]] if f_pow is not None else powers[-4:])
        return h / 6.0 * (((P[0] + 2.0 * P[1]) + 2.0 * P[2]) + P[3])
    if isinstance(integ, ImplicitMidpoint):
        if times is None or t0 is None:
            return h * powers[-1]
        return _midpoint_work(powers, times, t0, h)
    if isinstance(integ, DormandPrince5):
        P0 = f_pow if f_pow is not None else powers[0]
        return h * float(_DP_B @ np.array([P0, *powers[-6:]]))
    if isinstance(integ, DOP853 | RK8):
        P0 = f_pow if f_pow is not None else powers[0]
        stages = powers[-12:-1] if fsal else powers[-11:]
        return h * float(np.asarray(_dop853_tableau.B)[:12] @ np.array([P0, *stages]))
    return float("nan")


#: Drift-aware rank tolerance factor (see :func:`drift_rank_rtol`). The spurious singular value
#: of a state off the manifold by δ is ~0.04·δ·σ₁ (A04), so 1 leaves a margin of 25. (It was 10:
#: on a long chain — A02 N = 40, σ_min/σ_max ~ 1e-3…1e-2 — RK4 stage points at dt = 5e-2 with
#: δ ~ 1e-3 then cut real constraint directions at up to 1e-2 and needed the SVD: 0.63 against
#: 0.42 s of wall time per simulated second; the library's small mechanisms and the validation
#: suite give the same results with either.)
DRIFT_RANK_FACTOR = 1.0

#: Engines accepted by ``simulate(engine=...)``.
ENGINES = ("auto", "engine", "python")

#: Relative round-off level of the free gap acceleration at a located release: at the zero of
#: the normal force it is zero up to ~eps × the size of its terms, so its sign there is noise
#: (a 1-ulp change in the kernel flipped a release of the 2R arm into "release-refused").
RELEASE_RTOL = 1e-10


def drift_rank_rtol(ct: ConstraintTerms, rtol: float | None) -> float:
    """Rank tolerance for the dynamics at a state that may be off the constraint manifold.

    A redundant constraint (Bricard's mechanism) or a singular configuration makes a singular
    value of A vanish *on* the manifold only; at a state off it by a distance δ (an RK stage
    point, or drift without projection) that singular value is O(δ) (measured ≈ 0.04·δ·σ₁ on
    A04) instead of 0. Taking it as a constraint divides the inconsistent part of γ by it and
    kicks the motion (0.45 J in 0.5 s on A04 with RK4 at dt = 1e-3). Singular values below
    the drift cannot be told from zero, so the relative cutoff is raised to
    ``max(rtol, DRIFT_RANK_FACTOR · max_i |φ_i| / ‖a_i‖)`` over the holonomic rows (the
    distance of the state from each constraint surface, to first order). On the manifold
    (after projection, ‖φ‖ ~ 1e-15) it is the plain ``rtol``.
    """
    base = DEFAULT_RTOL if rtol is None else float(rtol)
    hol = np.asarray(ct.holonomic)
    if ct.A.shape[0] == 0 or not hol.any():
        return base
    A, phi = (ct.A, ct.phi) if hol.all() else (ct.A[hol], ct.phi[hol])  # (all rows: no copies)
    norms = row_norms(A)
    live = norms > base * float(norms.max())
    if not live.all():
        if not live.any():
            return base
        phi, norms = phi[live], norms[live]
    drift = float((np.abs(phi) / norms).max())
    return min(max(base, DRIFT_RANK_FACTOR * drift), 1e-2)


#: Largest |q|, |q̇| the general driver evaluates: beyond it the squares in a model's terms
#: (θ̇², q̇ᵀMq̇) overflow. A stage state past it comes from a step far too large for the motion
#: (crossed four-bar, RK4 dt 0.14: |q̇| 5.7e181 at t = 4.78 s, after the engine's handover).
STATE_RANGE = 1e150


def _check_range(t: float, y: FloatArray) -> None:
    """SimulationError for a finite state past :data:`STATE_RANGE` (NaN and inf are left to the
    model's own typed checks), before its evaluation overflows with RuntimeWarnings."""
    big = float(np.max(np.abs(y), initial=0.0))
    if big > STATE_RANGE and math.isfinite(big):
        raise SimulationError(
            f"the state left the range of finite arithmetic at t = {t:.12g}: |(q, qd)|∞ = {big:.3g} "
            f"(> {STATE_RANGE:g}); the step is too large for this motion: take a smaller dt or an "
            "adaptive method"
        )


@dataclass
class _System:
    """Model + controller + stabilization bias, with the active set and controller state."""

    model: Model
    controller: Any
    stab: Stabilization
    rank_rtol: float | None
    n: int
    k: int
    active: frozenset[str]
    cstate: Any
    n_rhs: int = 0
    need_lambda: bool = False
    unilateral: tuple[str, ...] = ()
    #: the powers of W at the right-hand-side evaluations of the step being taken (rhs)
    powers: list[float] = field(default_factory=list)
    power_t: list[float] = field(default_factory=list)  #: (their times)

    @cached_property
    def working_constraints(self) -> bool:
        """A rheonomic or nonholonomic constraint: the constraint forces work (_power)."""
        return any(c.kind in ("rheonomic", "nonholonomic") for c in self.model.constraints)

    def rtol_at(self, ct: ConstraintTerms) -> float:
        """Rank tolerance at a (possibly off-manifold) state: see :func:`drift_rank_rtol`."""
        return drift_rank_rtol(ct, self.rank_rtol)

    def _forces(self, t: float, q: FloatArray, qd: FloatArray) -> tuple[Any, FloatArray, FloatArray]:
        terms = self.model.evaluate(t, q, qd, self.active)
        g = terms.h + terms.f_passive
        if self.controller is not None:
            raw = _durable.user_call("controller", t, self.controller, t, q, qd, self.cstate, active=self.active)
            u = _durable.finite_output("controller", t, raw, (self.k,), self.model.actuator_names)
            g = g + terms.B @ u
        else:
            u = np.zeros(self.k)
        return terms, g, u

    def rhs(self, t: float, y: FloatArray) -> FloatArray:
        """``F(t, y) = (qd, qdd)``."""
        self.n_rhs += 1
        _check_range(t, y)
        n = self.n
        q, qd = y[:n], y[n:]
        terms, g, _ = self._forces(t, q, qd)
        ct = terms.constraints
        qdd = forward_dynamics(terms.M, g, ct.A, self.stab.bias(ct), rtol=self.rtol_at(ct))
        if not np.all(np.isfinite(qdd)):
            raise SimulationError(f"non-finite acceleration at t = {t:.12g}")
        # the power of W (_power): the work's quadrature (_step_work) combines the powers of a
        # step's evaluations with the method's weights
        self.powers.append(self._power(terms, g, qd, qdd))
        self.power_t.append(float(t))
        return np.concatenate((qd, qdd))

    def _power(self, terms: Any, g: FloatArray, qd: FloatArray, qdd: FloatArray) -> float:
        """``q̇ᵀ(B u + f_passive) = q̇ᵀ(g − h)``; with rheonomic (or nonholonomic) constraints,
        whose forces work, ``q̇ᵀ(B u + f_passive + f_c) = q̇ᵀ(M q̈ − h)`` (the engine's
        work_power: scleronomic constraint forces do no work on the manifold, their power at a
        stage state off it is the integrator's error, left to the drift)."""
        if self.working_constraints:
            return float(qd @ (terms.M @ qdd - terms.h))
        return float(qd @ (g - terms.h))

    def point(self, t: float, q: FloatArray, qd: FloatArray) -> _Point:
        """Everything recorded at a sample (one more model evaluation)."""
        self.n_rhs += 1
        terms, g, u = self._forces(t, q, qd)
        ct = terms.constraints
        sol = solve_dynamics(terms.M, g, ct.A, self.stab.bias(ct), rtol=self.rtol_at(ct))
        qdd, f_c, mu, L = sol.qdd, sol.f_c, float(sol.mu), sol.L
        if not np.all(np.isfinite(qdd)):
            raise SimulationError(f"non-finite acceleration at t = {t:.12g}")
        # λ with f_c = Aᵀλ (least squares; only for contact release and diagnostics)
        if ct.A.shape[0] and (self.need_lambda or any(nm in self.active for nm in self.unilateral)):
            lam = range_basis(ct.A, self.rank_rtol).pinv().T @ f_c
        else:
            lam = np.zeros(0)
        energy = 0.5 * float(qd @ terms.M @ qd) + self.model.potential_energy(q)
        return _Point(t, q, qd, qdd, f_c, u, int(sol.rank), mu, L, lam, ct.A, ct.gamma,
                      ct.phi, ct.velocity, ct.holonomic, energy, self._power(terms, g, qd, qdd))

    def free_gap_acceleration(self, t: float, q: FloatArray, qd: FloatArray, name: str) -> float:
        """Acceleration of constraint ``name``'s gap if it were inactive."""
        return self.free_gap_acceleration_and_scale(t, q, qd, name)[0]

    def free_gap_acceleration_and_scale(
        self, t: float, q: FloatArray, qd: FloatArray, name: str
    ) -> tuple[float, float]:
        """The free gap acceleration and the size of its terms (its round-off is ~eps × that)."""
        saved = self.active
        self.active = saved - {name}
        try:
            y = self.rhs(t, np.concatenate((q, qd)))
        finally:
            self.active = saved
        a_row, gam, _ = _own_row(self.model, t, q, qd, name)
        terms = a_row * y[self.n :]
        return float(terms.sum() + gam), float(np.abs(terms).sum() + abs(gam))


# --------------------------------------------------------------------------- guards


class _Watch(NamedTuple):
    kind: str  # "user", "impact", "release"
    name: str
    direction: int
    event: Event | None


def _own_row(model: Any, t: float, q: FloatArray, qd: FloatArray, name: str) -> tuple[FloatArray, float, float]:
    """The (first) row of constraint ``name`` evaluated alone: A row, γ, φ.

    A source may add rows that are always active (a robot's unit-quaternion rows), so the row is
    located by name (:meth:`Model.row_slices`), never taken as row 0.
    """
    act = frozenset({name})
    ct = model.constraint_terms(t, q, qd, act)
    i = model.row_slices(act)[name].start
    return ct.A[i], float(ct.gamma[i]), float(ct.phi[i])


def _guard_value(sys: _System, w: _Watch, p: _Point) -> float:
    if w.kind == "user":
        assert w.event is not None
        raw = _durable.user_call(f"event {w.name!r}: guard", p.t, w.event.guard, p.t, p.q, p.qd, p.f_c)
        try:
            val = float(raw)
        except (TypeError, ValueError):
            raise SimulationError(
                f"event {w.name!r}: guard returned {type(raw).__name__} {raw!r}, not a number, at t = {p.t:.12g}"
            ) from None
        if not math.isfinite(val):
            raise SimulationError(f"event {w.name!r}: guard returned {val} at t = {p.t:.12g}")
        return val
    if w.kind == "impact":
        return _own_row(sys.model, p.t, p.q, p.qd, w.name)[2]
    # release: compressive normal force of the active unilateral constraint
    rows = sys.model.row_slices(sys.active)[w.name]
    return float(p.lam[rows][0])


def _guard_values(sys: _System, watches: list[_Watch], p: _Point) -> list[float]:
    """Every watch's value at ``p`` (:func:`_guard_value`), the impact gaps from one evaluation
    with their constraints active together (each constraint's rows are its own: the engine's
    ``gaps`` reads them the same way) instead of one per constraint."""
    names = frozenset(w.name for w in watches if w.kind == "impact")
    gap: dict[str, float] = {}
    if len(names) > 1:
        ct = sys.model.constraint_terms(p.t, p.q, p.qd, names)
        gap = {nm: float(ct.phi[sl.start]) for nm, sl in sys.model.row_slices(names).items()}
    return [gap[w.name] if w.kind == "impact" and w.name in gap else _guard_value(sys, w, p) for w in watches]


def _pulling(sys: _System, w: _Watch, p: _Point, g: float) -> bool:
    """Release watch ``w``'s normal force ``g`` at ``p`` clearly pulling:
    ``−λ‖A_row‖ > RELEASE_RTOL ‖f_c‖`` (the engine's ``pulling``)."""
    if not g < 0.0:
        return False
    norm = float(np.linalg.norm(p.A[sys.model.row_slices(sys.active)[w.name].start]))
    return norm > 0.0 and -g * norm > RELEASE_RTOL * float(np.linalg.norm(p.f_c))


def _crossed(g0: float, g1: float, direction: int) -> bool:
    up = g0 < 0.0 <= g1
    down = g0 > 0.0 >= g1
    if direction > 0:
        return up
    if direction < 0:
        return down
    return up or down


# --------------------------------------------------------------------------- recorder


class _Recorder:
    """Samples, row by row (general driver) or in array blocks (compiled engine), in order."""

    KEYS = ("t", "q", "qd", "qdd", "f_c", "u", "active_mask", "rank", "cond", "mu", "energy",
            "phi_norm", "velocity_residual_norm", "friction_work", "work")  # fmt: skip

    def __init__(self, model: Model) -> None:
        #: the friction forces' work up to the state reached (the engine's EngineResult.friction_work):
        #: the value of the rows added here and of engine blocks without friction
        self.work = 0.0
        #: the work of controllers and applied forces (the general driver's quadrature)
        self.quad = _WorkQuadrature()
        self.names = model.constraint_names
        self.n, self.k = model.n, model.k
        self.blocks: list[dict[str, Any]] = []
        self.cols: dict[str, list[Any]] = {key: [] for key in self.KEYS}
        self.count = 0
        self.max_count = _durable.MAX_RECORD_BYTES // _durable.sample_bytes(self.n, self.k, len(self.names))

    def last_t(self, default: float) -> float:
        """Time of the last recorded sample (``default`` before the first)."""
        if self.cols["t"]:
            return float(self.cols["t"][-1])
        return float(self.blocks[-1]["t"][-1]) if self.blocks and len(self.blocks[-1]["t"]) else default

    def add(self, p: _Point, active: frozenset[str]) -> None:
        self.count += 1
        if self.count > self.max_count:
            raise SimulationError(
                f"{self.count - 1} samples recorded by t = {p.t:.12g} fill the "
                f"{_durable.MAX_RECORD_BYTES / 2**30:g} GiB budget of a run; pass a coarser t_eval"
            )
        c = self.cols
        c["t"].append(p.t)
        c["q"].append(p.q.copy())
        c["qd"].append(p.qd.copy())
        c["qdd"].append(p.qdd)
        c["f_c"].append(p.f_c)
        c["u"].append(p.u)
        c["active_mask"].append([nm in active for nm in self.names])
        c["rank"].append(p.rank)
        sv = np.linalg.svd(p.L, compute_uv=False)
        c["cond"].append(float((sv[0] / sv[-1]) ** 2) if sv.size else 1.0)
        c["mu"].append(p.mu)
        c["energy"].append(p.energy)
        hol = p.phi[p.holonomic]
        c["phi_norm"].append(float(np.max(np.abs(hol))) if hol.size else 0.0)
        c["velocity_residual_norm"].append(float(np.max(np.abs(p.velocity))) if p.velocity.size else 0.0)
        c["friction_work"].append(self.work)
        c["work"].append(p.work if np.isfinite(p.work) else self.quad.at(p.t))

    def extend(self, block: dict[str, Any]) -> None:
        """Append a block of samples (arrays with the keys of :meth:`arrays`)."""
        self._flush()
        if "friction_work" not in block:
            block["friction_work"] = np.full(len(block["t"]), self.work)
        if "work" not in block:
            block["work"] = np.full(len(block["t"]), np.nan)
        self.blocks.append(block)
        self.count += len(block["t"])

    def _flush(self) -> None:
        if self.cols["t"]:
            self.blocks.append(self._rows())
            self.cols = {key: [] for key in self.KEYS}

    def _rows(self) -> dict[str, Any]:
        c, n, k = self.cols, self.n, self.k
        N = min(len(v) for v in c.values())  # an interrupt inside add() leaves a ragged row
        c = {key: v[:N] for key, v in c.items()}
        return {
            "t": np.asarray(c["t"], dtype=float),
            "q": np.asarray(c["q"], dtype=float).reshape(N, n),
            "qd": np.asarray(c["qd"], dtype=float).reshape(N, n),
            "qdd": np.asarray(c["qdd"], dtype=float).reshape(N, n),
            "f_c": np.asarray(c["f_c"], dtype=float).reshape(N, n),
            "u": np.asarray(c["u"], dtype=float).reshape(N, k),
            "active_mask": np.asarray(c["active_mask"], dtype=bool).reshape(N, len(self.names)),
            "rank": np.asarray(c["rank"], dtype=np.int64),
            "cond": np.asarray(c["cond"], dtype=float),
            "mu": np.asarray(c["mu"], dtype=float),
            "energy": np.asarray(c["energy"], dtype=float),
            "phi_norm": np.asarray(c["phi_norm"], dtype=float),
            "velocity_residual_norm": np.asarray(c["velocity_residual_norm"], dtype=float),
            "friction_work": np.asarray(c["friction_work"], dtype=float),
            "work": np.asarray(c["work"], dtype=float),
        }

    def arrays(self) -> dict[str, Any]:
        self._flush()
        if not self.blocks:
            return self._rows()
        if len(self.blocks) == 1:
            return self.blocks[0]
        return {key: np.concatenate([b[key] for b in self.blocks]) for key in self.KEYS}


# --------------------------------------------------------------------------- validation


def _resolve_method(method: Integrator | str, dt: float | None, rtol: float, atol: float) -> Integrator:
    if isinstance(method, str):  # (before the ABC's isinstance, the slower test)
        if method not in METHODS:
            raise UnknownNameError(f"method: unknown integrator {method!r}; known: {sorted(METHODS)}")
        cls = METHODS[method]
        if cls.adaptive:
            return cls(rtol=rtol, atol=atol)  # type: ignore[call-arg]
        return cls(dt=dt)  # type: ignore[call-arg]
    if isinstance(method, Integrator):
        return method
    raise InputError(
        f"method must be an Integrator object or one of {sorted(METHODS)}, got {type(method).__name__}"
    )


def _energy_level(
    stab: Projection, model: Model, t0: float, q: FloatArray, qd: FloatArray, act: frozenset[str],
    rank_rtol: float | None, project_initial: bool, nonconservative: bool,
) -> Projection:  # fmt: skip
    """``Projection(energy=True)``: refuse what is visibly not conservative, fill in the level
    (the energy of the projected initial state) when not given."""
    kinds = {c.name: c.kind for c in model.constraints}
    if nonconservative or any(kinds.get(c) == "rheonomic" for c in act):
        raise InputError(
            "stabilization: Projection(energy=True) holds the energy of a conservative system; "
            "got a controller, events, unilateral contact or a driver (rheonomic constraint)"
        )
    if stab.energy_level is not None:
        return stab
    if project_initial and act:
        q, qd = replace(stab, energy=False).project(model, t0, q, qd, act, rank_rtol)
    return replace(stab, energy_level=float(model.energy(q, qd)))


#: Earlier step ends a resumed run observes for its singular-passage history.
PASSAGE_HISTORY = 8


def _passage_history(prev: Trajectory | None, active: frozenset[str], t_out: Any) -> tuple[FloatArray, FloatArray]:
    """The step ends before a resumed run's start (its last ``PASSAGE_HISTORY`` samples under
    the same active set, strictly earlier), so that its singular-passage placement continues
    as the uninterrupted run's would: ``(t, y)`` of shapes (k,), (k, 2n). Empty unless every
    step was recorded (no ``t_eval``: samples are then the step ends the history was made of)."""
    if prev is None or t_out is not None or len(prev) < 2:
        return np.zeros(0), np.zeros((0, 0))
    t_end = float(prev.t[-1])
    idx: list[int] = []
    for i in range(len(prev) - 2, -1, -1):
        if prev.active[i] != active or not float(prev.t[i]) < t_end or len(idx) == PASSAGE_HISTORY:
            break
        if idx and not prev.t[i] < prev.t[idx[-1]]:
            break  # an event's pair of samples: the history restarted there
        idx.append(i)
    idx.reverse()
    ys = np.concatenate((prev.q[idx], prev.qd[idx]), axis=1) if idx else np.zeros((0, 0))
    return np.asarray(prev.t[idx], dtype=float), ys


def _positive(x: Any, name: str) -> float:
    try:
        v = float(x)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a positive number, got {x!r}") from None
    if not (v > 0 and math.isfinite(v)):
        raise InputError(f"{name} must be a positive finite number, got {x!r}")
    return v


def _t_span(t_span: Any) -> tuple[float, float]:
    """``(t0, t1)`` from ``(t0, t1)`` or a final time, validated."""
    # (plain numbers, the usual call: NumPy's values, without NumPy)
    if type(t_span) in (float, int):
        pair = (0.0, float(t_span))
    elif type(t_span) in (tuple, list) and len(t_span) == 2 and all(type(v) in (float, int) for v in t_span):
        pair = (float(t_span[0]), float(t_span[1]))
    else:
        pair = _t_span_array(t_span)
    if not all(math.isfinite(v) for v in pair):
        raise NonFiniteError(f"t_span must be finite, got {pair}")
    if not pair[1] > pair[0]:
        raise InputError(f"t_span must be increasing (t0 < t1), got {pair}")
    return pair


def _t_span_array(t_span: Any) -> tuple[float, float]:
    """``(t0, t1)`` from a NumPy scalar or array (text and booleans refused)."""
    if isinstance(t_span, bool | str | bytes) or (
            isinstance(t_span, tuple | list) and any(isinstance(v, bool | str | bytes) for v in t_span)):
        raise InputError(f"t_span must be (t0, t1) or a final time in seconds, got {t_span!r}")
    try:
        if np.isscalar(t_span):
            pair = (0.0, float(t_span))  # type: ignore[arg-type]
            arr = None
        else:
            arr = np.asarray(t_span, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"t_span must be (t0, t1) or a final time, got {t_span!r}") from None
    if arr is not None:
        if arr.shape != (2,):
            raise ShapeError(f"t_span must be (t0, t1) or a final time, got shape {arr.shape}")
        pair = (float(arr[0]), float(arr[1]))
    return pair


def _vector(x: ArrayLike, name: str, n: int) -> FloatArray:
    try:
        arr = np.array(as_float_array(x, name))  # text, booleans, complex: InputError
    except ShapeError:
        raise ShapeError(f"{name} must be {n} numbers, got {x!r}") from None
    if arr.shape != (n,):
        batch = "; k initial states are k runs: nonmin.simulate_batch" if arr.shape[-1:] == (n,) else ""
        raise ShapeError(f"{name} must have shape ({n},), got shape {arr.shape}{batch}")
    if not np.isfinite(arr).all():
        raise NonFiniteError(f"{name} must be finite")
    return arr


def _real(x: Any, name: str) -> float:
    try:
        return float(x)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a real number, got {x!r}") from None


def _check_names(model: Model, names: Iterable[str], what: str) -> None:
    unknown = sorted(set(names).difference(model.constraint_names))
    if unknown:
        raise UnknownNameError(
            f"{what}: unknown constraint name(s) {unknown} for model {model.name!r}; "
            f"known: {list(model.constraint_names)}"
        )


def _restitution_of(restitution: float | dict[str, float], name: str) -> float:
    if isinstance(restitution, dict):
        return float(restitution.get(name, 0.0))
    return float(restitution)


# --------------------------------------------------------------------------- driver


def simulate(
    model: Any,
    t_span: float | Sequence[float],
    q0: ArrayLike | None = None,
    qd0: ArrayLike | None = None,
    *,
    active: Iterable[str] | str | None = None,
    controller: Any = None,
    method: Integrator | str | None = None,
    dt: float | None = None,
    solver: Solver | None = None,
    stabilization: Stabilization | str | None = "projection",
    events: EventSet | Iterable[Event] = (),
    output: Output | None = None,
    engine: str = "auto",
    resume: str | os.PathLike[str] | Trajectory | None = None,
    **options: Any,
) -> Trajectory:
    """Simulate a constrained mechanical system through singularities and topology switches.

    Parameters
    ----------
    model : Model or Mechanism
        Any :class:`nonmin.model.Model`; or an object with ``.model`` and ``.state`` (a library
        mechanism), whose state then supplies the defaults of ``q0``, ``qd0`` and ``active``.
    t_span : (float, float) or float
        ``(t0, t1)`` with ``t0 < t1``; a single number means ``(0, t1)``.
    q0, qd0 : array_like, shape (n,)
        Initial coordinates and velocities (qd0 defaults to zero). ``q0`` may also be a
        :class:`nonmin.model.State` (e.g. from :func:`nonmin.model.assemble`), which then supplies
        ``qd0`` and ``active`` too.
    active : iterable of str, optional
        Initially active constraints (default ``model.default_active``).
    controller : callable ``(t, q, qd, state, active=...) -> u``, optional
        A :class:`nonmin.control.Controller` (``initial_state`` and ``update`` are used when
        present); ``u`` has shape (k,) and enters as ``B(q) u``.
    method, dt : shorthands of ``solver``
        The integrator (``"rk4"``, ``"rk8"``, ``"dopri5"``, ``"dop853"``, ``"midpoint"`` or an :class:`Integrator`
        value) and its step: ``simulate(m, 1, method="rk4", dt=1e-3)`` is
        ``simulate(m, 1, solver=Solver("rk4", dt=1e-3))``.
    solver : Solver, optional
        The integrator with its step, tolerances, rank tolerance, step budget and initial
        projection (:class:`~nonmin.sim.Solver`; default ``Solver()``: RK4 at
        :data:`DEFAULT_DT` with the core's rank tolerance).
    stabilization : str or Stabilization, default "projection"
        ``"none"``, ``"baumgarte"``, ``"projection"`` (mass-metric post-step projection), or a
        :class:`Stabilization` value.
    events : EventSet or iterable of Event
        The user events and the automatic contact settings (:class:`~nonmin.sim.EventSet`;
        a plain iterable of :class:`Event` means ``EventSet(events)``).
    output : Output, optional
        Sampling (``t_eval``), progress bar, checkpoints and failure policy
        (:class:`~nonmin.sim.Output`).
    engine : {"auto", "engine", "python"}, default "auto"
        ``"python"``: the general driver. ``"engine"``: the whole loop in the compiled engine
        (C++, :mod:`nonmin.sim._engine`; same algorithm, results to round-off): every built-in
        method, stabilization, ``t_eval``, controllers (called back), events and automatic
        contact (the guards are watched at every step; the general driver takes the steps in
        which one crosses), for any model (its compiled program, or its Python ``evaluate``
        called back); custom Integrator or Stabilization classes are not covered
        (:class:`~nonmin.errors.InputError` names what is missing);
        ``"auto"``: the engine when it covers the run (not with the core's backend set to
        ``"numpy"``), else the general driver. No path compiles anything at run time.
        ``trajectory.metadata["engine"]`` tells which ran. If a kernel fails in the engine's
        loop, the general driver takes over at the last accepted step (and raises the typed
        error).
    resume : path or Trajectory, optional
        Continue an interrupted run (a checkpoint, or any trajectory of the same model ending
        before ``t1``) from its last sample: its samples are kept in front of the new ones.
        The integrator, the controller's internal state and the events' re-arming restart at
        that sample, so a resumed run matches an uninterrupted one to the integration error
        (to round-off with a fixed-step method, the same ``dt`` and every step recorded).
    **options
        Flat shorthands of the fields of the three values: ``rtol``, ``atol``, ``h0``,
        ``rank_rtol``, ``max_steps``, ``project_initial`` (:class:`Solver`); ``contact``,
        ``restitution``, ``impact_velocity_threshold``, ``zeno_max_events``, ``zeno_window``,
        ``event_rearm`` (:class:`EventSet`); ``t_eval``, ``progress``, ``checkpoint``,
        ``checkpoint_every``, ``throw`` (:class:`Output`). A field given both ways with
        different values raises :class:`~nonmin.errors.InputError`.

    Returns
    -------
    Trajectory
        With status ``interrupted`` and the samples computed so far when ``KeyboardInterrupt``
        (Ctrl-C) stops the run (whatever ``throw``).

    Raises
    ------
    InputError, ShapeError, UnknownNameError
        Bad arguments.
    SimulationError, ZenoError, NotPositiveDefiniteError
        When the integration cannot go on (unless ``throw=False``).
    """
    if not isinstance(engine, str) or engine not in ENGINES:
        raise InputError(f"engine must be one of {ENGINES}, got {engine!r}")
    flat = dict(options)
    if method is not None:
        flat["method"] = method
    if dt is not None:
        flat["dt"] = dt
    sol, evset, out = resolve_options(solver, events, output, flat)
    method, dt, rtol, atol, h0 = sol.method, sol.dt, sol.rtol, sol.atol, sol.h0
    rank_rtol, max_steps, project_initial = sol.rank_rtol, sol.max_steps, sol.project_initial
    contact = evset.contact
    restitution = evset.restitution if isinstance(evset.restitution, float) else dict(evset.restitution)
    impact_velocity_threshold, event_rearm = evset.impact_velocity_threshold, evset.event_rearm
    zeno_max_events, zeno_window = evset.zeno_max_events, evset.zeno_window
    t_eval, progress, throw = out.t_eval, out.progress, out.throw
    checkpoint, checkpoint_every = out.checkpoint, out.checkpoint_every
    # ---------------------------------------------------------------- model / mechanism
    if not isinstance(model, Model):
        mech = model
        inner = getattr(mech, "model", None)
        if not isinstance(inner, Model):
            raise InputError(
                f"model must be a nonmin Model or a mechanism with .model, got {type(model).__name__}"
            )
        model = inner
        st = getattr(mech, "state", None)
        if st is not None:
            if q0 is None:
                q0 = st.q
            if qd0 is None:
                qd0 = st.qd
            if active is None:
                active = st.active
    if isinstance(q0, State):  # e.g. the result of nonmin.model.assemble
        st0 = q0
        q0 = st0.q
        if qd0 is None:
            qd0 = st0.qd
        if active is None:
            active = st0.active
    n, k = model.n, model.k
    t0, t1 = _t_span(t_span)
    t_grid = t0  # (fixed steps: the grid of SingularPassages.align; a resumed run keeps it)
    prev = None
    if resume is not None:
        prev = _durable.resume_point(resume, model, t1)
        t0, q0, qd0, active = float(prev.t[-1]), prev.q[-1], prev.qd[-1], prev.active[-1]
        if project_initial is None:
            project_initial = False
    ck_path, ck_every = _durable.check_checkpoint(checkpoint, checkpoint_every)
    if q0 is None:
        raise InputError("simulate: q0 is required for a bare model (shape (n,))")
    q = _vector(q0, "q0", n)
    qd = np.zeros(n) if qd0 is None else _vector(qd0, "qd0", n)
    act = model.resolve_active(active)
    stab = resolve_stabilization(stabilization)
    integ = _resolve_method(method, dt, rtol, atol)
    if integ.adaptive:
        h_init = 0.0 if h0 is None else h0
        if dt is not None and hasattr(integ, "h_max"):
            integ = type(integ)(**{**integ.__dict__, "h_max": dt})
    else:
        step = getattr(integ, "dt", None) or dt or DEFAULT_DT
        h_init = _positive(step, "dt")
    events = evset.events
    for ev in events:
        tr = ev.transition
        if isinstance(tr, Activate | Deactivate):
            _check_names(model, tr.names, f"event {ev.name!r}")
    if isinstance(restitution, dict):
        _check_names(model, restitution, "restitution")
    t_out: FloatArray | None = None
    if t_eval is not None:
        t_raw = np.asarray(t_eval)
        _durable.check_budget(t0=t0, t1=t1, h=None, max_steps=1, t_out=t_raw, n=n, k=k,
                              c=len(model.constraint_names))  # its size, before copying it
        t_out = np.array(t_raw, dtype=float)
        if not np.isfinite(t_out).all():
            raise NonFiniteError(f"t_eval must be finite, got NaN/inf at index {int(np.argmax(~np.isfinite(t_out)))}")
        if prev is not None:
            t_out = t_out[t_out > t0]
        if t_out.size and (bool((t_out[1:] < t_out[:-1]).any()) or t_out[0] < t0 or t_out[-1] > t1):
            raise InputError(f"t_eval must be non-decreasing and inside t_span {(t0, t1)}")
    if controller is not None and not callable(controller):
        raise InputError(f"controller must be callable, got {type(controller).__name__}")
    _durable.check_budget(t0=t0, t1=t1, h=dt if integ.adaptive else h_init, max_steps=int(max_steps),
                          t_out=t_out, n=n, k=k, c=len(model.constraint_names))
    if rank_rtol is None and integ.adaptive:
        rank_rtol = ADAPTIVE_RANK_RTOL
    v_thresh, zeno_max, rearm_tol = impact_velocity_threshold, zeno_max_events, event_rearm
    project_initial = isinstance(stab, Projection) if project_initial is None else bool(project_initial)

    cstate = (_durable.user_call("controller.initial_state", t0, controller.initial_state)
              if hasattr(controller, "initial_state") else None)
    unilateral = tuple(c.name for c in model.constraints if c.kind == "unilateral") if contact else ()
    system = _System(model, controller, stab, rank_rtol, n, k, act, cstate, unilateral=unilateral)
    # the engine's event layer (restitution per constraint): only its contact guards read it
    contact_opts = ([_restitution_of(restitution, c.name) for c in model.constraints], v_thresh) \
        if unilateral else None  # fmt: skip
    use_engine = False
    why: str | None = None
    fcs = model.friction_contacts if contact else ()
    slip: dict[str, tuple[float, ...]] = {}  # friction: the slipping contacts' directions, by normal name
    if engine in ("auto", "engine"):
        why = _engine.ineligible(integ, stab, events, unilateral, engine)
        if why is not None and engine == "engine":
            raise InputError(f"engine='engine' cannot run this simulation: {why}")
        use_engine = why is None
    if fcs:
        _friction.check_friction_run(model, engine, use_engine, why, events)
    meta = {
        "model": _describe(model),
        "options": {
            "t_span": [t0, t1],
            "method": integ.name or type(integ).__name__,
            "integrator": repr(integ),
            "dt": h_init if not integ.adaptive else dt,
            "rtol": rtol,
            "atol": atol,
            "stabilization": repr(stab),
            "contact": bool(contact),
            "restitution": restitution,
            # the controller's type, not its repr: a repr prints every gain array (~1 ms a call)
            "controller": None if controller is None else _type_name(controller),
            "events": [e.name for e in events],
            "rank_rtol": rank_rtol,
            "engine": engine,
        },
        "initial_state": {"t": t0, "q": q.tolist(), "qd": qd.tolist(), "active": list(_sorted_names(act))},
        "engine": "engine" if use_engine else "python",
    }
    if isinstance(stab, Projection) and stab.energy:
        stab = _energy_level(stab, model, t0, q, qd, act, rank_rtol, project_initial,
                             bool(controller is not None or events or unilateral))  # fmt: skip
    rec = _Recorder(model)
    passages = (SingularPassages(integ.passage_fractions, widen=not integ.adaptive and integ.widen_passages)
                 if getattr(integ, "passages", False) else None)  # fmt: skip
    if passages is not None and not integ.adaptive:
        passages.origin = t_grid  # (fixed steps: the grid t_grid + k·dt, SingularPassages.align)
    seed = _passage_history(prev, act, t_out)
    records: list[EventRecord] = []
    status = Status.SUCCESS
    message = "reached the end of t_span"
    n_steps = 0
    n_rejected = 0

    def snapshot(st: Status, msg: str) -> Trajectory:
        """The samples so far as a Trajectory (checkpoints, interruption, the final result),
        behind those of the run it resumes."""
        arrays = rec.arrays()
        new = Trajectory(
            **arrays,
            impact_loss=impact_losses(model, tuple(records), arrays["t"]),
            constraint_names=model.constraint_names,
            coordinate_names=model.coordinate_names,
            actuator_names=model.actuator_names,
            events=tuple(records),
            status=st,
            message=msg,
            n_steps=n_steps,
            n_rhs=system.n_rhs,
            n_rejected=n_rejected,
            metadata=meta,
        )
        if prev is None:
            return new
        # the resumed run's first sample is the earlier run's last one, recomputed
        return _durable.join(prev, new, drop_last=t_out is None and len(new) > 0)

    bar = _durable.Checkpointer(Progress(t0, t1, progress), ck_path, ck_every, t0, snapshot)
    t = t0
    try:
        engine_on = False  # the engine takes the steps (the general driver takes event steps)
        if use_engine:
            eng_prog = _engine.program_for(model)
            opts = _engine.options(
                integ, stab, dt=h_init, t1=t1, h0=h_init, rank_rtol=rank_rtol,
                drift_factor=DRIFT_RANK_FACTOR, project_initial=project_initial,
                max_steps=int(max_steps), t_grid=t_grid,
            )  # fmt: skip
        er: _engine.EngineResult | None = None
        pending: _engine.EngineResult | None = None  # the engine's first run with contact guards (below)
        if use_engine and not (events or fcs):  # the engine starts the run (start included)
            creg = _engine.compiled_controller(controller, model, eng_prog, act)
            ccb = _engine.ControllerCallback(controller, system.cstate, k, None, model) \
                if controller is not None and creg is None else None  # fmt: skip
            watches = _watches(events, act, unilateral)  # (values at the first point: the engine's)
            g_idx, guards = _engine_guards(system, watches, [0.0] * len(watches))
            try:
                er = _engine.run(eng_prog, opts=opts, active_mask=model_mask(model, act), t_out=t_out,
                                 sink=rec.extend, progress=bar, start=(t0, q, qd), controller=ccb,
                                 passage_seed=seed, compiled=creg, guards=guards,
                                 contact=contact_opts)  # fmt: skip
            finally:
                if ccb is not None:
                    system.cstate = ccb.state
                if creg is not None:
                    system.cstate = _engine.merge_state(controller, system.cstate, creg)
            if not er.started:  # the first evaluation failed: the general driver raises
                er = None
                meta["engine"] = "python"
            elif unilateral:  # the loop below takes the engine's result (events, resumes)
                pending, er = er, None
                gvals = [0.0] * len(watches)
                # (the state at t0 when the engine took no step: its projected start, pending.y)
                state = StepperState(t0, pending.y.copy(), None, h_init)
                out_i, engine_on = 0, True
        if er is not None:  # the engine ran the whole run, or to a handover
            n_steps += er.steps
            n_rejected += er.n_rejected
            system.n_rhs += er.n_rhs
            rec.quad.commit(er.work)
            t = er.t
            out_i = er.out_i if t_out is not None else 0
            q, qd = er.y[:n].copy(), er.y[n:].copy()
            watches, gvals = [], []
            state = StepperState(t, er.y.copy(), None, er.h if integ.adaptive else h_init)
            if er.handover:
                meta["engine"] = f"engine, then python from t = {t:.12g}"
        elif pending is None:  # the Python start (pending: the engine's first run enters the loop below)
            if project_initial and act:
                q, qd = stab.project(model, t0, q, qd, act, rank_rtol) if isinstance(stab, Projection) \
                    else Projection().project(model, t0, q, qd, act, rank_rtol)
            t = t0
            if fcs:  # the contacts' initial modes (stick or slip), projected onto a new sticking row
                act_f, slip = _friction.initial_modes(model, t, q, qd, system.active, v_thresh=v_thresh,
                                                      rank_rtol=rank_rtol, bias=stab.bias)  # fmt: skip
                if act_f != system.active:
                    system.active = act_f
                    q, qd = stab.project(model, t0, q, qd, act_f, rank_rtol) if isinstance(stab, Projection) \
                        else Projection().project(model, t0, q, qd, act_f, rank_rtol)  # fmt: skip
            p = system.point(t, q, qd)
            if fcs:
                p = _friction.first_point(model, p, system.active, slip, rank_rtol=rank_rtol, bias=stab.bias,
                                          B_u=None if controller is None else model.input_matrix(q) @ p.u)  # fmt: skip
            if t_out is None or (t_out.size and t_out[0] == t0):
                rec.add(p, system.active)
            out_i = 0 if t_out is None else int(np.searchsorted(t_out, t0, side="right"))
            watches = _watches(events, system.active, unilateral)
            gvals = _guard_values(system, watches, p)
            state = integ.init(system.rhs, t, np.concatenate((q, qd)), h_init)
            if passages is not None:
                for ts, ys in zip(*seed, strict=True):
                    passages.observe(float(ts), model.constraint_terms(float(ts), ys[:n], ys[n:], act).A)
                passages.observe(t, p.A)
            engine_on = use_engine
        project_y = None
        if isinstance(stab, Projection) and (integ.adaptive or (passages is not None and type(integ) is RK4)):

            def project_y(tt: float, yy: FloatArray) -> FloatArray:
                _check_range(tt, yy)  # (a stage point before its projection's evaluation)
                qq, vv = stab.project(model, tt, yy[:n].copy(), yy[n:].copy(), system.active, rank_rtol)
                return np.concatenate((qq, vv))

        recent_events: list[float] = []
        f_pow = float("nan")  # the power of W at the state of state.f
        disarmed: set[int] = set()

        def fpoint(tt: float, qq: FloatArray, vv: FloatArray, sl: Mapping[str, tuple[float, ...]]) -> _Point:
            """The recorded point with the slipping contacts' friction applied."""
            pp = system.point(tt, qq, vv)
            return _friction.first_point(model, pp, system.active, sl, rank_rtol=rank_rtol, bias=stab.bias,
                                         B_u=None if controller is None else model.input_matrix(qq) @ pp.u)  # fmt: skip
        while t < t1:
            if engine_on and pending is not None:  # the engine's first run (it started the run)
                er, pending = pending, None
            elif engine_on:  # the engine's steps up to t1, a failure, or a guard crossing
                creg = _engine.compiled_controller(controller, model, eng_prog, system.active)
                ccb = _engine.ControllerCallback(controller, system.cstate, k, None, model) \
                    if controller is not None and creg is None else None  # fmt: skip
                g_idx, guards = _engine_guards(system, watches, gvals)
                try:
                    er = _engine.run(
                        eng_prog, opts=opts, active_mask=model_mask(model, system.active), t_out=t_out,
                        sink=rec.extend, progress=bar, controller=ccb, compiled=creg,
                        resume=(t, state.y, state.h if integ.adaptive else h_init, n_steps, out_i),
                        watch=_engine_watch(system, watches, gvals, disarmed, rearm_tol), guards=guards,
                        contact=contact_opts, friction=_friction.engine_contacts(model, slip) if fcs else None,
                        work0=rec.work, ctrl_work0=rec.quad.W,
                    )  # fmt: skip
                finally:
                    if ccb is not None:
                        system.cstate = ccb.state
                    if creg is not None:
                        system.cstate = _engine.merge_state(controller, system.cstate, creg)
            if engine_on:
                assert er is not None
                fstep = None
                if fcs and er.event and not er.handover:  # a guard crossed with user guards watched
                    fstep = _friction_step(
                        system, partial(_friction_run, er=er, guards=guards, slip=dict(slip), opts=opts, t1=t1,
                                        run_kw=dict(program=eng_prog, t_out=t_out, contact=contact_opts,
                                                    active_mask=model_mask(model, system.active)),
                                        controller=controller, eng_prog=eng_prog, system=system,
                                        h_fixed=None if integ.adaptive else h_init),
                        partial(fpoint, sl=dict(slip)), watches, gvals, disarmed, er.t,
                        min(er.h if integ.adaptive else h_init, t1 - er.t), n, rec.extend,
                    )  # fmt: skip
                    er = fstep.er
                if fcs:
                    rec.work = er.friction_work
                rec.quad.commit(er.work)
                for i, g in zip(g_idx, er.guards):
                    gvals[i] = g
                if fcs:
                    slip = _friction.slip_from_engine(model, er.slip)
                    _friction.check_engine_result(model, er, t)
                n_rejected += er.n_rejected
                system.n_rhs += er.n_rhs
                n_steps = er.steps
                if er.steps or er.t != t:
                    t = er.t
                    out_i = er.out_i if t_out is not None else out_i
                    state = StepperState(t, er.y.copy(), None, er.h if integ.adaptive else h_init)
                elif integ.adaptive:
                    state = state._replace(h=er.h)
                if er.handover:
                    engine_on = False
                    meta["engine"] = f"engine, then python from t = {t:.12g}"
                if er.transition:  # the engine located and applied contact events (no user guard)
                    label = ""
                    for d in er.events:
                        after = _mask_names(model, d["active_after"])
                        records.append(EventRecord(float(d["t"]), str(d["name"]), str(d["transition"]),
                                                   d["q_before"], d["qd_before"], d["q_after"], d["qd_after"],
                                                   _mask_names(model, d["active_before"]), after))  # fmt: skip
                        recent_events.append(float(d["t"]))
                        label = str(d["name"])
                        system.active = after
                    _zeno_check(recent_events, t, zeno_window, zeno_max, label)
                    q, qd = er.y[:n].copy(), er.y[n:].copy()
                    if controller is not None and hasattr(controller, "update"):
                        system.cstate = _durable.user_call("controller.update", t, controller.update, t, q, qd,
                                                           system.cstate, active=system.active)  # fmt: skip
                    watches = _watches(events, system.active, unilateral)
                    gvals = list(er.guards)  # the contact watches (in their order, after the user ones)
                    if events:
                        p_after = fpoint(t, q, qd, slip)
                        gvals = [_guard_value(system, w2, p_after) for w2 in watches[: len(events)]] + gvals
                    continue
                if fstep is not None and fstep.p is not None:  # user events at fstep.te (friction run)
                    te, p = fstep.te, fstep.p
                    if t_out is not None:
                        rec.add(p, system.active)
                    terminal = False
                    label = ""
                    for i in fstep.group:
                        w = watches[i]
                        before_active = system.active
                        qn, qdn, new_active, label, term_i, _cap = _apply(system, w, p)
                        qn, qdn, slip = _friction_after_user(model, stab, te, qn, qdn, new_active, v_thresh,
                                                             rank_rtol, system,
                                                             None if controller is None else p.u)  # fmt: skip
                        records.append(EventRecord(te, label, _transition_text(w), p.q.copy(), p.qd.copy(),
                                                   qn.copy(), qdn.copy(), before_active, system.active))  # fmt: skip
                        disarmed.add(id(w.event))
                        terminal = terminal or term_i
                        recent_events.append(te)
                        p = fpoint(te, qn, qdn, slip)
                    _zeno_check(recent_events, te, zeno_window, zeno_max, label)
                    rec.add(p, system.active)
                    t, q, qd = te, p.q, p.qd
                    state = StepperState(te, np.concatenate((q, qd)), None, er.h if integ.adaptive else h_init)
                    if controller is not None and hasattr(controller, "update"):
                        system.cstate = _durable.user_call("controller.update", te, controller.update, te, q, qd,
                                                           system.cstate, active=system.active)  # fmt: skip
                    watches = _watches(events, system.active, unilateral)
                    gvals = _guard_values(system, watches, p)
                    bar.update(t)
                    if terminal:
                        status = Status.EVENT_TERMINATED
                        message = f"terminal event {label!r} at t = {te:.12g}"
                        break
                    continue
                if t >= t1:
                    break
                if passages is not None:  # the history is the engine's: start afresh here
                    passages.reset()
                    passages.observe(t, model.constraint_terms(t, state.y[:n], state.y[n:], system.active).A)
                # er.event: the general driver takes this step (locates, applies the transition)
            if n_steps >= max_steps:
                raise SimulationError(f"max_steps = {max_steps} reached at t = {t:.12g}")
            if state.f is None and not integ.adaptive and t_out is not None and out_i < t_out.size:
                # F at the step start: the method needs it anyway, output samples inside the
                # step need it for the continuous extension
                state = state._replace(f=system.rhs(state.t, state.y))
                f_pow = system.powers[-1]
            h_star = _end_at_passage(integ, passages, stab, system.active, state, t1)
            if h_star is not None and state.f is None:
                state = state._replace(f=system.rhs(state.t, state.y))
                f_pow = system.powers[-1]
            y_start, f_start, t_start = state.y, state.f, state.t
            fp_start = f_pow if f_start is not None else None
            system.powers.clear()
            system.power_t.clear()
            res = integ.step(system.rhs, state, t1 if h_star is None else t_start + h_star, project_y, passages) \
                if passages is not None else integ.step(system.rhs, state, t1, project_y)  # fmt: skip
            n_rejected += res.n_rejected
            n_steps += 1
            h = res.h
            t_new = res.state.t
            # the work's increment over the step, from its stage powers (the method's weights)
            d8_fsal = isinstance(integ, DOP853) and res.state.f is not None
            dW_step = (_step_work(integ, system.powers, fp_start, h, d8_fsal, system.power_t, t_start)
                       if system.powers else float("nan"))  # fmt: skip
            P0_step = fp_start if fp_start is not None else (system.powers[0] if system.powers else float("nan"))
            P1_step = system.powers[-1] if (isinstance(integ, DormandPrince5) or d8_fsal) else float("nan")
            h_work = h
            dense_star = None
            if h_star is not None:
                # the run ends at a predicted singular instant: the step placed past it was
                # taken; the end state is its quintic Hermite interpolant at t1, projected as a
                # sample (the engine loop's end_star, PASSAGE_END_BAND)
                assert f_start is not None
                qf, vf = stab.project(model, t_new, res.state.y[:n].copy(), res.state.y[n:].copy(),
                                      system.active, rank_rtol)  # fmt: skip
                pf = system.point(t_new, qf, vf)
                P1_step = pf.power
                dense_star = partial(_fixed_step_dense, y_start, f_start, np.concatenate((qf, vf)),
                                     np.concatenate((vf, pf.qdd)), t_start, h)  # fmt: skip
                ys = dense_star(t1)
                res = res._replace(state=StepperState(t1, ys, None, res.state.h))
                h, t_new = t1 - t_start, t1

            def at(s: float, _y: FloatArray = y_start, _f: Any = f_start, _t: float = t_start,
                   _fp: float | None = fp_start) -> _Point:  # fmt: skip
                """Projected state after a partial step of size s from the step start (W there:
                the partial step's own quadrature)."""
                if s <= 0.0:
                    yy, dw = _y, 0.0
                else:
                    mark = len(system.powers)
                    yy = integ.advance(system.rhs, _t, _y, _f, s)
                    dw = _step_work(integ, system.powers[mark:], _fp if _f is not None else None, s,
                                    times=system.power_t[mark:], t0=_t)  # fmt: skip
                qq, vv = stab.project(model, _t + s, yy[:n].copy(), yy[n:].copy(), system.active, rank_rtol)
                return system.point(_t + s, qq, vv)._replace(work=rec.quad.W + dw)

            _check_range(t_new, res.state.y)  # (the stages were checked, not the step's end)
            if dense_star is None:
                q1, qd1 = stab.project(model, t_new, res.state.y[:n].copy(), res.state.y[n:].copy(),
                                       system.active, rank_rtol)  # fmt: skip
            else:
                q1, qd1 = stab.project_sample(model, t_new, res.state.y[:n].copy(), res.state.y[n:].copy(),
                                              system.active, rank_rtol)  # fmt: skip
            end_tol = 1e-12 * max(1.0, abs(t_new))
            dense = res.dense if dense_star is None else dense_star
            if (integ.adaptive and _integrators.ADAPTIVE_PARTIAL_SAMPLES and dense_star is None
                    and not (system.active and passages is not None and passages.holds(t_start, h))):
                dense = None  # samples inside: the method's partial steps (`at`), not the extension
            inside = (dense is None and not integ.adaptive and f_start is not None and t_out is not None
                      and out_i < t_out.size and t_out[out_i] < t_new - end_tol)  # fmt: skip
            # the full evaluation at the step end is needed for guards, recording, or the
            # continuous extension of a fixed-step method (then it is also the next step's F)
            p1 = system.point(t_new, q1, qd1) if (watches or t_out is None or inside) else None
            if p1 is not None and dense_star is None:
                P1_step = p1.power
            rec.quad.set_step(t_start, h_work, dW_step, P0_step, P1_step)
            if inside:
                assert p1 is not None and f_start is not None
                dense = partial(_fixed_step_dense, y_start, f_start, np.concatenate((q1, qd1)),
                                np.concatenate((qd1, p1.qdd)), t_start, h)  # fmt: skip

            def out_at(
                s: float, _d: Any = dense, _t: float = t_start, _h: float = h, _q: Any = q1,
                _v: Any = qd1, _p: Any = p1, _tn: float = t_new, _tol: float = end_tol,
            ) -> _Point:
                """Output sample: the step end itself, the continuous extension when the method
                has one (fixed-step methods: the Hermite interpolant), else a partial step."""
                if abs(s - _h) <= _tol:
                    return _p if _p is not None else system.point(_tn, _q, _v)
                if _d is None:
                    return at(s)
                mark = len(system.powers)
                yy = _d(_t + s)
                if len(system.powers) > mark:  # DOP853's extension: F(t + h, y1) first
                    rec.quad.end_power(system.powers[mark])
                qq, vv = stab.project_sample(model, _t + s, yy[:n].copy(), yy[n:].copy(), system.active, rank_rtol)
                return system.point(_t + s, qq, vv)

            new_g = _guard_values(system, watches, p1) if p1 is not None else []
            fired = [
                i for i, w in enumerate(watches)
                if (_crossed(gvals[i], new_g[i], w.direction) and id(w.event) not in disarmed)
                or (w.kind == "impact" and gvals[i] <= 0.0 and new_g[i] < 0.0)
                # a contact pulling from the step start (run start, after a transition: no
                # downward crossing to see) and still clearly pulling at its end
                or (w.kind == "release" and gvals[i] < 0.0 and p1 is not None and _pulling(system, w, p1, new_g[i]))
            ]
            for key in list(disarmed):  # re-arm user events whose guard left the zero band
                j = next((i for i, w in enumerate(watches) if id(w.event) == key), None)
                if j is None or abs(new_g[j]) > rearm_tol:
                    disarmed.discard(key)
            if fired:
                roots: list[tuple[float, int]] = []
                for i in fired:
                    w = watches[i]

                    def gfun(s: float, _w: _Watch = w) -> float:
                        return _guard_value(system, _w, at(s))

                    if gvals[i] < 0.0 and w.kind == "release":
                        s_root = 0.0  # pulling from the step start: released there
                    elif w.kind == "impact" and gvals[i] <= 0.0:
                        # a bounce too short to resolve (or a start inside the obstacle): the
                        # gap never became positive at a sample — contact from the step start
                        s_root = 0.0
                    elif new_g[i] == 0.0:
                        s_root = h
                    else:
                        try:
                            from scipy.optimize import brentq  # lazy: 0.4 s of import

                            s_root = float(brentq(gfun, 0.0, h, xtol=EVENT_XTOL, rtol=1e-15, maxiter=200))
                        except ValueError:  # re-evaluated end values lost the sign change
                            s_root = h
                        # take the bracket end on the far side of the crossing
                        s_root = _past_root(gfun, s_root, h, gvals[i])
                    roots.append((s_root, i))
                roots.sort()
                best_s = roots[0][0]
                # events within the location tolerance fire together (user events first)
                group = [i for s_i, i in roots if s_i <= best_s + 4 * EVENT_XTOL]
                group.sort(key=lambda i: (watches[i].kind != "user", i))
                pe = at(best_s) if (best_s < h or p1 is None) else p1
                te = t_start + best_s
                _sample_t_eval(rec, t_out, out_i, t_start, te, out_at, system)
                out_i = _advance_out(t_out, out_i, te)
                rec.add(pe, system.active)
                rec.quad.commit(pe.work if np.isfinite(pe.work) else rec.quad.at(te))  # (W continuous)
                terminal = False
                h_cap = 0.0
                label = ""
                p = pe
                # user events one by one, then every contact closing now as one set impact
                # (which also decides the contacts already closed); releases alone otherwise
                impacts = [i for i in group if watches[i].kind == "impact"]
                actions = [[i] for i in group if watches[i].kind == "user"]
                if impacts:
                    actions.append(impacts)
                else:
                    actions += [[i] for i in group if watches[i].kind == "release"]
                for idx in actions:
                    w = watches[idx[0]]
                    before_active = system.active
                    dt_fix = h_init if not integ.adaptive else 0.0
                    if w.kind == "impact":
                        fired_names = [watches[i].name for i in idx]
                        plastic = frozenset(watches[i].name for i in idx if gvals[i] <= 0.0)
                        qn, qdn, new_active, label, term_i, cap_i = _set_impact(
                            system, fired_names, plastic, p, restitution, v_thresh, dt_fix)
                        text = f"impact {'+'.join(fired_names)}"
                    else:
                        qn, qdn, new_active, label, term_i, cap_i = _apply(system, w, p)
                        text = _transition_text(w)
                    if isinstance(stab, Projection) and new_active:
                        qn, qdn = stab.project(model, te, qn, qdn, new_active, rank_rtol)
                    system.active = new_active
                    records.append(EventRecord(te, label, text, p.q.copy(), p.qd.copy(),
                                               qn.copy(), qdn.copy(), before_active, new_active))
                    if w.kind == "user":
                        disarmed.add(id(w.event))
                    terminal = terminal or term_i
                    h_cap = cap_i if h_cap == 0.0 else (min(h_cap, cap_i) if cap_i > 0 else h_cap)
                    recent_events.append(te)
                    p = system.point(te, qn, qdn)
                _zeno_check(recent_events, te, zeno_window, zeno_max, label)
                rec.add(p, system.active)
                qn, qdn = p.q, p.qd
                t = te
                if controller is not None and hasattr(controller, "update"):
                    system.cstate = _durable.user_call("controller.update", te, controller.update, te, qn,
                                                       qdn, system.cstate, active=system.active)
                watches = _watches(events, system.active, unilateral)
                gvals = _guard_values(system, watches, p)
                if passages is not None:
                    passages.reset()
                    passages.observe(te, p.A)
                h_next = state.h if not integ.adaptive else res.state.h
                if h_cap > 0 and integ.adaptive:
                    h_next = min(h_next, h_cap)
                state = StepperState(te, np.concatenate((qn, qdn)), None, h_next)
                bar.update(t)
                if terminal:
                    status = Status.EVENT_TERMINATED
                    message = f"terminal event {label!r} at t = {te:.12g}"
                    break
                continue
            # no event: accept the step
            # requested times within end_tol after the step end are the step end (accumulated
            # round-off in t must not turn them into partial steps of the next step)
            _sample_t_eval(rec, t_out, out_i, t_start, t_new + end_tol, out_at, system)
            out_i = _advance_out(t_out, out_i, t_new + end_tol)
            if t_out is None and p1 is not None:
                rec.add(p1, system.active)
            rec.quad.commit(rec.quad.at(t_new))
            t = t_new
            gvals = new_g
            if passages is not None:
                passages.observe(t, p1.A if p1 is not None else
                                 model.constraint_terms(t, q1, qd1, system.active).A)  # fmt: skip
            changed = not (np.array_equal(q1, res.state.y[:n]) and np.array_equal(qd1, res.state.y[n:]))
            f_next = None if changed else res.state.f
            f_pow = P1_step if f_next is not None else float("nan")  # (FSAL: the last stage's)
            if f_next is None and p1 is not None and controller is None:
                # the full evaluation at the (projected) step end is F(t, y) of the next step
                f_next = np.concatenate((qd1, p1.qdd))
                f_pow = p1.power
            state = StepperState(t, np.concatenate((q1, qd1)), f_next, res.state.h)
            if controller is not None and hasattr(controller, "update"):
                system.cstate = _durable.user_call("controller.update", t, controller.update, t, q1, qd1,
                                                   system.cstate, active=system.active)
            bar.update(t)
    except KeyboardInterrupt as exc:  # Ctrl-C: keep what was computed
        counts = getattr(exc, "engine_counts", None)
        if counts is not None:  # inside an engine run: its steps (from the run's start or resume)
            n_steps = max(n_steps, counts[0])
            system.n_rhs += counts[1]
            n_rejected += counts[2]
        status = Status.INTERRUPTED
        message = f"interrupted (KeyboardInterrupt) after t = {rec.last_t(t0):.12g}"
    except Exception as exc:  # throw=False: any failure ends the run with a partial result
        if isinstance(exc, InputError | ModelError):  # raised mid-run: the state, not the arguments
            err: Exception = SimulationError(f"the simulation cannot go on after t = {rec.last_t(t0):.12g}: "
                                             f"{type(exc).__name__}: {exc}")
            err.__cause__ = exc
        else:
            err = exc
        if throw:
            bar.close()
            if err is exc:
                raise
            raise err from exc
        status = Status.FAILED
        message = f"{type(err).__name__}: {err}"
    finally:
        bar.close()
    result = snapshot(status, message)
    if status is Status.SUCCESS and t_out is None and prev is None:
        result = _kick_check(result)
    if result.events:  # the impulses of the impacts, by constraint name (sim/_impulses.py)
        result = replace(result, events=with_impulses(model, result.events, rank_rtol))
    if out.reactions and len(result):  # each constraint's wrench per sample (nonmin.analysis)
        result = result.with_reactions(model, None if out.reactions is True else out.reactions, rtol=rank_rtol)
    if ck_path is not None:  # the checkpoint ends as the whole run, whatever its status
        bar.write(result)
    return result


# --------------------------------------------------------------------------- helpers

#: A step whose velocity change departs from the trapezoidal rule ``½Δt(q̈₀ + q̈₁)`` by more
#: than this many times ``Δt·|q̈|`` (∞-norms, |q̈| the median over the neighbouring step ends)
#: is a kick, not a motion: smooth motion stays within ~(Δt·ω)²/12 of it, a discontinuous
#: input within ~1. Measured (issue 18,
#: crossed four-bar, RK4(passages=False), dt = 1e-3, θ0 = 5.5718870706804555, ω0 =
#: −6.483511434888186): the step from a step end 1.5e-6 rad before a change point reversed the
#: crank, θ̇ −4.75 → +15.6 rad/s (ratio 1.6e3), energy 90.4 → 325.8 J, then 3.1 rad off the branch.
KICK_RATIO = 10.0


def _kick_check(result: Trajectory) -> Trajectory:
    """Step-end samples (no ``t_eval``) whose velocity jumped between two step ends with no
    event between them (:data:`KICK_RATIO`): the run is marked FAILED with their times in
    ``metadata["velocity_kicks"]`` and a RuntimeWarning, instead of a silent "success"."""
    t, qd, qdd = result.t, result.qd, result.qdd
    if t.shape[0] < 2 or qd.shape[1] == 0:
        return result
    # (ndarray methods and slices: np.diff and np.max's wrappers cost more than the arithmetic
    # on a short run; the same values)
    dt = t[1:] - t[:-1]
    dv = np.abs((qd[1:] - qd[:-1]) - 0.5 * dt[:, None] * (qdd[1:] + qdd[:-1])).max(axis=1)
    # the acceleration level around each step: the median of |q̈|∞ over the 6 step ends
    # i−2 … i+3 (one wrong q̈ at a step end next to a singular instant, 19051 against 80
    # measured in the case of KICK_RATIO, must not set the scale; a jump of the input does not
    # move the median below half the larger level)
    a = np.abs(qdd).max(axis=1)
    floor = 1e-9 * (1.0 + np.abs(qd).max(axis=1)[1:])
    # every window's median is at least min(a) (rounding is monotone): when no step exceeds
    # the ratio against that lower scale, none exceeds it against the medians
    if bool((~(dt > 0.0) | (dv <= KICK_RATIO * (dt * a.min() + floor))).all()):
        return result
    pad = np.concatenate((np.full(2, a[0]), a, np.full(2, a[-1])))
    acc = np.median(np.lib.stride_tricks.sliding_window_view(pad, 6), axis=1)[: dt.shape[0]]
    scale = dt * acc + floor
    ok = ~(dt > 0.0) | (dv <= KICK_RATIO * scale)
    if result.events:  # an impact changes q̇ at its instant: the intervals touching it are exempt
        te = np.array([e.t for e in result.events])
        ok |= np.any((t[:-1, None] <= te[None, :]) & (te[None, :] <= t[1:, None]), axis=1)
    if bool(np.all(ok)):
        return result
    bad = np.flatnonzero(~ok)
    kicks = [float(t[i]) for i in bad]
    import warnings
    from dataclasses import replace

    msg = (f"the velocity jumped in {len(kicks)} step(s), first from t = {kicks[0]:.12g} "
           f"(|Δq̇ − Δt·q̈| = {float(dv[bad[0]]):.3g} against Δt·|q̈| = {float(scale[bad[0]]):.3g}): "
           "a step next to a singular configuration (a change of branch?); a smaller dt or "
           "the singular-passage placement (passages=True) avoids it")  # fmt: skip
    warnings.warn(msg, RuntimeWarning, stacklevel=3)
    meta = dict(result.metadata)
    meta["velocity_kicks"] = kicks
    return replace(result, status=Status.FAILED, message=msg, metadata=meta)



def model_mask(model: Model, active: frozenset[str]) -> NDArray[np.uint8]:
    """The active set as the engine's mask (one entry per constraint, declaration order)."""
    return model.active_mask(active)


@lru_cache(maxsize=64)
def _sorted_names(active: frozenset[str]) -> tuple[str, ...]:
    """An active set's names in sorted order (the metadata's; a run starts from one of a few)."""
    return tuple(sorted(active))


def _describe(model: Model) -> dict[str, Any]:
    """The model's description for a result's metadata (its top level a copy; the rest the
    model's own, shared by its runs: :meth:`Model.describe`)."""
    try:
        return dict(model.describe())
    except Exception:  # describe() is informative only
        return {"name": model.name, "type": type(model).__name__}


def _watches(events: tuple[Event, ...], active: frozenset[str], unilateral: tuple[str, ...]) -> list[_Watch]:
    out = [_Watch("user", e.name, e.direction, e) for e in events]
    for nm in unilateral:
        if nm in active:
            out.append(_Watch("release", nm, -1, None))
        else:
            out.append(_Watch("impact", nm, -1, None))
    return out


def _engine_watch(
    system: _System, watches: list[_Watch], gvals: list[float], disarmed: set[int], rearm_tol: float
) -> Callable[[float, FloatArray, FloatArray, FloatArray], bool] | None:
    """The user events' guards as the engine's watch (the contact guards are evaluated by the
    engine itself: :func:`_engine_guards`): at each projected step end ``(t, q, qd, f_c)``, True
    when a guard crossed (the step is then left to the general driver, which locates the
    crossing); else their values and the re-arming are updated as the driver does after an
    accepted step. None without user events."""
    user = [i for i, w in enumerate(watches) if w.kind == "user"]
    if not user:
        return None

    def check(t: float, q: FloatArray, qd: FloatArray, f_c: FloatArray) -> bool:
        z = np.zeros(0)
        p = _Point(t, q, qd, z, f_c, z, 0, 0.0, z, z, z, z, z, z, np.zeros(0, dtype=bool), 0.0)
        new_g = {i: _guard_value(system, watches[i], p) for i in user}
        for i in user:
            if _crossed(gvals[i], new_g[i], watches[i].direction) and id(watches[i].event) not in disarmed:
                return True
        for key in list(disarmed):  # re-arm user events whose guard left the zero band
            j = next((i for i in user if id(watches[i].event) == key), None)
            if j is None or abs(new_g[j]) > rearm_tol:
                disarmed.discard(key)
        for i in user:
            gvals[i] = new_g[i]
        return False

    return check


def _engine_guards(
    system: _System, watches: list[_Watch], gvals: list[float]
) -> tuple[list[int], list[tuple[bool, int, int, float]]]:
    """The contact watches as the engine's guards ``(release, constraint index, first active row,
    value)`` and their indices in ``watches``."""
    if all(w.kind == "user" for w in watches):
        return [], []
    model = system.model
    index = {c.name: i for i, c in enumerate(model.constraints)}
    rows = model.row_slices(system.active)
    idx: list[int] = []
    out: list[tuple[bool, int, int, float]] = []
    for i, w in enumerate(watches):
        if w.kind == "user":
            continue
        release = w.kind == "release"
        idx.append(i)
        out.append((release, index[w.name], rows[w.name].start if release else 0, float(gvals[i])))
    return idx, out


def _zeno_check(recent_events: list[float], te: float, zeno_window: float, zeno_max: int, label: str) -> None:
    """Raise ZenoError when more than ``zeno_max`` events fell within ``zeno_window`` before te."""
    while recent_events and recent_events[0] < te - zeno_window:
        recent_events.pop(0)
    if len(recent_events) > zeno_max:
        raise ZenoError(
            f"{len(recent_events)} events within {zeno_window:g} s before t = {te:.12g} "
            f"(last: {label!r}); Zeno accumulation not resolved — raise "
            "impact_velocity_threshold or zeno_max_events"
        )


def _mask_names(model: Model, mask: Any) -> frozenset[str]:
    """The active set of an engine mask (declaration order)."""
    return frozenset(c.name for c, a in zip(model.constraints, mask) if a)


def _past_root(gfun: Callable[[float], float], s: float, h: float, g0: float) -> float:
    """Nudge the located root to the side where the guard has left g0's sign (≤ 1e-13 s)."""
    if g0 == 0.0:
        return s
    sign0 = math.copysign(1.0, g0)
    g = gfun(s)
    step = EVENT_XTOL / 4
    tries = 0
    while g * sign0 > 0 and tries < 8 and s < h:
        s = min(h, s + step)
        g = gfun(s)
        step *= 2
        tries += 1
    return s


def _transition_text(w: _Watch) -> str:
    if w.kind == "user":
        assert w.event is not None
        return describe_transition(w.event.transition)
    return f"{w.kind} {w.name}"


def _advance_out(t_out: FloatArray | None, i: int, t: float) -> int:
    if t_out is None:
        return i
    while i < t_out.size and t_out[i] <= t:
        i += 1
    return i


#: A fixed-step run whose end lies within this fraction of the placed step from the predicted
#: singular instant ends by interpolation (:func:`_end_at_passage`; the engine loop's
#: ``PASSAGE_END_BAND``).
PASSAGE_END_BAND = 0.05


def _end_at_passage(
    integ: Integrator, passages: SingularPassages | None, stab: Stabilization, active: frozenset[str],
    state: StepperState, t1: float,
) -> float | None:  # fmt: skip
    """The step to take past ``t1`` when the run ends at a predicted singular instant, else None.

    A step ending on the singular configuration evaluates F there (the Gauss solution, not the
    limit along the branch: the crossed four-bar ending at a change point had q̇ off by up to
    5 m/s). When the placed step reaches past ``t1`` and ``t1`` lies within
    :data:`PASSAGE_END_BAND` of it from the predicted instant, the driver takes that step and
    ends on its quintic Hermite interpolant at ``t1``, projected as a sample (engine loop:
    ``end_star`` in ``run``)."""
    if integ.adaptive or passages is None or not isinstance(stab, Projection) or not active:
        return None
    ts = passages.t_star
    if ts is None or not ts > state.t:
        return None
    hp = passages.place(state.t, state.h)
    if _clip(state.t, hp, t1) != t1 - state.t or not state.t + hp > t1:
        return None
    return hp if abs(t1 - ts) <= PASSAGE_END_BAND * hp else None


def _fixed_step_dense(
    y0: FloatArray, f0: FloatArray, y1: FloatArray, f1: FloatArray, t0: float, h: float, t: float
) -> FloatArray:
    """Continuous extension of a fixed step between its projected ends, at time ``t``."""
    return hermite_quintic(y0, f0, y1, f1, h, t - t0)


def _sample_t_eval(
    rec: _Recorder,
    t_out: FloatArray | None,
    i: int,
    t_start: float,
    t_end: float,
    at: Callable[[float], _Point],
    system: _System,
) -> None:
    """Record the requested output times in ``(t_start, t_end]`` (from ``at``: continuous extension or partial step)."""
    if t_out is None:
        return
    while i < t_out.size and t_out[i] <= t_end:
        pt = at(float(t_out[i]) - t_start)
        rec.add(pt._replace(t=float(t_out[i])), system.active)
        i += 1


def _apply(system: _System, w: _Watch, p: _Point) -> tuple[FloatArray, FloatArray, frozenset[str], str, bool, float]:
    """Apply the transition of a user or release watch ``w`` at point ``p`` (contact impacts:
    :func:`_set_impact`).

    Returns (q, qd, active, label, terminal, h_cap) — h_cap > 0 caps the next adaptive step.
    """
    from ..core import impact_map

    model = system.model
    q, qd, act = p.q.copy(), p.qd.copy(), system.active
    if w.kind == "user":
        ev = w.event
        assert ev is not None
        tr = ev.transition
        if isinstance(tr, Activate):
            new = act | frozenset(tr.names)
            ct = model.constraint_terms(p.t, q, qd, new)
            if ct.A.shape[0]:
                qd = impact_map(model.mass_matrix(q), ct.A, qd, restitution=tr.restitution,
                                rtol=system.rank_rtol)
            if tr.restitution > 0.0:  # a bounce: unilateral constraints separate again
                new = new - frozenset(nm for nm in tr.names if model.constraint(nm).kind == "unilateral")
            act = new
        elif isinstance(tr, Deactivate):
            act = act - frozenset(tr.names)
        elif isinstance(tr, Reset):
            out = _durable.user_call(f"event {ev.name!r}: Reset fn", p.t, tr.fn, p.t, q, qd, act)
            if not (isinstance(out, tuple) and len(out) == 3):
                raise SimulationError(f"event {ev.name!r}: Reset fn must return (q, qd, active), got "
                                      f"{type(out).__name__} at t = {p.t:.12g}")
            q = _durable.finite_output(f"event {ev.name!r}: Reset fn q", p.t, out[0], (system.n,),
                                       system.model.coordinate_names)
            qd = _durable.finite_output(f"event {ev.name!r}: Reset fn qd", p.t, out[1], (system.n,),
                                        system.model.coordinate_names)
            act = model.resolve_active(out[2])
        return q, qd, act, ev.name, ev.terminal, 0.0
    # release: located just past the zero of the normal force, where the free gap acceleration
    # is zero up to round-off; refuse only if the free motion would clearly penetrate
    name = w.name
    a_free, a_scale = system.free_gap_acceleration_and_scale(p.t, q, qd, name)
    if a_free > -RELEASE_RTOL * a_scale:
        return q, qd, act - {name}, f"release:{name}", False, 0.0
    return q, qd, act, f"release-refused:{name}", False, 0.0


def _set_impact(
    system: _System,
    fired: list[str],
    plastic: frozenset[str],
    p: _Point,
    restitution: float | dict[str, float],
    v_thresh: float,
    dt_fixed: float,
) -> tuple[FloatArray, FloatArray, frozenset[str], str, bool, float]:
    """One impact over every unilateral contact closed at ``p`` (docs/theory.md,
    "Simultaneous impacts").

    The set: the contacts whose gap crossed (``fired``; ``plastic`` ones started inside the
    obstacle and get e = 0), the active (resting) ones, and inactive ones touching and not
    separating (gap ≤ 0, ``a qd ≤ 0``). Velocity: :func:`nonmin.core.simultaneous_impact`
    (Newton's law per contact in inequality form; resting contacts may reopen). A bounce too
    small to resolve (normal speed ≤ ``v_thresh`` or flight time ≤ ``2·dt_fixed``) is made
    plastic and the set solved again (the contacts so closed only grow). Contacts left at zero
    normal velocity stay active unless Gauss's principle with the contact inequalities
    (:func:`nonmin.core.polyhedral_projection` of the free acceleration) separates them.
    Returns (q, qd, active, label, terminal, h_cap) as :func:`_apply`.
    """
    from ..core import polyhedral_projection
    from ..core.impact import FEASIBILITY_RTOL

    model = system.model
    t, q, qd, act = p.t, p.q.copy(), p.qd.copy(), system.active
    own = {nm: _own_row(model, t, q, qd, nm) for nm in system.unilateral}
    contacts = [
        nm for nm in system.unilateral
        if nm in fired or nm in act or (own[nm][2] <= 0.0 and float(own[nm][0] @ qd) <= 0.0)
    ]  # fmt: skip
    bil = act - frozenset(contacts)
    ct_b = model.constraint_terms(t, q, qd, bil)
    Ab = ct_b.A
    Ac = np.array([own[nm][0] for nm in contacts])
    u = Ac @ qd
    e = np.array([0.0 if (nm in plastic or nm in act) else _restitution_of(restitution, nm) for nm in contacts])
    target = e * np.maximum(-u, 0.0)
    M = model.mass_matrix(q)
    mc = len(contacts)
    forced = np.zeros(mc, dtype=bool)  # small bounces made plastic (equality a_i v = 0)
    while True:
        free = ~forced
        res = polyhedral_projection(M, qd, np.vstack((Ab, Ac[forced])), np.zeros(Ab.shape[0] + int(forced.sum())),
                                    Ac[free], -target[free], rtol=system.rank_rtol)  # fmt: skip
        v = res.x
        un = Ac @ v
        scale = np.abs(Ac).sum(axis=1) * max(float(np.max(np.abs(v))), float(np.max(np.abs(qd))))
        closed = forced | (np.abs(un) <= FEASIBILITY_RTOL * scale)
        new_act = bil | frozenset(nm for nm, c in zip(contacts, closed) if c)
        saved = system.active
        system.active = new_act
        try:
            qdd = system.rhs(t, np.concatenate((q, v)))[system.n :]
        finally:
            system.active = saved
        gam_c = np.array([_own_row(model, t, q, v, nm)[1] for nm in contacts])  # Ȧ v at the new v
        a_gap = Ac @ qdd + gam_c
        flight = np.where(a_gap < 0.0, 2.0 * un / np.where(a_gap < 0.0, -a_gap, 1.0), np.inf)
        weak = ~closed & ((un <= v_thresh) | (flight <= 2.0 * dt_fixed))
        if not weak.any():
            break
        forced |= weak
    h_cap = 0.0
    bouncing = ~closed & np.isfinite(flight)
    if bouncing.any():
        h_cap = float(np.min(flight[bouncing])) / 4.0
    if closed.any():  # Gauss's principle with the closed contacts as inequalities
        saved = system.active
        system.active = bil
        try:
            qdd_free = system.rhs(t, np.concatenate((q, v)))[system.n :]
        finally:
            system.active = saved
        ct_b = model.constraint_terms(t, q, v, bil)
        acc = polyhedral_projection(M, qdd_free, ct_b.A, ct_b.gamma, Ac[closed], gam_c[closed],
                                    rtol=system.rank_rtol)  # fmt: skip
        keep = np.zeros(mc, dtype=bool)
        keep[np.flatnonzero(closed)] = acc.at_bound
        new_act = bil | frozenset(nm for nm, c in zip(contacts, keep) if c)
    else:
        new_act = bil
    label = "impact:" + "+".join(nm for nm in system.unilateral if nm in fired)
    return q, v, new_act, label, False, h_cap


class _Quiet:
    """A progress sink for the trial runs of :func:`_friction_step` (reports nothing)."""

    def update(self, t: float) -> None:
        pass


class _FrictionStep(NamedTuple):
    """What :func:`_friction_step` found in a step of a friction run with user events."""

    er: Any  # the accepted engine run (its samples given to the recorder)
    te: float  # the user events' instant (NaN: none; er is then a contact transition or the step)
    group: list[int]  # the user watches firing at te
    p: _Point | None  # the point at te before their transitions (friction applied)


def _friction_step(
    system: _System, run: Callable[[float, Callable[[dict[str, Any]], None]], Any],
    point: Callable[[float, FloatArray, FloatArray], _Point], watches: list[_Watch], gvals: list[float],
    disarmed: set[int], t0: float, h: float, n: int, sink: Callable[[dict[str, Any]], None],
) -> _FrictionStep:  # fmt: skip
    """The step from ``t0`` that the engine left to Python in a run with frictional contacts and
    user events (a guard crossed: a user one, or a contact/friction one while user guards are
    watched). The general driver has no friction, so the step is taken by the engine itself:
    ``run(s, sink)`` is its run from the step start over ``s`` (one step of the fixed-step
    methods, the partial step the event layer locates on; without user guards, so contact and
    friction events are located and applied by the engine's event layer).

    The whole step is run first. A contact/friction transition in it at ``te`` is accepted when
    no user guard has crossed by then (read at the state before it); otherwise the earliest user
    crossing before ``te`` (or in the step) is located by Brent's method on ``run(s)``'s end
    state, nudged past the root as the driver does, and the run up to it is accepted."""
    from scipy.optimize import brentq  # lazy: 0.4 s of import

    user = [i for i, w in enumerate(watches) if w.kind == "user" and id(w.event) not in disarmed]

    def crossed_at(pt: _Point) -> list[int]:
        return [i for i in user if _crossed(gvals[i], _guard_value(system, watches[i], pt), watches[i].direction)]

    blocks: list[dict[str, Any]] = []
    full = run(h, blocks.append)
    s_hi = h
    if full.handover or full.painleve is not None:  # the caller reports it
        for b in blocks:
            sink(b)
        return _FrictionStep(full, math.nan, [], None)
    if full.transition:
        d = full.events[0]
        te = float(d["t"])
        if not crossed_at(point(te, np.asarray(d["q_before"]), np.asarray(d["qd_before"]))):
            for b in blocks:
                sink(b)
            return _FrictionStep(full, math.nan, [], None)
        s_hi = te - t0
    elif not full.event and not full.handover and full.t == t0 + h:
        pe = point(full.t, full.y[:n], full.y[n:])
        if not crossed_at(pe):  # re-run without user guards: nothing crossed (the step stands)
            for b in blocks:
                sink(b)
            return _FrictionStep(full, math.nan, [], None)
    cache: dict[float, _Point] = {}

    def at(s: float) -> _Point:
        if s not in cache:
            r = run(s, lambda b: None)
            cache[s] = point(r.t, r.y[:n], r.y[n:])
        return cache[s]

    roots: list[tuple[float, int]] = []
    for i in crossed_at(at(s_hi)):

        def gfun(s: float, _w: _Watch = watches[i]) -> float:
            return _guard_value(system, _w, at(s))

        try:
            s_root = float(brentq(gfun, 0.0, s_hi, xtol=EVENT_XTOL, rtol=1e-15, maxiter=200))
        except ValueError:  # the start value lost its sign against the end: the end
            s_root = s_hi
        roots.append((_past_root(gfun, s_root, s_hi, gvals[i]), i))
    if not roots:  # not reproduced (a crossing and its return inside the step): the step stands
        for b in blocks:
            sink(b)
        return _FrictionStep(full, math.nan, [], None)
    roots.sort()
    best = roots[0][0]
    er = run(best, sink)
    group = [i for s_i, i in roots if s_i <= best + 4 * EVENT_XTOL]
    if er.transition or er.t != t0 + best:  # (a contact event inside the partial step after all)
        return _FrictionStep(er, math.nan, [], None)
    return _FrictionStep(er, er.t, group, point(er.t, er.y[:n], er.y[n:]))


def _friction_run(
    s: float, sink: Callable[[dict[str, Any]], None], *, er: Any, guards: list[tuple[bool, int, int, float]],
    slip: dict[str, tuple[float, ...]], opts: Any, t1: float, run_kw: dict[str, Any], controller: Any,
    eng_prog: Any, system: _System, h_fixed: float | None,
) -> Any:  # fmt: skip
    """The engine's run over ``s`` from the start ``(er.t, er.y)`` of the step a guard fired in,
    with the contact and friction guards and no user guards (:func:`_friction_step`)."""
    g0 = [(rel, c, row, float(er.guards[j])) for j, (rel, c, row, _) in enumerate(guards)]
    opts.t1 = min(t1, er.t + s)
    creg = _engine.compiled_controller(controller, system.model, eng_prog, system.active)
    ccb = _engine.ControllerCallback(controller, system.cstate, system.model.k, None, system.model) \
        if controller is not None and creg is None else None  # fmt: skip
    try:
        return _engine.run(
            run_kw["program"], opts=opts, active_mask=run_kw["active_mask"], t_out=run_kw["t_out"], sink=sink,
            progress=_Quiet(), controller=ccb, compiled=creg, guards=g0, contact=run_kw["contact"],
            resume=(er.t, er.y, min(er.h, s) if h_fixed is None else h_fixed, er.steps, er.out_i),
            friction=_friction.engine_contacts(system.model, slip), work0=er.friction_work, ctrl_work0=er.work,
        )  # fmt: skip
    finally:
        opts.t1 = t1


def _friction_after_user(
    model: Model, stab: Any, t: float, q: FloatArray, qd: FloatArray, active: frozenset[str], v_thresh: float,
    rank_rtol: float | None, system: _System, u: FloatArray | None,
) -> tuple[FloatArray, FloatArray, dict[str, tuple[float, ...]]]:  # fmt: skip
    """After a user transition in a friction run: the contacts' modes decided afresh (a sticking
    contact the transition set moving slips; :func:`_friction.initial_modes`, with the input
    ``u`` of the event's instant applied), the state projected onto the active set;
    ``system.active`` set."""
    proj = stab if isinstance(stab, Projection) else Projection()
    act = set(active)
    for fc in model.friction_contacts:  # moving at a sticking contact (a Reset): it slips
        if fc.tangent in act and fc.normal in act:
            At = model.constraint_terms(t, q, qd, frozenset({fc.tangent})).A
            if float(np.linalg.norm(At @ qd)) > v_thresh:
                act.discard(fc.tangent)
    new = frozenset(act)
    if new:
        q, qd = proj.project(model, t, q, qd, new, rank_rtol)
    act_f, slip = _friction.initial_modes(model, t, q, qd, new, v_thresh=v_thresh, rank_rtol=rank_rtol,
                                          bias=stab.bias,
                                          g_extra=None if u is None else model.input_matrix(q) @ u)  # fmt: skip
    if act_f != new and act_f:
        q, qd = proj.project(model, t, q, qd, act_f, rank_rtol)
    system.active = act_f
    return q, qd, dict(slip)


def _type_name(obj: Any) -> str:
    """``module.Type`` of a value, or the name of a plain function (run metadata)."""
    name = getattr(obj, "__qualname__", None)
    if callable(obj) and name is not None and not isinstance(obj, type):
        return f"{getattr(obj, '__module__', '?')}.{name}"
    t = type(obj)
    return f"{t.__module__}.{t.__qualname__}"
