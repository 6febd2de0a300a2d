"""Base of the projection controllers: evaluation, actuation, saturation, bookkeeping."""

from __future__ import annotations

from abc import abstractmethod
from collections.abc import Iterable
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike

from ..errors import InputError
from ..model import Model
from ._common import (
    INFEASIBLE_POLICIES,
    ControlInfo,
    ControlState,
    Evaluation,
    FloatArray,
    InfeasiblePolicy,
    actuate,
    evaluate,
    saturate,
    state_vectors,
)
from ._protocol import Controller

__all__ = ["LawOutput", "ProjectedController"]


class LawOutput(NamedTuple):
    """What a control law returns at one state.

    Attributes
    ----------
    f_par : ndarray, shape (n,)
        Admissible generalized force ``f_∥ ∈ N(A)``.
    target : ndarray, shape (n,)
        Reference configuration used (projected onto the manifold).
    error : ndarray, shape (n,)
        ``q − q*``.
    lyapunov : float
        Value of the law's Lyapunov function (NaN if none).
    """

    f_par: FloatArray
    target: FloatArray
    error: FloatArray
    lyapunov: float


class ProjectedController(Controller):
    """Common machinery of controllers acting through ``u = Γ f_∥``, ``Γ = (PB)⁺``.

    Subclasses are frozen dataclasses with the attributes ``model``, ``u_min``, ``u_max``,
    ``on_infeasible``, ``rtol`` and implement :meth:`law`, the admissible generalized force
    ``f_∥ ∈ N(A)`` they want. This class turns it into actuator forces (checking the actuation
    condition ``rank(PB) = n − rank(A)``), applies the actuator limits and keeps the
    bookkeeping in :class:`ControlState`.
    """

    model: Model
    u_min: Any
    u_max: Any
    on_infeasible: InfeasiblePolicy
    rtol: float | None

    # ------------------------------------------------------------------ validation helpers
    def _validate_common(self) -> None:
        if not isinstance(self.model, Model):
            raise InputError(f"model must be a nonmin Model, got {type(self.model).__name__}")
        if self.on_infeasible not in INFEASIBLE_POLICIES:
            raise InputError(
                f"on_infeasible must be one of {INFEASIBLE_POLICIES}, got {self.on_infeasible!r}"
            )
        from ._common import limit_vector

        k = self.model.k
        lo = limit_vector(self.u_min, "u_min", k, -np.inf)
        hi = limit_vector(self.u_max, "u_max", k, np.inf)
        if np.any(lo > hi):
            raise InputError(f"u_min must be ≤ u_max for every actuator, got {lo.tolist()} > {hi.tolist()}")
        object.__setattr__(self, "_lo", lo)
        object.__setattr__(self, "_hi", hi)

    # ------------------------------------------------------------------ the law
    @abstractmethod
    def law(
        self, t: float, q: FloatArray, qd: FloatArray, ev: Evaluation, active: frozenset[str]
    ) -> LawOutput:
        """Admissible generalized force ``f_∥`` and diagnostics at one state."""

    def actuation(
        self,
        t: float,
        q: FloatArray,
        qd: FloatArray,
        ev: Evaluation,
        out: LawOutput,
        active: frozenset[str],
    ) -> tuple[FloatArray, bool, FloatArray]:
        """``(u, feasible, σ(PB))`` realizing ``out.f_par``: ``u = Γ f_∥`` (force control overrides)."""
        return actuate(ev, out.f_par, policy=self.on_infeasible, rtol=self.rtol, t=t)

    # ------------------------------------------------------------------ protocol
    def info(
        self,
        t: float,
        q: ArrayLike,
        qd: ArrayLike,
        state: Any = None,
        *,
        active: Iterable[str] | None = None,
    ) -> ControlInfo:
        """Everything the controller computes at ``(t, q, qd)``: see :class:`ControlInfo`."""
        qv, v = state_vectors(self.model, q, qd)
        act = self.model.resolve_active(active)
        ev = evaluate(self.model, float(t), qv, v, act, self.rtol)
        out = self.law(float(t), qv, v, ev, act)
        u_raw, feasible, sigma = self.actuation(float(t), qv, v, ev, out, act)
        if not np.isfinite(u_raw).all():
            from ..errors import NonFiniteError

            raise NonFiniteError(f"controller produced non-finite actuator forces at t = {t}: {u_raw}")
        u, sat = saturate(u_raw, self._lo, self._hi)  # type: ignore[attr-defined]
        return ControlInfo(
            u=u,
            u_raw=u_raw,
            saturated=sat,
            feasible=feasible,
            sigma_pb=sigma,
            f_par=out.f_par,
            target=out.target,
            error=out.error,
            lyapunov=float(out.lyapunov),
        )

    def __call__(
        self,
        t: float,
        q: ArrayLike,
        qd: ArrayLike,
        state: Any = None,
        *,
        active: Iterable[str] | None = None,
    ) -> FloatArray:
        """Actuator forces ``u``, shape (k,), after saturation."""
        return self.info(t, q, qd, state, active=active).u

    def lyapunov(
        self, q: ArrayLike, qd: ArrayLike, *, t: float = 0.0, active: Iterable[str] | None = None
    ) -> float:
        """The control law's Lyapunov function at ``(t, q, qd)`` (NaN if it has none)."""
        qv, v = state_vectors(self.model, q, qd)
        act = self.model.resolve_active(active)
        ev = evaluate(self.model, float(t), qv, v, act, self.rtol)
        return float(self.law(float(t), qv, v, ev, act).lyapunov)

    def engine_controller(self, model: Any, program: Any, active: frozenset[str]) -> Any | None:
        """The engine's compiled form for the active set ``active`` (Regulator, the
        Tracker (computed torque; passivity on planar and robot programs), ForceControl over
        either; :mod:`nonmin.control._engine`), else None (called back). See :meth:`nonmin.control.Controller.engine_controller`."""
        from ._engine import compile_controller

        return compile_controller(self, model, program, active)

    def engine_state(self, state: Any, compiled: Any) -> Any:
        """:class:`ControlState` after the steps the compiled controller took (what
        ``ControlState.record`` over them gives)."""
        from ._engine import merge_state

        return merge_state(state, compiled, self.model.k)

    def initial_state(self) -> ControlState:
        """Fresh bookkeeping state (no step seen, no saturation)."""
        return ControlState.initial(self.model.k)

    def update(
        self,
        t: float,
        q: ArrayLike,
        qd: ArrayLike,
        state: Any,
        *,
        active: Iterable[str] | None = None,
    ) -> ControlState:
        """Record the accepted step ending at ``(t, q, qd)`` (saturation counts, σ_min(PB))."""
        st = state if isinstance(state, ControlState) else self.initial_state()
        return st.record(self.info(t, q, qd, st, active=active))
