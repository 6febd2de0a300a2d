"""Integrators: immutable steppers with explicit state (``init`` / ``step``).

Every integrator works on a first-order system ``y' = F(t, y)`` with ``y = (q, qd)`` and knows
nothing about mechanics. Its evolving data live in a :class:`StepperState` value that is passed
in and returned; the objects themselves are frozen and can be shared between runs.

* :class:`RK4` — classical fixed-step Runge–Kutta, order 4 (``"rk4"``).
* :class:`DormandPrince5` — adaptive Dormand–Prince 5(4) with FSAL, PI-free standard step-size
  control and the continuous extension (``"dopri5"``); tableau from Dormand & Prince (1980),
  Hairer, Nørsett & Wanner, *Solving ODEs I*, Table II.5.2.
* :class:`ImplicitMidpoint` — the symmetric, symplectic implicit midpoint rule, order 2
  (``"midpoint"``): bounded energy error over long runs.

:data:`METHODS` maps names to classes (like ``scipy.integrate._ivp.METHODS``).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass
from typing import ClassVar, NamedTuple

import numpy as np
from numpy.typing import NDArray

from ..errors import InputError, NonminError, SimulationError

__all__ = [
    "METHODS",
    "RK4",
    "DormandPrince5",
    "ImplicitMidpoint",
    "Integrator",
    "Projector",
    "StepResult",
    "StepperState",
    "hermite_quintic",
]

FloatArray = NDArray[np.float64]
RHS = Callable[[float, FloatArray], FloatArray]
Projector = Callable[[float, FloatArray], FloatArray]


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
    """:func:`hermite_quintic` into ``out``; plain loops, so the compiled engine compiles this
    very function (``nonmin.sim._fast_kernels._hermite``)."""
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

    @abstractmethod
    def step(
        self, fun: RHS, state: StepperState, t_bound: float, project: Projector | None = None
    ) -> StepResult:
        """Take one accepted step, never beyond ``t_bound``.

        ``project(t, y) -> y`` (optional) is the stabilization's projection; adaptive methods
        measure their error estimate on projected solutions (see :class:`DormandPrince5`).
        """


@dataclass(frozen=True)
class RK4(Integrator):
    """Classical 4th-order Runge–Kutta with a fixed step ``dt`` (4 RHS calls per step)."""

    dt: float | None = None

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
        self, fun: RHS, state: StepperState, t_bound: float, project: Projector | None = None
    ) -> StepResult:
        h = _clip(state.t, state.h, t_bound)
        y1 = self.advance(fun, state.t, state.y, state.f, h)
        t1 = t_bound if h == t_bound - state.t else state.t + h
        return StepResult(StepperState(t1, y1, None, state.h), h, 0, None)


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
    ``"rk4"`` through singular configurations.
    """

    dt: float | None = None
    xtol: float = 1e-13
    max_iter: int = 50
    max_halvings: int = 12

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
        self, fun: RHS, state: StepperState, t_bound: float, project: Projector | None = None
    ) -> StepResult:
        h = _clip(state.t, state.h, t_bound)
        y1 = self.advance(fun, state.t, state.y, state.f, h)
        t1 = t_bound if h == t_bound - state.t else state.t + h
        return StepResult(StepperState(t1, y1, None, state.h), h, 0, None)


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
    """

    rtol: float = 1e-8
    atol: float = 1e-10
    h_max: float = np.inf
    h_min_factor: float = 1e-14

    name: ClassVar[str] = "dopri5"
    order: ClassVar[int] = 5
    adaptive: ClassVar[bool] = True

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
        scale = self.atol + self.rtol * np.abs(y0)
        d0 = float(np.sqrt(np.mean((y0 / scale) ** 2)))
        d1 = float(np.sqrt(np.mean((f0 / scale) ** 2)))
        h0 = 1e-6 if d0 < 1e-5 or d1 < 1e-5 else 0.01 * d0 / d1
        h0 = min(h0, abs(t_bound - t0))
        y1 = y0 + h0 * f0
        f1 = fun(t0 + h0, y1)
        d2 = float(np.sqrt(np.mean(((f1 - f0) / scale) ** 2))) / h0
        h1 = max(1e-6, h0 * 1e-3) if max(d1, d2) <= 1e-15 else (0.01 / max(d1, d2)) ** (1 / 5)
        return float(min(100 * h0, h1, self.h_max))

    def step(
        self, fun: RHS, state: StepperState, t_bound: float, project: Projector | None = None
    ) -> StepResult:
        t, y = state.t, state.y
        f0 = fun(t, y) if state.f is None else state.f
        h = state.h
        if not np.isfinite(h) or h <= 0:
            h = self.initial_step(fun, t, y, f0, t_bound)
        h = min(h, self.h_max)
        rejected = 0
        h_min = self.h_min_factor * max(1.0, abs(t))
        while True:
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
            scale = self.atol + self.rtol * np.maximum(np.abs(y), np.abs(y1))
            err = float(np.sqrt(np.mean((err_vec / scale) ** 2)))
            if not np.isfinite(err):
                rejected += 1
                h *= 0.2
                continue
            if err <= 1.0:
                fac = 5.0 if err == 0.0 else min(5.0, max(0.2, 0.9 * err ** (-0.2)))
                if rejected:
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


#: Integrators by name (``method=`` of :func:`nonmin.sim.simulate`).
METHODS: dict[str, type[Integrator]] = {
    "rk4": RK4,
    "dopri5": DormandPrince5,
    "midpoint": ImplicitMidpoint,
}
