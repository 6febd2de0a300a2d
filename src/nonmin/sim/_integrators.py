"""Integrators: immutable steppers with explicit state (``init`` / ``step``).

Every integrator works on a first-order system ``y' = F(t, y)`` with ``y = (q, qd)`` and knows
nothing about mechanics. Its evolving data live in a :class:`StepperState` value that is passed
in and returned; the objects themselves are frozen and can be shared between runs.

* :class:`RK4` — classical fixed-step Runge–Kutta, order 4 (``"rk4"``).
* :class:`DormandPrince5` — adaptive Dormand–Prince 5(4) with FSAL, PI-free standard step-size
  control and the continuous extension (``"dopri5"``); tableau from Dormand & Prince (1980),
  Hairer, Nørsett & Wanner, *Solving ODEs I*, Table II.5.2.
* :class:`DOP853` — adaptive Dormand–Prince 8(5,3) with its 7th-order continuous extension
  (``"dop853"``): fewer, longer steps at tight tolerances.
* :class:`RK8` — DOP853's 8th-order stages with a fixed step and no error estimate (``"rk8"``):
  the cheapest accurate steps at coarse dt on smooth motion.
* :class:`ImplicitMidpoint` — the symmetric, symplectic implicit midpoint rule, order 2
  (``"midpoint"``): bounded energy error over long runs.

:data:`METHODS` maps names to classes (like ``scipy.integrate._ivp.METHODS``).
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass
from typing import ClassVar, NamedTuple

import numpy as np
from numpy.typing import NDArray

from ..errors import InputError, NonminError, SimulationError
from . import _dop853_tableau as _D8

__all__ = [
    "DOP853",
    "METHODS",
    "RK4",
    "RK8",
    "DormandPrince5",
    "ImplicitMidpoint",
    "Integrator",
    "Projector",
    "SingularPassages",
    "StepResult",
    "StepperState",
    "hermite_quintic",
    "singular_indicator",
]

FloatArray = NDArray[np.float64]
RHS = Callable[[float, FloatArray], FloatArray]
Projector = Callable[[float, FloatArray], FloatArray]
Placer = Callable[[float, float], float]


class StepperState(NamedTuple):
    """Explicit state of a stepper.

    Attributes
    ----------
    t : float
        Current time.
    y : ndarray, shape (2n,)
        Current state ``(q, qd)``.
    f : ndarray, shape (2n,) or None
        ``F(t, y)`` if already known (first-same-as-last reuse), else None.
    h : float
        Step size proposed for the next step.
    """

    t: float
    y: FloatArray
    f: FloatArray | None
    h: float


class StepResult(NamedTuple):
    """Outcome of one accepted step.

    Attributes
    ----------
    state : StepperState
        State at the end of the step.
    h : float
        Size of the accepted step.
    n_rejected : int
        Attempts rejected by the error control before acceptance.
    dense : callable ``t -> y`` or None
        Continuous extension on ``[t_old, t_new]`` when the method has one.
    """

    state: StepperState
    h: float
    n_rejected: int
    dense: Callable[[float], FloatArray] | None


def hermite_quintic(
    y0: FloatArray, f0: FloatArray, y1: FloatArray, f1: FloatArray, h: float, s: float
) -> FloatArray:
    """Continuous extension of a fixed step of a second-order system: ``y(t₀ + s)``.

    ``y = (q, qd)``, ``f = F(t, y) = (qd, qdd)`` at both ends of a step of size ``h``
    (``0 ≤ s ≤ h``). ``q`` is the quintic Hermite interpolant of ``q, qd, qdd`` at both ends
    (interpolation error O(h⁶)), ``qd`` its time derivative (O(h⁵)), so the sample is as
    accurate as the O(h⁵) local error of a step of RK4. It replaces a partial step from the
    step start (three more right-hand sides) for the output samples of fixed-step methods;
    the stabilization then projects the sample onto the constraints as it does a step end.
    """
    out = np.empty(y0.shape[0])
    hermite_into(y0, f0, y1, f1, h, s, out)
    return out


def hermite_into(
    y0: FloatArray, f0: FloatArray, y1: FloatArray, f1: FloatArray, h: float, s: float,
    out: FloatArray,
) -> None:  # fmt: skip
    """:func:`hermite_quintic` into ``out`` (plain loops: the engine's ``hermite_quintic`` in
    ``engine/src/sim_integrators.cpp`` is this function in C++)."""
    n = y0.shape[0] // 2
    t = s / h
    t2 = t * t
    t3 = t2 * t
    t4 = t3 * t
    t5 = t4 * t
    b1 = 10.0 * t3 - 15.0 * t4 + 6.0 * t5
    b2 = t - 6.0 * t3 + 8.0 * t4 - 3.0 * t5
    b3 = -4.0 * t3 + 7.0 * t4 - 3.0 * t5
    b4 = 0.5 * (t2 - 3.0 * t3 + 3.0 * t4 - t5)
    b5 = 0.5 * (t3 - 2.0 * t4 + t5)
    d1 = 30.0 * t2 - 60.0 * t3 + 30.0 * t4
    d2 = 1.0 - 18.0 * t2 + 32.0 * t3 - 15.0 * t4
    d3 = -12.0 * t2 + 28.0 * t3 - 15.0 * t4
    d4 = t - 4.5 * t2 + 6.0 * t3 - 2.5 * t4
    d5 = 1.5 * t2 - 4.0 * t3 + 2.5 * t4
    hh = h * h
    for i in range(n):
        dq = y1[i] - y0[i]
        v0 = f0[i]
        v1 = f1[i]
        a0 = f0[n + i]
        a1 = f1[n + i]
        out[i] = y0[i] + dq * b1 + h * (v0 * b2 + v1 * b3) + hh * (a0 * b4 + a1 * b5)
        out[n + i] = (dq / h) * d1 + (v0 * d2 + v1 * d3) + h * (a0 * d4 + a1 * d5)


def _clip(t: float, h: float, t_bound: float) -> float:
    rem = t_bound - t
    if h >= rem or rem - h <= 1e-9 * h:
        return rem
    return h


# --------------------------------------------------------------------------- singular passages

#: Rows of A whose norm is at most this fraction of the largest one have vanished (rule 1 of the
#: rank policy, ``docs/theory.md``) and are left out of :func:`singular_indicator`.
PASSAGE_ROW_RTOL = 1e-10

#: Up to this many live rows :func:`singular_indicator` takes the smallest eigenvalue of the
#: Gram matrix from a dense symmetric eigensolver; above, from inverse iterations.
PASSAGE_DENSE_ROWS = 32

#: Inverse iterations of :func:`singular_indicator` (warm-started from the previous step end's
#: vector) stop when the Rayleigh quotient changes by at most :data:`PASSAGE_ITER_RTOL`
#: (relative), or after this many.
PASSAGE_MAX_ITERATIONS = 30
PASSAGE_ITER_RTOL = 1e-6

#: An indicator below this at a projected step end is a configuration at a singular point or
#: with a permanently redundant constraint (Bricard's mechanism: ~1e-8, the round-off of the
#: Gram matrix): no passage is predicted from it. Step ends placed around a passage stay at
#: least a quarter step from it, where the indicator is ≳ 1e-5 (A02 N = 2 at dt = 1e-4).
PASSAGE_FLOOR = 1e-7

#: Adaptive steps keep their ends out of ``|t − t*| < PASSAGE_ZONE_SIGMA/|dσ/dt|`` around a
#: predicted singular instant (:meth:`SingularPassages.zone`). Measured on the crossed four-bar
#: (4 s, rtol 1e-10, general driver): DOP853 energy drift 2.9e-5 / 3.1e-7 / 4.2e-7 / 9.5e-7 /
#: 6.8e-4 J with 1e-4 / 3e-4 / 1e-3 / 3e-3 / 1e-2 (too small: the forced crossing's stages sit
#: next to the instant; too large: long forced steps), DOPRI5 3.9e-7 / 4.2e-7 J with 1e-4 / 1e-3.
PASSAGE_ZONE_SIGMA = 1e-3

#: :class:`DormandPrince5` uses the zone with its half-width capped at ``PASSAGE_ZONE_STEP``
#: times the step it entered with: its forced crossing is then no longer than a step its error
#: control accepted. Without the zone DOPRI5 walked into A02 N = 40's passage at t = 3.2096 s
#: (rtol 1e-10: steps down to 1.4e-7 s, one kick of 1.2e-5 J, 10.3 s CPU over 20 s); with the
#: uncapped zone its forced step crossed 2d ≫ h and failed (rtol 1e-8, t = 4.4 s). Capped at
#: 0.5: 8.2e-7 J, 2.2 s CPU (A02 N = 2 rtol 1e-10: B0 5.8e-7 → 1.5e-8 m).
PASSAGE_ZONE_STEP = 0.5

#: Round-off of a projected state near a singular configuration, relative to ``eps·(1 + |y|)``
#: and divided by the indicator σ (the projection's sensitivity: the tangent space turns by
#: δq/σ): :class:`DormandPrince5` adds ``noise = PASSAGE_NOISE·eps/σ`` (× (1 + |y_i|)) to its
#: error scale, so that an error estimate of projected solutions at that level is not taken
#: for a truncation error (which made the step collapse to 1e-11 s a microsecond before A02's
#: first passage at rtol 1e-10).
PASSAGE_NOISE = 100.0

#: :meth:`SingularPassages.align`: a fixed step that starts within this fraction of a step of
#: the grid ``origin + k·dt`` is on it.
PASSAGE_ALIGN_RTOL = 1e-6

#: RK4 projects its stage states (position and velocity, the stabilization's projection) in a
#: step from which the predicted instant lies at most ``PASSAGE_STAGE_AHEAD`` steps ahead (this
#: step or the next holds it), or that lies nearer to it (``τ = σ/|dσ/dt|``, either side) than
#: both ``PASSAGE_STAGE_K`` steps and ``PASSAGE_STAGE_WINDOW`` times the motion's own time scale
#: ``‖q̇‖/‖q̈‖`` (from ``F(t, y)`` at the step start). Near a passage F's derivatives across the
#: constraint manifold grow like 1/τ, and an unprojected stage costs the step an error
#: ``e_x ≈ e_o·(τ₁/τ)^b`` (``e_o ∝ h⁵`` its own, b ≈ 2–3) while h ≪ τ: where projection pays
#: does not depend on h; where h/τ is not small it pays on the approach only (docs/theory.md,
#: "Projected RK4 stages near a singular passage", the derivation and the measurements; the
#: former ``30·|dσ/dt|·h > σ`` held on nearly every step at dt ≥ 1e-2).
PASSAGE_STAGE_AHEAD = 2.0
PASSAGE_STAGE_K = 30.0
PASSAGE_STAGE_WINDOW = 0.15

#: The step that holds a singular instant (fixed-step methods) is at least so long that its ends
#: and stages lie where the indicator is ≥ PASSAGE_SIGMA: ``H = max(h, PASSAGE_SIGMA /
#: (fractions[0]·|dσ/dt|))``, at most ``PASSAGE_WIDEN_MAX·h``. A projected state at indicator σ
#: carries a round-off velocity across the branch of ~eps/σ² (the projection holds it on the
#: level set of φ that round-off left, whose tangent turns like 1/σ²), which a step end next to
#: the instant turns into a kick that grows as the step shrinks (measured, A02 N = 2, one
#: passage from a 10 s run's state: +6.6e-9 / 4.1e-10 / 1.4e-11 / 1.1e-12 J at h = 2.5e-5 /
#: 5e-5 / 1e-4 / 2e-4). A longer passage step costs its samples (quintic Hermite over H) and
#: its own truncation error: 2e-4 measured best of 1e-4, 2e-4, 5e-4 (A02 N = 2, 10 s, samples
#: every 0.01 s, energy at dt 2.5e-4 / 1e-4 / 5e-5: 2.0e-11 / 7.3e-11 / 1.3e-10 J; 5e-4 gave
#: 1.3e-9 J at a sample inside the passage step of 1.4e-3 s). The cap ``PASSAGE_WIDEN_MAX = 2``
#: keeps H ∝ h, so the passage step's error falls with dt at the method's order: with 64 the
#: step was H = PASSAGE_SIGMA/(¼|σ̇|) whatever dt, and on A02 N = 40 (20 s, samples every 0.1 s)
#: its samples' energy stayed at 1.5e-5 J for dt 2e-3 and 1e-3; with 2: 2.2e-6 / 1.1e-7 J
#: (targets 1 and 2 of issue 18 unchanged: A02 N = 2 ≤ 1.3e-10 J, crossed four-bar ≤ 2.2e-8 J).
PASSAGE_SIGMA = 2e-4
PASSAGE_WIDEN_MAX = 2.0

#: The indicator *decreases* (a passage is predicted) only when it falls by more than this
#: fraction per step end: a constant σ_min that changes by round-off (A01, one row: σ = 1 ±
#: eps) gave a quadratic root next to t and a passage zone of half-width 1e-3/(eps/h), whose
#: forced step jumped DOP853 over the rest of the run (A01, 2000 s, rtol 1e-10,
#: ``Projection(energy=True)``: one step from t = 1748.6 s to the end, energy 2.4e93 J,
#: reported SUCCESS; after: 5.3e-15 J).
PASSAGE_TREND = 1e-9


#: Adaptive methods take an output sample inside a step from a partial step of the method from
#: the step start (projected as a step end), not from the continuous extension, unless the step
#: holds a predicted singular instant (the extension keeps the stages off it; the engine's
#: ``Options.partial_samples``, set from this constant). The extension's
#: error is not controlled: measured, A02 N = 40, 20 s, samples every 0.1 s, rtol 1e-10 (atol
#: rtol/100), energy error at the samples / at the step ends: DOPRI5 8.2e-7 / 2.6e-7 J, DOP853
#: 1.8e-7 / 1.0e-7 J (rtol 1e-12: 1.7e-8 / 3.7e-9 J); with partial steps the samples are at the
#: step ends' level (2.6e-7, 1.0e-7, 6.7e-9 J) for 6–15 % more evaluations.
ADAPTIVE_PARTIAL_SAMPLES = True


def _passage_start(m: int) -> FloatArray:
    """Deterministic start vector of the inverse iteration (not symmetric: the mechanisms are)."""
    return 1.0 + 0.5 * np.sin(1.0 + np.arange(m, dtype=float))


def singular_indicator(A: FloatArray, v: FloatArray | None = None) -> tuple[float, FloatArray | None]:
    """Estimate of ``σ_min(D A)``, the smallest singular value of the row-equilibrated A.

    ``D A`` has unit rows (vanished rows, :data:`PASSAGE_ROW_RTOL`, left out), so its largest
    singular value lies in ``[1, √m]`` and ``σ_min`` is the relative distance to a rank drop.
    Computed as ``√λ_min`` of the Gram matrix ``G = (DA)(DA)ᵀ``: up to
    :data:`PASSAGE_DENSE_ROWS` live rows by a symmetric eigensolver, above by inverse
    iterations (Cholesky of G) from ``v`` (the vector of the previous call) or a fixed start
    until the Rayleigh quotient (an upper bound of λ_min) settles; returns the estimate and the
    vector to pass next time. 0 when G is not positive definite (a singular or redundant A).
    The engine (``engine/src/sim_integrators.cpp``, ``singular_indicator``) computes the same;
    up to :data:`PASSAGE_DENSE_ROWS` rows by tridiagonalization and Newton's method on
    ``det(T − xI)`` from 0 (``sym_min_eigenvalue``), equal to ``eigvalsh``'s to round-off.
    """
    m = A.shape[0]
    if m == 0:
        return math.inf, None
    norms = np.sqrt(np.einsum("ij,ij->i", A, A))
    big = float(norms.max())
    if not (big > 0.0 and math.isfinite(big)):
        return 0.0, None
    live = norms > PASSAGE_ROW_RTOL * big
    B = A[live] / norms[live, None]
    G = B @ B.T
    k = B.shape[0]
    if k <= PASSAGE_DENSE_ROWS:
        return math.sqrt(max(float(np.linalg.eigvalsh(G)[0]), 0.0)), None
    try:
        L = np.linalg.cholesky(G)
    except np.linalg.LinAlgError:
        return 0.0, None
    x = v if v is not None and v.shape == (k,) else _passage_start(k)
    x = x / np.linalg.norm(x)
    lam = math.inf
    for _ in range(PASSAGE_MAX_ITERATIONS):
        y = np.linalg.solve(L.T, np.linalg.solve(L, x))
        ny = float(np.linalg.norm(y))
        if not (ny > 0.0 and math.isfinite(ny)):
            return 0.0, None
        prev, lam = lam, float(x @ y) / (ny * ny)  # Rayleigh quotient of y: yᵀx / yᵀy
        x = y / ny
        if abs(lam - prev) <= PASSAGE_ITER_RTOL * lam:
            break
    return math.sqrt(max(lam, 0.0)), x


class SingularPassages:
    """Singularity-aware step placement: predict the next singular instant, keep stages off it.

    Near a configuration where A loses rank (a singular or change-point configuration) the
    right-hand side ``F(q, q̇)`` is smooth *along* the motion but its derivatives *across* the
    constraint manifold grow like ``1/σ_min(A)``: an RK stage (off the manifold by the method's
    error) or a step end that falls within round-off distance of the singular instant gets a
    kick (measured before: A02 N = 2, RK4 at dt = 2e-4, one stage 3e-9 s from it: B0 error
    3.6e-6 m instead of ~1e-11). With every stage at a distance proportional to h from the
    singular instant the error of the step that crosses it scales like that of any step.

    The driver calls :meth:`observe` at every projected step end with the active A (the
    indicator :func:`singular_indicator`); from the last two or three values, decreasing, the
    zero of ``σ_min(t)`` is extrapolated (linear, then quadratic through three). :meth:`place`
    then shortens the step so that the predicted instant falls at one of the method's
    ``fractions`` of a step — the middle of the largest gaps between its stage nodes (RK4 and
    the implicit midpoint: 1/4 and 3/4; DOPRI5: 0.45–0.65, between its nodes 0.3 and 0.8) —
    either of this step or, with the nominal step, of the next one. At most one step per
    passage is added, and one more after it: fixed steps then return to their grid
    (:meth:`align`). The engine loop implements the same rules (``sim_integrators.cpp``,
    ``sim_loop.cpp``).
    """

    def __init__(self, fractions: tuple[float, ...], *, widen: bool = False) -> None:
        self.fractions = tuple(sorted(fractions))
        self.widen = widen  # fixed-step methods: the passage step is ≥ PASSAGE_SIGMA wide
        self._t: list[float] = []
        self._s: list[float] = []
        self._v: FloatArray | None = None
        self.t_star: float | None = None
        self.sigma = math.inf  # the last indicator observed
        self._last: tuple[float, float] | None = None  # (t, σ) observed last, across passages
        self.rate = 0.0  # |dσ/dt| between the last two observations
        self.origin: float | None = None  # fixed steps return to the grid origin + k·dt (align)

    def reset(self) -> None:
        """Forget the history (a new active set, or a state reached elsewhere)."""
        self._t.clear()
        self._s.clear()
        self._v = None
        self.t_star = None
        self.sigma = math.inf
        self._last = None
        self.rate = 0.0

    @property
    def noise(self) -> float:
        """Relative round-off level of a projected state at the last step end
        (:data:`PASSAGE_NOISE`)."""
        if not (math.isfinite(self.sigma) and self.sigma >= PASSAGE_FLOOR):
            return 0.0  # below the floor: a permanently redundant row (Bricard), no passage
        return PASSAGE_NOISE * float(np.finfo(float).eps) / self.sigma

    def __call__(self, t: float, h: float) -> float:
        """:meth:`place`, then :meth:`align` (the object is the ``place`` argument of
        :meth:`Integrator.step`; adaptive methods have no grid, ``origin`` None)."""
        return self.align(t, h, self.place(t, h))

    def observe(self, t: float, A: FloatArray) -> None:
        """Record the indicator at a projected step end ``t`` with the active rows ``A``."""
        s, self._v = singular_indicator(A, self._v)
        self.sigma = s
        if not (s >= PASSAGE_FLOOR and math.isfinite(s)):
            self._t.clear()
            self._s.clear()
            self.t_star = None
            self._last = None
            self.rate = 0.0
            return
        last = self._last
        self.rate = abs(s - last[1]) / (t - last[0]) if last is not None and t > last[0] else 0.0
        self._last = (float(t), s)
        if (self._t and not t > self._t[-1]) or (self.t_star is not None and t >= self.t_star):
            self._t.clear()  # a new time line, or the predicted passage is behind: the
            self._s.clear()  # values across it are not one smooth branch of σ_min(t)
        self._t.append(float(t))
        self._s.append(s)
        if len(self._t) > 3:
            del self._t[0], self._s[0]
        self.t_star = passage_time(self._t, self._s)

    def place(self, t: float, h: float) -> float:
        """The step to take from ``t`` instead of ``h`` (≤ h) given the predicted instant."""
        H = h
        if self.widen and self.rate > 0.0:
            H = min(max(h, PASSAGE_SIGMA / (self.fractions[0] * self.rate)), PASSAGE_WIDEN_MAX * h)
        return place_step(self.t_star, t, h, self.fractions, H)

    def align(self, t: float, h: float, hp: float) -> float:
        """The fixed step ``hp = place(t, h)``, or — when the placement left it at ``h`` and no
        instant is predicted ahead — the step to the next point of the grid ``origin + k·h``
        (the run's ``t_span`` start) if ``t`` is off it by more than
        :data:`PASSAGE_ALIGN_RTOL` of a step: a placed or widened step (or an event) before
        moved the steps off the grid, and output samples on it (``t_eval`` every ``h`` or a
        multiple) would otherwise fall inside every later step, each costing a projection and
        an evaluation more. The engine loop: ``passage_align``."""
        if self.origin is None or hp != h or not h > 0.0:
            return hp
        if self.t_star is not None and self.t_star > t:
            return hp
        r = (t - self.origin) / h
        k = float(math.floor(r))
        if r - k <= PASSAGE_ALIGN_RTOL or (k + 1.0) - r <= PASSAGE_ALIGN_RTOL:
            return hp
        return (self.origin + (k + 1.0) * h) - t

    def stages(self, t: float, h: float, f: FloatArray) -> bool:
        """Whether the step of size ``h`` from ``t`` projects its stage states, ``f = F(t, y)``
        (:data:`PASSAGE_STAGE_AHEAD`, :data:`PASSAGE_STAGE_K`, :data:`PASSAGE_STAGE_WINDOW`)."""
        if not (math.isfinite(self.sigma) and self.sigma >= PASSAGE_FLOOR):
            return False
        if self.t_star is not None and t < self.t_star and self.t_star - t <= PASSAGE_STAGE_AHEAD * h:
            return True
        if not PASSAGE_STAGE_K * self.rate * h > self.sigma:
            return False
        n = f.shape[0] // 2
        v2 = a2 = 0.0
        for i in range(n):  # (the engine's order of summation: the same decision bit for bit)
            v2 += float(f[i]) * float(f[i])
            a2 += float(f[n + i]) * float(f[n + i])
        return self.sigma * math.sqrt(a2) < PASSAGE_STAGE_WINDOW * self.rate * math.sqrt(v2)

    def holds(self, t: float, h: float) -> bool:
        """Whether the step of size ``h`` from ``t`` holds the predicted singular instant
        (adaptive methods then take its output samples from the continuous extension)."""
        return self.t_star is not None and t < self.t_star and self.t_star - t <= (1.0 + PASSAGE_BAND) * h

    def zone(self, t: float, h: float, d_cap: float = math.inf) -> tuple[float, bool]:
        """DOP853: the step to attempt so that no step ends within the zone
        ``|t − t*| < d`` of the predicted instant, ``d = PASSAGE_ZONE_SIGMA/|dσ/dt|``, and whether
        it is *forced* (it crosses the zone from its near edge: the error control accepts it,
        since any shorter attempt ends inside). A step end there gets its velocity from a
        projection whose tangent turns by (position error)/σ, and an error control that shrinks
        the steps walks them into it (measured, crossed four-bar, DOP853 at rtol 1e-10: steps
        down to 2e-8 s, ends at σ ~ 2e-6, energy kicks of 1.9e-5 J). With DOPRI5 it helped A02
        N = 2 (B0 5.8e-7 → 1.5e-8 m at rtol 1e-10) but made A02 N = 40 fail (t = 4.54 s, rtol
        1e-8) when uncapped: DOPRI5 passes ``d_cap`` (:data:`PASSAGE_ZONE_STEP`). The engine
        computes the same (``passage_zone``)."""
        if self.t_star is None or len(self._t) < 2:
            return h, False
        slope = (self._s[-2] - self._s[-1]) / (self._t[-1] - self._t[-2])
        g = self.t_star - t
        if not (slope > 0.0 and math.isfinite(slope)) or not g > 0.0:
            return h, False
        d = min(PASSAGE_ZONE_SIGMA / slope, d_cap)
        end = g - h
        if end >= d or end <= -d:
            return h, False
        if g - d >= 0.2 * h:
            return g - d, False
        return g + d, True


def passage_time(ts: list[float], ss: list[float]) -> float | None:
    """Extrapolated zero of ``σ_min(t)`` from its values at the last step ends (None unless
    it decreases over the last two): the root ahead of the quadratic through three
    decreasing values when it has one, else the linear extrapolation of the last two."""
    if len(ts) < 2 or not ss[-1] < (1.0 - PASSAGE_TREND) * ss[-2]:
        return None
    t0, t1, s0, s1 = ts[-2], ts[-1], ss[-2], ss[-1]
    lin = t1 + s1 * (t1 - t0) / (s0 - s1)
    if len(ts) < 3 or not ss[-2] < (1.0 - PASSAGE_TREND) * ss[-3]:
        return lin
    # Newton form of the quadratic through the three points, root nearest after t1
    ta, sa = ts[-3], ss[-3]
    d1 = (s0 - sa) / (t0 - ta)
    d2 = (s1 - s0) / (t1 - t0)
    c2 = (d2 - d1) / (t1 - ta)
    # s(t) = s1 + b (t − t1) + c2 (t − t1)², b = slope at t1
    b = d2 + c2 * (t1 - t0)
    if c2 == 0.0:
        return lin
    disc = b * b - 4.0 * c2 * s1
    if disc < 0.0:
        return lin
    r = math.sqrt(disc)
    roots = [x for x in ((-b - r) / (2.0 * c2), (-b + r) / (2.0 * c2)) if x > 0.0]
    if not roots:
        return lin
    return t1 + min(roots)


#: A predicted singular instant within this fraction of a step of one of the method's
#: ``passage_fractions`` counts as placed (the prediction moves by a little at every step end:
#: without this band each one would shorten the step again).
PASSAGE_BAND = 0.05


def place_step(
    t_star: float | None, t: float, h: float, fractions: tuple[float, ...], H: float | None = None
) -> float:
    """Largest step ``s ≤ h`` from ``t`` that puts ``t_star`` at one of ``fractions`` of this
    step, or ends it so that the next step of size h has it there (ends at least 0.2 h long);
    ``h`` when ``t_star`` is beyond reach (more than ``(1 + max fraction) h`` ahead), behind,
    or already within :data:`PASSAGE_BAND` of a fraction of this step or the next.

    With a passage step ``H > h`` (:data:`PASSAGE_SIGMA`): ``H`` when ``t_star`` lies within
    the band of a fraction of it; else the step (≤ h) that ends where such a step of size H
    starts, ``h`` while that is farther (halved when less than 0.2 h would be left); when
    ``t_star`` is nearer than ``fractions[0]·H``, a step ≤ H that holds it at a fraction."""
    if t_star is None:
        return h
    if H is not None and H > h:
        g = t_star - t
        if not (g > 0.0):
            return h
        x = g / H
        if any(abs(x - c) <= PASSAGE_BAND for c in fractions):
            return H
        ahead = [g - c * H for c in fractions if g - c * H > 0.0]
        if ahead:
            fit = [d for d in ahead if d <= h]
            if fit:
                return max(fit)
            d = min(ahead)
            return h if d - h >= 0.2 * h else 0.5 * d
        fit = [g / c for c in fractions if g / c <= H]
        return max(fit) if fit else h
    g = t_star - t
    if not (g > 0.0) or g > (1.0 + fractions[-1] + PASSAGE_BAND) * h:
        return h
    x = g / h
    if any(abs(x - c) <= PASSAGE_BAND or abs(x - 1.0 - c) <= PASSAGE_BAND for c in fractions):
        return h
    best = 0.0
    for c in fractions:
        s = g / c
        if s <= h:
            best = max(best, s)
        s = g - c * h
        if 0.2 * h <= s <= h:
            best = max(best, s)
    return best if best > 0.0 else h


class Integrator(ABC):
    """Abstract integrator. Subclasses are frozen dataclasses.

    Class attributes
    ----------------
    name : str
        Registered name.
    order : int
        Classical order of accuracy.
    adaptive : bool
        Whether the step size is chosen by error control.
    """

    name: ClassVar[str] = ""
    order: ClassVar[int] = 0
    adaptive: ClassVar[bool] = False

    def init(self, fun: RHS, t0: float, y0: FloatArray, h0: float) -> StepperState:
        """Initial stepper state (``h0``: first step size, or the fixed step)."""
        return StepperState(t=float(t0), y=np.array(y0, dtype=float), f=None, h=float(h0))

    @abstractmethod
    def advance(self, fun: RHS, t: float, y: FloatArray, f: FloatArray | None, h: float) -> FloatArray:
        """One raw step of size ``h`` from ``(t, y)`` (no error control); returns ``y(t + h)``.

        Used for partial steps (event location, output at requested times) so that the
        located state is exactly what the method produces.
        """

    #: Fractions of a step at which a singular instant is placed (:class:`SingularPassages`):
    #: the middles of the largest gaps between the stage nodes.
    passage_fractions: ClassVar[tuple[float, ...]] = (0.25, 0.75)
    #: Fixed-step methods: the step that holds a singular instant is widened to
    #: :data:`PASSAGE_SIGMA` (:class:`SingularPassages`, ``widen``); not for :class:`RK8`.
    widen_passages: ClassVar[bool] = True

    @abstractmethod
    def step(
        self, fun: RHS, state: StepperState, t_bound: float, project: Projector | None = None,
        place: Placer | None = None,
    ) -> StepResult:  # fmt: skip
        """Take one accepted step, never beyond ``t_bound``.

        ``project(t, y) -> y`` (optional) is the stabilization's projection; adaptive methods
        measure their error estimate on projected solutions (see :class:`DormandPrince5`).
        ``place(t, h) -> h'`` (optional, a :class:`SingularPassages`) shortens a step
        attempt so that no stage falls next to a predicted singular instant; its ``noise``
        attribute (if any) widens an adaptive method's error scale by the projection's
        round-off level.
        """


def _fixed_step(
    method: Integrator, fun: RHS, state: StepperState, t_bound: float, project: Projector | None,
    place: Placer | None,
) -> StepResult:  # fmt: skip
    """One fixed step of ``method``; next to a singular passage (``method`` RK4, ``place`` a
    :class:`SingularPassages` whose :meth:`~SingularPassages.stages` holds) the step is RK4's
    with its stage states projected by ``project`` (the engine loop: ``rk4_advance`` with
    ``Loop::stage_proj``)."""
    t = state.t
    h = _clip(t, state.h if place is None else place(t, state.h), t_bound)
    f = state.f
    stages = False
    if project is not None and isinstance(place, SingularPassages) and isinstance(method, RK4):
        if f is None:
            f = fun(t, state.y)  # (the decision reads F(t, y); the step reuses it as its first stage)
        stages = place.stages(t, h, f)
    if not stages:
        y1 = method.advance(fun, t, state.y, f, h)
    else:
        assert f is not None and project is not None
        y = state.y
        k1 = f
        k2 = fun(t + 0.5 * h, project(t + 0.5 * h, y + 0.5 * h * k1))
        k3 = fun(t + 0.5 * h, project(t + 0.5 * h, y + 0.5 * h * k2))
        k4 = fun(t + h, project(t + h, y + h * k3))
        y1 = y + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
    t1 = t_bound if h == t_bound - t else t + h
    return StepResult(StepperState(t1, y1, None, state.h), h, 0, None)


@dataclass(frozen=True)
class RK4(Integrator):
    """Classical 4th-order Runge–Kutta with a fixed step ``dt`` (4 RHS calls per step).

    With ``passages=True`` (default) the steps next to a predicted singular instant are placed
    so that it falls at 1/4 or 3/4 of a step (:class:`SingularPassages`): at most one step per
    passage is shortened, and the first step after it ends on the grid ``t0 + k·dt`` again
    (:meth:`SingularPassages.align`), the others keep ``dt``; the step that holds the instant is at least
    :data:`PASSAGE_SIGMA` wide (in σ_min), and the steps near the instant project their stage
    states (:data:`PASSAGE_STAGE_WINDOW`). Measured (A02 N = 2, 10 s, samples every 0.01 s,
    engine loop, reference at rtol 1e-13): B0 error 2.0e-11 / 4.9e-11 / 9.9e-11 m and energy drift
    2.0e-11 / 7.3e-11 / 1.3e-10 J at dt = 2.5e-4 / 1e-4 / 5e-5; crossed four-bar, 10 s:
    energy 2.2e-8 / 2.0e-9 / 7.0e-10 / 2.7e-10 / 2.7e-11 J at dt 1e-3 / 7e-4 / 5e-4 / 2.5e-4 /
    1e-4 (without the placement: 6.5e-10, 8.7e-7, 1.6e-3, 1.6e-4 m on A02 at 2.5e-4 … 5e-5: a
    stage within ~1e-8 s of a singular instant).
    """

    dt: float | None = None
    passages: bool = True

    name: ClassVar[str] = "rk4"
    order: ClassVar[int] = 4
    adaptive: ClassVar[bool] = False

    def advance(self, fun: RHS, t: float, y: FloatArray, f: FloatArray | None, h: float) -> FloatArray:
        k1 = fun(t, y) if f is None else f
        k2 = fun(t + 0.5 * h, y + 0.5 * h * k1)
        k3 = fun(t + 0.5 * h, y + 0.5 * h * k2)
        k4 = fun(t + h, y + h * k3)
        return y + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)

    def step(
        self, fun: RHS, state: StepperState, t_bound: float, project: Projector | None = None,
        place: Placer | None = None,
    ) -> StepResult:  # fmt: skip
        """One step (:func:`_fixed_step`)."""
        return _fixed_step(self, fun, state, t_bound, project, place)


@dataclass(frozen=True)
class ImplicitMidpoint(Integrator):
    """Implicit midpoint rule ``y₁ = y₀ + h F(t + h/2, (y₀ + y₁)/2)`` with a fixed step.

    Symmetric and symplectic (order 2): for conservative systems the energy error stays
    bounded instead of drifting. The implicit equation is solved by fixed-point iteration to
    ``xtol`` (relative); when it does not converge in ``max_iter`` iterations (near a change
    point the contraction condition ``h·‖∂F/∂y‖ < 2`` fails) the step is taken as two half
    steps, recursively up to ``max_halvings`` times, then
    :class:`~nonmin.errors.SimulationError` is raised. Limitation (measured, dt = 5e-4 s,
    10 s): at the exact singular configurations of A02 and the crossed four-bar ``‖∂F/∂y‖`` is
    unbounded and no sub-step converges with the default rank tolerance (1e-10). With
    ``rank_rtol=1e-5`` both pass (A02: q error 2.9e-6, energy drift 9.6e-5 J; crossed four-bar:
    8.0e-5, 3.1e-4 J), with 1e-6 the crossed four-bar loses accuracy (q error 0.12): prefer
    ``"rk4"`` through singular configurations. ``passages`` as for :class:`RK4`.
    """

    dt: float | None = None
    xtol: float = 1e-13
    max_iter: int = 50
    max_halvings: int = 12
    passages: bool = True

    name: ClassVar[str] = "midpoint"
    order: ClassVar[int] = 2
    adaptive: ClassVar[bool] = False

    def advance(self, fun: RHS, t: float, y: FloatArray, f: FloatArray | None, h: float) -> FloatArray:
        return self._advance(fun, t, y, f, h, self.max_halvings)

    def _solve(self, fun: RHS, t: float, y: FloatArray, f: FloatArray | None, h: float) -> FloatArray | None:
        f0 = fun(t, y) if f is None else f
        tm = t + 0.5 * h
        k = fun(tm, y + 0.5 * h * f0)  # explicit midpoint predictor
        scale = 1.0 + float(np.max(np.abs(y)))
        prev = np.inf
        for it in range(self.max_iter):
            try:
                k_new = fun(tm, y + 0.5 * h * k)
            except (NonminError, ArithmeticError):  # the iteration left the model's domain
                return None
            delta = float(np.max(np.abs(k_new - k))) * abs(h)
            if not np.isfinite(delta) or (it >= 3 and delta > prev):
                return None  # diverging
            k = k_new
            if delta <= self.xtol * scale:
                return y + h * k
            prev = delta
        return None

    def _advance(
        self, fun: RHS, t: float, y: FloatArray, f: FloatArray | None, h: float, depth: int
    ) -> FloatArray:
        y1 = self._solve(fun, t, y, f, h)
        if y1 is not None:
            return y1
        if depth <= 0:
            raise SimulationError(
                f"implicit midpoint: fixed-point iteration did not converge in {self.max_iter} "
                f"iterations at t = {t:.12g} even with the step halved {self.max_halvings} times "
                f"(h = {h:.3g}); at an exact change point of a mechanism (crossed four-bar) use "
                "method='rk4' with the projection"
            )
        # the iteration contracts only for h·‖∂F/∂y‖ < 2, which fails near change points
        # (∂F/∂y ∝ 1/σ_min(A)): take two half steps instead, the driver's grid is unchanged
        ym = self._advance(fun, t, y, f, 0.5 * h, depth - 1)
        return self._advance(fun, t + 0.5 * h, ym, None, 0.5 * h, depth - 1)

    def step(
        self, fun: RHS, state: StepperState, t_bound: float, project: Projector | None = None,
        place: Placer | None = None,
    ) -> StepResult:  # fmt: skip
        """One step (:func:`_fixed_step`)."""
        return _fixed_step(self, fun, state, t_bound, project, place)


def _initial_step(
    fun: RHS, t0: float, y0: FloatArray, f0: FloatArray, t_bound: float, rtol: float, atol: float,
    h_max: float, order: int,
) -> float:  # fmt: skip
    """Hairer's starting-step heuristic (Solving ODEs I, II.4) for a method of ``order``."""
    scale = atol + rtol * np.abs(y0)
    d0 = float(np.sqrt(np.mean((y0 / scale) ** 2)))
    d1 = float(np.sqrt(np.mean((f0 / scale) ** 2)))
    h0 = 1e-6 if d0 < 1e-5 or d1 < 1e-5 else 0.01 * d0 / d1
    h0 = min(h0, abs(t_bound - t0))
    y1 = y0 + h0 * f0
    f1 = fun(t0 + h0, y1)
    d2 = float(np.sqrt(np.mean(((f1 - f0) / scale) ** 2))) / h0
    h1 = max(1e-6, h0 * 1e-3) if max(d1, d2) <= 1e-15 else (0.01 / max(d1, d2)) ** (1 / order)
    return float(min(100 * h0, h1, h_max))


# Dormand–Prince 5(4) tableau (Hairer, Nørsett & Wanner, Solving ODEs I, Table II.5.2).
_DP_C = np.array([0.0, 1 / 5, 3 / 10, 4 / 5, 8 / 9, 1.0, 1.0])
_DP_A = [
    np.array([]),
    np.array([1 / 5]),
    np.array([3 / 40, 9 / 40]),
    np.array([44 / 45, -56 / 15, 32 / 9]),
    np.array([19372 / 6561, -25360 / 2187, 64448 / 6561, -212 / 729]),
    np.array([9017 / 3168, -355 / 33, 46732 / 5247, 49 / 176, -5103 / 18656]),
    np.array([35 / 384, 0.0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84]),
]
_DP_B = np.array([35 / 384, 0.0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84, 0.0])
_DP_BHAT = np.array(
    [5179 / 57600, 0.0, 7571 / 16695, 393 / 640, -92097 / 339200, 187 / 2100, 1 / 40]
)
_DP_E = _DP_B - _DP_BHAT
# Continuous extension (Shampine 1986 / Hairer's dopri5 "dense" coefficients).
_DP_D = np.array(
    [
        -12715105075 / 11282082432,
        0.0,
        87487479700 / 32700410799,
        -10690763975 / 1880347072,
        701980252875 / 199316789632,
        -1453857185 / 822651844,
        69997945 / 29380423,
    ]
)


@dataclass(frozen=True)
class DormandPrince5(Integrator):
    """Adaptive explicit Runge–Kutta 5(4) of Dormand & Prince with dense output.

    Error per step is measured in the RMS norm of ``err_i / (atol + rtol·max(|y0_i|, |y1_i|))``
    and the step is accepted when it is ≤ 1; the next step is ``h·min(5, max(0.2, 0.9·err^(-1/5)))``.
    When the driver passes a projection (post-step stabilization), ``err`` is the difference of
    the *projected* 5th- and 4th-order solutions: the error of what is kept. Near a change point
    the raw estimate is dominated by huge off-manifold stage accelerations (∝ 1/σ_min(A)) that
    the projection removes; measured on the crossed four-bar (rtol 1e-8, first change point):
    raw estimate → steps collapse to 1e-10 s; projected → 20 steps, min step 1.3e-3 s.
    Limitation (measured, 10 s, library models, atol = rtol/100): the crossed four-bar (22
    change points) passes at rtol 1e-6 / 1e-8 / 1e-9 (343 / 872 / 1328 steps, q error
    2.0e-4 / 2.4e-5 / 4.2e-6, energy drift 1.3e-3 / 4.0e-5 / 6.6e-6 J) but rtol 1e-10 underflows
    at t = 3.3 s; A02 (N = 2) passes at rtol 1e-8 (459 steps, q error 8.7e-7) but not at 1e-9
    (the first singular configuration, t = 0.714 s). Error control cannot see past the
    1/σ_min blow-up of off-manifold stage values exactly at a singular configuration — with
    the rank tolerance of A at 1e-10. :func:`~nonmin.sim.simulate` therefore uses 1e-6 with
    adaptive methods (``ADAPTIVE_RANK_RTOL``), with which rtol 1e-10 passes both (A02: q error
    2.4e-7, crossed four-bar: 1.2e-7).
    Fixed-step ``"rk4"`` with the projection is the robust choice there (crossed four-bar,
    dt = 2.5e-4 s: q error 3.7e-8, drift 5.6e-8 J).

    Parameters
    ----------
    rtol, atol : float
        Relative and absolute tolerances.
    h_max : float
        Largest step allowed (default: unbounded).
    h_min_factor : float
        A step below ``h_min_factor·max(1, |t|)`` raises :class:`SimulationError`
        (step-size underflow).
    passages : bool
        Place every attempt so that a predicted singular instant falls at 0.45–0.65 of it,
        between the nodes 0.3 and 0.8 (:class:`SingularPassages`), and widen the error scale
        by the projection's round-off level ``PASSAGE_NOISE·eps/σ_min·(1 + |y_i|)`` (measured,
        A02 N = 2, 10 s, rtol 1e-10: 1426 steps, 124 rejected, 0.6 s; without: 2239 steps,
        788 rejected, steps down to 1e-11 s a microsecond before the first passage).
    """

    rtol: float = 1e-8
    atol: float = 1e-10
    h_max: float = np.inf
    h_min_factor: float = 1e-14
    passages: bool = True

    name: ClassVar[str] = "dopri5"
    order: ClassVar[int] = 5
    adaptive: ClassVar[bool] = True
    passage_fractions: ClassVar[tuple[float, ...]] = (0.45, 0.55, 0.65)  # nodes 0.3 | 0.8

    def __post_init__(self) -> None:
        if not (self.rtol > 0 and self.atol >= 0):
            raise InputError(f"dopri5: need rtol > 0 and atol ≥ 0, got rtol={self.rtol}, atol={self.atol}")

    def _stages(self, fun: RHS, t: float, y: FloatArray, f0: FloatArray, h: float) -> FloatArray:
        K = np.empty((7, y.shape[0]))
        K[0] = f0
        for s in range(1, 7):
            K[s] = fun(t + _DP_C[s] * h, y + h * (_DP_A[s] @ K[:s]))
        return K

    def advance(self, fun: RHS, t: float, y: FloatArray, f: FloatArray | None, h: float) -> FloatArray:
        f0 = fun(t, y) if f is None else f
        K = self._stages(fun, t, y, f0, h)
        return y + h * (_DP_B @ K)

    def initial_step(self, fun: RHS, t0: float, y0: FloatArray, f0: FloatArray, t_bound: float) -> float:
        """Hairer's starting-step heuristic (Solving ODEs I, II.4)."""
        return _initial_step(fun, t0, y0, f0, t_bound, self.rtol, self.atol, self.h_max, 5)

    def step(
        self, fun: RHS, state: StepperState, t_bound: float, project: Projector | None = None,
        place: Placer | None = None,
    ) -> StepResult:  # fmt: skip
        t, y = state.t, state.y
        f0 = fun(t, y) if state.f is None else state.f
        h = state.h
        if not np.isfinite(h) or h <= 0:
            h = self.initial_step(fun, t, y, f0, t_bound)
        h = min(h, self.h_max)
        rejected = 0
        h_min = self.h_min_factor * max(1.0, abs(t))
        noise = float(getattr(place, "noise", 0.0))
        zone = getattr(place, "zone", None)
        forced = False
        d_cap = PASSAGE_ZONE_STEP * h
        while True:
            h = h if place is None else place(t, h)
            if zone is not None:
                h, forced = zone(t, h, d_cap)
            h = _clip(t, h, t_bound)
            if h < h_min:
                raise SimulationError(
                    f"dopri5: step size underflow at t = {t:.12g} (h = {h:.3g} < {h_min:.3g}); "
                    "the problem may be stiff or the state non-smooth here"
                )
            K = self._stages(fun, t, y, f0, h)
            y1 = y + h * (_DP_B @ K)
            err_vec = h * (_DP_E @ K)
            if project is not None:
                err_vec = project(t + h, y1) - project(t + h, y1 - err_vec)
            big = np.maximum(np.abs(y), np.abs(y1))
            scale = self.atol + self.rtol * big + noise * (1.0 + big)
            err = float(np.sqrt(np.mean((err_vec / scale) ** 2)))
            if not np.isfinite(err):
                rejected += 1
                h *= 0.2
                continue
            if err <= 1.0 or forced:
                fac = 5.0 if err == 0.0 else min(5.0, max(0.2, 0.9 * err ** (-0.2)))
                if rejected or forced:
                    fac = min(fac, 1.0)
                t1 = t_bound if h == t_bound - t else t + h
                f1 = K[6]  # FSAL: F(t + h, y1)
                dense = _dp_dense(t, h, y, y1, K)
                h_next = min(h * fac, self.h_max)
                return StepResult(StepperState(t1, y1, f1, h_next), h, rejected, dense)
            rejected += 1
            h *= max(0.2, 0.9 * err ** (-0.2))


def _dp_dense(t0: float, h: float, y0: FloatArray, y1: FloatArray, K: FloatArray) -> Callable[[float], FloatArray]:
    """Hairer's 4th-order continuous extension of Dormand–Prince 5(4)."""
    ydiff = y1 - y0
    bspl = h * K[0] - ydiff
    r3 = ydiff - h * K[6] - bspl
    r4 = h * (_DP_D @ K)

    def interp(t: float) -> FloatArray:
        s = (t - t0) / h
        s1 = 1.0 - s
        return y0 + s * (ydiff + s1 * (bspl + s * (r3 + s1 * r4)))

    return interp


@dataclass(frozen=True)
class DOP853(Integrator):
    """Adaptive explicit Runge–Kutta 8(5,3) of Dormand & Prince with a 7th-order continuous
    extension (``"dop853"``; Hairer, Nørsett & Wanner, *Solving ODEs I*, II.10).

    Twelve stages per step; the error is Hairer's combination of the 5th- and 3rd-order
    estimates, ``err = ‖e₅‖² / √(N (‖e₅‖² + 0.01‖e₃‖²))`` in the RMS-scaled norm of
    :class:`DormandPrince5` (scale ``atol + rtol·max(|y0_i|, |y1_i|)``, widened by the
    projection's round-off level near a singular passage), accepted when ≤ 1; the next step is
    ``h·min(6, max(1/3, 0.9·err^(-1/8)))``. With a projection both estimates are measured on
    projected solutions, as in :class:`DormandPrince5`. The continuous extension costs
    ``F(t + h, y1)`` and three more stages, evaluated only for a step with an output sample
    inside. Singular passages: every attempt is placed so that a predicted instant falls at
    0.41–0.52 of it, inside the widest gap of the nodes (1/3 | 0.6).

    Parameters
    ----------
    rtol, atol, h_max, h_min_factor, passages
        As :class:`DormandPrince5`.
    """

    rtol: float = 1e-8
    atol: float = 1e-10
    h_max: float = np.inf
    h_min_factor: float = 1e-14
    passages: bool = True

    name: ClassVar[str] = "dop853"
    order: ClassVar[int] = 8
    adaptive: ClassVar[bool] = True
    passage_fractions: ClassVar[tuple[float, ...]] = (0.41, 0.465, 0.52)  # nodes 1/3 | 0.6

    def __post_init__(self) -> None:
        if not (self.rtol > 0 and self.atol >= 0):
            raise InputError(f"dop853: need rtol > 0 and atol ≥ 0, got rtol={self.rtol}, atol={self.atol}")

    @staticmethod
    def _stages(fun: RHS, t: float, y: FloatArray, K: FloatArray, h: float, first: int, last: int) -> None:
        for s in range(first, last):
            K[s] = fun(t + _D8.C[s] * h, y + h * (_D8.A[s, :s] @ K[:s]))

    def advance(self, fun: RHS, t: float, y: FloatArray, f: FloatArray | None, h: float) -> FloatArray:
        return _d8_advance(fun, t, y, f, h)

    def step(
        self, fun: RHS, state: StepperState, t_bound: float, project: Projector | None = None,
        place: Placer | None = None,
    ) -> StepResult:  # fmt: skip
        t, y = state.t, state.y
        f0 = fun(t, y) if state.f is None else state.f
        h = state.h
        if not np.isfinite(h) or h <= 0:
            h = _initial_step(fun, t, y, f0, t_bound, self.rtol, self.atol, self.h_max, 8)
        h = min(h, self.h_max)
        rejected = 0
        h_min = self.h_min_factor * max(1.0, abs(t))
        noise = float(getattr(place, "noise", 0.0))
        K = np.empty((16, y.shape[0]))
        K[0] = f0
        zone = getattr(place, "zone", None)
        forced = False
        while True:
            h = h if place is None else place(t, h)
            if zone is not None:
                h, forced = zone(t, h)
            h = _clip(t, h, t_bound)
            if h < h_min:
                raise SimulationError(
                    f"dop853: step size underflow at t = {t:.12g} (h = {h:.3g} < {h_min:.3g}); "
                    "the problem may be stiff or the state non-smooth here"
                )
            self._stages(fun, t, y, K, h, 1, 12)
            y1 = y + h * (_D8.B @ K[:12])
            e5 = h * (_D8.E5[:12] @ K[:12])
            e3 = h * (_D8.E3[:12] @ K[:12])
            if project is not None:
                yq = project(t + h, y1)
                e5 = yq - project(t + h, y1 - e5)
                e3 = yq - project(t + h, y1 - e3)
            big = np.maximum(np.abs(y), np.abs(y1))
            scale = self.atol + self.rtol * big + noise * (1.0 + big)
            s5 = float(np.sum((e5 / scale) ** 2))
            s3 = float(np.sum((e3 / scale) ** 2))
            den = s5 + 0.01 * s3
            err = s5 / math.sqrt(den * y.shape[0]) if den > 0.0 else 0.0
            if not np.isfinite(err):
                rejected += 1
                h *= 0.2
                continue
            if err <= 1.0 or forced:
                fac = 6.0 if err == 0.0 else min(6.0, max(1.0 / 3.0, 0.9 * err ** (-0.125)))
                if rejected or forced:
                    fac = min(fac, 1.0)
                t1 = t_bound if h == t_bound - t else t + h
                f1 = None
                if project is None:  # the FSAL stage (with a projection F is taken at the projected end)
                    f1 = fun(t + h, y1)
                    K[12] = f1
                dense = _d8_dense(fun, t, h, y, y1, K.copy(), f1 is not None)
                h_next = min(h * fac, self.h_max)
                return StepResult(StepperState(t1, y1, f1, h_next), h, rejected, dense)
            rejected += 1
            h *= max(1.0 / 3.0, 0.9 * err ** (-0.125))


def _d8_dense(
    fun: RHS, t0: float, h: float, y0: FloatArray, y1: FloatArray, K: FloatArray, have_f1: bool
) -> Callable[[float], FloatArray]:
    """DOP853's 7th-order continuous extension on [t0, t0 + h]: F(t0 + h, y1) (unless known)
    and the three extra stages are evaluated at the first call."""
    F: list[FloatArray] = []

    def setup() -> None:
        if not have_f1:
            K[12] = fun(t0 + h, y1)
        DOP853._stages(fun, t0, y0, K, h, 13, 16)
        dy = y1 - y0
        F.extend([dy, h * K[0] - dy, 2.0 * dy - h * (K[12] + K[0])])
        F.extend(h * (_D8.D @ K))

    def interp(t: float) -> FloatArray:
        if not F:
            setup()
        x = (t - t0) / h
        x1 = 1.0 - x
        p = F[6]
        for c, w in ((F[5], x), (F[4], x1), (F[3], x), (F[2], x1), (F[1], x), (F[0], x1)):
            p = c + w * p
        return y0 + x * p

    return interp


def _d8_advance(fun: RHS, t: float, y: FloatArray, f: FloatArray | None, h: float) -> FloatArray:
    """DOP853's 8th-order step ``y₁`` from ``(t, y)`` (``f = F(t, y)`` or None): its 12 stages
    and weights, no error estimate (:class:`DOP853` and :class:`RK8`)."""
    K = np.empty((12, y.shape[0]))
    K[0] = fun(t, y) if f is None else f
    DOP853._stages(fun, t, y, K, h, 1, 12)
    return y + h * (_D8.B @ K[:12])


@dataclass(frozen=True)
class RK8(Integrator):
    """Dormand–Prince's 8th-order stages and weights (:class:`DOP853`'s ``y₁``) with a fixed step
    ``dt``: 12 right-hand sides per step (11 new ones: the first is F at the projected step end
    before), no error estimate — so none of DOP853's projections of the error points
    ``y₁ − e₅``, ``y₁ − e₃`` and no rejected attempts — the step end projected as with RK4.

    For coarse steps on smooth motion, where DOP853's error control would take about the same
    steps: on A02 N = 2 (10 s, step ends recorded) dt = 0.25 s gives B0 within 1.1e-2 m and
    the energy within 4.9e-3 J in 40 steps, faster than Pinocchio's semi-implicit Euler at
    dt = 5e-2 (7.3e-2 m, 4.6 J; ``benchmarks/README.md``). Without error control nothing
    guards a step that is too long: the crossed four-bar's change points need dt ≲ 1e-2 and
    the singular-passage placement; check the accuracy against a finer run.

    ``passages`` as for :class:`RK4`, but the step that holds a singular instant is not widened
    (:data:`PASSAGE_SIGMA`): at steps of 0.1–0.3 s a doubled step loses the 8th-order accuracy
    (A02 N = 2 at dt 0.25 left the parallelogram mode with it). Samples between step ends come
    from the quintic Hermite interpolant of the projected step ends (order 6 in q, 5 in q̇),
    not from DOP853's 7th-order extension.
    """

    dt: float | None = None
    passages: bool = True

    name: ClassVar[str] = "rk8"
    order: ClassVar[int] = 8
    adaptive: ClassVar[bool] = False
    passage_fractions: ClassVar[tuple[float, ...]] = DOP853.passage_fractions
    widen_passages: ClassVar[bool] = False

    def advance(self, fun: RHS, t: float, y: FloatArray, f: FloatArray | None, h: float) -> FloatArray:
        return _d8_advance(fun, t, y, f, h)

    def step(
        self, fun: RHS, state: StepperState, t_bound: float, project: Projector | None = None,
        place: Placer | None = None,
    ) -> StepResult:  # fmt: skip
        """One step (:func:`_fixed_step`, without RK4's projected stages)."""
        return _fixed_step(self, fun, state, t_bound, None, place)


#: Integrators by name (``method=`` of :func:`nonmin.sim.simulate`).
METHODS: dict[str, type[Integrator]] = {
    "rk4": RK4,
    "dopri5": DormandPrince5,
    "midpoint": ImplicitMidpoint,
    "dop853": DOP853,
    "rk8": RK8,
}
