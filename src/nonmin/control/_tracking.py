"""Trajectory tracking in dependent coordinates on the projected dynamics.

The projected dynamics (paper eq. (EqMotion2), valid for admissible ``qd ∈ N``) are
``M̄ qdd + C̄ qd = P (f + f_g + f_p)`` with ``M̄ = PMP + μQ`` s.p.d. and ``dM̄/dt − 2C̄`` skew
(Theorem 1, C̄ from eq. (Cbar2) with the model's Ȧ matrix). Two methods are offered.

``method="passivity"`` (Slotine–Li type, default)::

    q̇_r = P (q̇* − λ e),   q̈_r = Ṗ (q̇* − λ e) + P (q̈* − λ ė),   s = qd − q̇_r ∈ N
    f_∥ = P ( M̄ q̈_r + C̄ q̇_r − f_g − f_p − Kd s − Kp e )

Closed loop ``M̄ ṡ + C̄ s = −Q(M̄ q̈_r + C̄ q̇_r) − P (Kd s + Kp e)``; with
``W = ½ sᵀ M̄ s + ½ eᵀ Kp e`` and the skew property (``sᵀQ = 0`` because ``s ∈ N``),
``dW/dt = −sᵀ Kd s − λ eᵀ Kp P e − eᵀ Kp Q q̇*``; the last term is second order in e
(``Q(q) q̇* = (Q(q) − Q(q*)) q̇*``), so tracking is locally exponentially stable, and for a
set-point (``q̇* = 0``) ``dW/dt ≤ 0`` exactly when Kp commutes with P (scalar Kp).

``method="computed_torque"``::

    a = q̈* − Kd ė − Kp e,   f_∥ = P ( M (P a + w) − h − f_p ),   w = −A⁺γ

gives ``P qdd = P a`` exactly (the N-part of the error obeys ``P(ë + Kd ė + Kp e) = 0``)
while ``Q qdd = w`` is imposed by the constraints.

The reference must be consistent with the constraints; with ``target_policy="project"`` (default)
``q*(t)`` is projected onto the manifold at every call and ``q̇*``, ``q̈*`` onto the tangent
space (first-order consistent; supply consistent references for exact tracking). With
``"reject"`` an inconsistent ``q*`` raises :class:`~nonmin.errors.AssemblyError`.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike

from ..core import pseudo_inverse
from ..errors import InputError
from ..model import Model
from ._base import LawOutput, ProjectedController
from ._common import (
    Evaluation,
    FloatArray,
    InfeasiblePolicy,
    gain_matrix,
    mbar,
)
from ._targets import (
    Metric,
    Reference,
    TargetPolicy,
    check_on_manifold,
    check_quaternion_blocks,
    project_acceleration,
    project_configuration,
    project_velocity,
)

TrackingLaw = Literal["passivity", "computed_torque"]

__all__ = ["Tracker"]


@dataclass(frozen=True, eq=False)
class Tracker(ProjectedController):
    """Tracking controller for a desired motion ``q*(t)`` in dependent coordinates.

    Parameters
    ----------
    model : Model
    reference : Reference or array_like, shape (n,)
        Desired motion (a constant array is a set-point).
    Kp, Kd : float or array_like, shape (n,) or (n, n)
        Stiffness and damping gains (s.p.d.).
    lambda_ : float
        Bandwidth λ > 0 of the sliding variable (passivity law only).
    method : {"passivity", "computed_torque"}
        See the module docstring.
    target_policy : {"project", "reject"}
    metric : {"euclidean", "mass"}
        Projection metric of the reference.
    fixed : sequence of int
        Coordinates kept at their reference value by the projection.
    quaternion_blocks : sequence of 4-index sequences
        Unit quaternions in q: the reference's sign is chosen per block for the shortest
        rotation (no unwinding).
    u_min, u_max, on_infeasible, rtol
        As for :class:`~nonmin.control.Regulator`.
    """

    model: Model
    reference: Reference | ArrayLike
    Kp: ArrayLike = 1.0
    Kd: ArrayLike = 1.0
    lambda_: float = 1.0
    method: TrackingLaw = "passivity"
    target_policy: TargetPolicy = "project"
    metric: Metric = "euclidean"
    fixed: Sequence[int] = ()
    quaternion_blocks: Sequence[Sequence[int]] = ()
    u_min: ArrayLike | None = field(default=None, kw_only=True)
    u_max: ArrayLike | None = field(default=None, kw_only=True)
    on_infeasible: InfeasiblePolicy = field(default="raise", kw_only=True)
    rtol: float | None = field(default=None, kw_only=True)
    # memo of the projected reference for the last few (t, active set) pairs: the RK stages
    # and the simulator's update call evaluate the same times; a pure cache, not state
    _memo: dict[tuple[float, frozenset[str], tuple[bool, ...]], tuple[FloatArray, FloatArray, FloatArray]] = (
        field(default_factory=dict, init=False, repr=False, compare=False)
    )

    def __post_init__(self) -> None:
        self._validate_common()
        n = self.model.n
        s = object.__setattr__
        ref = self.reference
        if not isinstance(ref, Reference):
            arr = np.asarray(ref, dtype=float)
            if arr.shape != (n,):
                raise InputError(f"reference must be a Reference or an array of shape ({n},), got {arr.shape}")
            ref = Reference.constant(arr)
        s(self, "_ref", ref)
        s(self, "_Kp", gain_matrix(self.Kp, "Kp", n))
        s(self, "_Kd", gain_matrix(self.Kd, "Kd", n))
        lam = float(self.lambda_)
        if not np.isfinite(lam) or lam <= 0.0:
            raise InputError(f"lambda_ must be a finite number > 0, got {self.lambda_!r}")
        if self.method not in ("passivity", "computed_torque"):
            raise InputError(f"method must be 'passivity' or 'computed_torque', got {self.method!r}")
        if self.target_policy not in ("project", "reject"):
            raise InputError(f"target_policy must be 'project' or 'reject', got {self.target_policy!r}")
        if self.metric not in ("euclidean", "mass"):
            raise InputError(f"metric must be 'euclidean' or 'mass', got {self.metric!r}")
        s(self, "_qblocks", check_quaternion_blocks(self.quaternion_blocks, n))

    # ------------------------------------------------------------------ reference
    def desired(
        self, t: float, q: FloatArray | None = None, *, active: Iterable[str] | None = None
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """``(q*, q̇*, q̈*)`` at t, made consistent with the active constraints.

        If ``q`` is given, quaternion blocks of the reference are sign-aligned with it.
        """
        act = self.model.resolve_active(active)
        n = self.model.n
        qs, vs, as_ = self._ref(t)  # type: ignore[attr-defined]
        signs: tuple[bool, ...] = ()
        if q is not None:
            signs = tuple(
                float(q[list(b)] @ qs[list(b)]) < 0.0 for b in self._qblocks  # type: ignore[attr-defined]
            )
        key = (float(t), act, signs)
        hit = self._memo.get(key)
        if hit is not None:
            return hit
        for arr, nm in ((qs, "q*"), (vs, "q̇*"), (as_, "q̈*")):
            if arr.shape != (n,) or not np.isfinite(arr).all():
                raise InputError(f"reference {nm}({t}) must be finite with shape ({n},), got {arr!r}")
        if q is not None:
            for b in self._qblocks:  # type: ignore[attr-defined]
                idx = list(b)
                if float(q[idx] @ qs[idx]) < 0.0:
                    qs, vs, as_ = qs.copy(), vs.copy(), as_.copy()
                    qs[idx], vs[idx], as_[idx] = -qs[idx], -vs[idx], -as_[idx]
        if self.target_policy == "reject":
            check_on_manifold(self.model, qs, t=t, active=act, what="reference q*(t)")
        else:
            qs = project_configuration(
                self.model, qs, t=t, active=act, metric=self.metric, fixed=self.fixed, rtol=self.rtol
            )
        vs = project_velocity(self.model, qs, vs, t=t, active=act, rtol=self.rtol)
        as_ = project_acceleration(self.model, qs, vs, as_, t=t, active=act, rtol=self.rtol)
        if len(self._memo) > 16:
            self._memo.clear()
        self._memo[key] = (qs, vs, as_)
        return qs, vs, as_

    # ------------------------------------------------------------------ law
    def law(
        self, t: float, q: FloatArray, qd: FloatArray, ev: Evaluation, active: frozenset[str]
    ) -> LawOutput:
        """Passivity-based or computed-torque ``f_∥`` (module docstring)."""
        qs, vs, as_ = self.desired(t, q, active=active)
        e = q - qs
        ed = qd - vs
        Kp: FloatArray = self._Kp  # type: ignore[attr-defined]
        Kd: FloatArray = self._Kd  # type: ignore[attr-defined]
        P = ev.P
        if self.method == "computed_torque":
            a = as_ - Kd @ ed - Kp @ e
            w = -ev.basis.solve(ev.gamma) if ev.A.shape[0] else np.zeros_like(q)
            f_par = P @ (ev.M @ (P @ a + w) - ev.h - ev.f_p)
            return LawOutput(f_par, qs, e, float("nan"))
        lam = float(self.lambda_)
        Mb, mu = mbar(ev)
        if ev.A.shape[0]:
            # Λ = −A⁺Ȧ, Ṗ = ΛP + PΛᵀ (Remark 1), C̄ = PCP + PM(ΛP + PΛᵀ) − μΛP (eq. (Cbar2));
            # the same formulas as nonmin.core.projector_derivative / coriolis_bar, sharing P
            # and one pseudo-inverse.
            Adot = self.model.constraint_jacobian_dot(t, q, qd, active)
            LP = -(pseudo_inverse(ev.A, self.rtol) @ Adot) @ P
            Pdot = LP + LP.T
            Cbar = P @ self.model.coriolis_matrix(q, qd) @ P + P @ ev.M @ Pdot - mu * LP
        else:
            Pdot = np.zeros_like(P)
            Cbar = self.model.coriolis_matrix(q, qd)
        x = vs - lam * e
        qr_d = P @ x
        qr_dd = Pdot @ x + P @ (as_ - lam * ed)
        sv = qd - qr_d
        f_par = P @ (Mb @ qr_dd + Cbar @ qr_d - ev.f_g - ev.f_p - Kd @ sv - Kp @ e)
        W = 0.5 * float(sv @ Mb @ sv) + 0.5 * float(e @ Kp @ e)
        return LawOutput(f_par, qs, e, W)
