"""The paper's set-point regulator in dependent coordinates (Sec. "Control", corrected).

Law (paper eq. (control-law), with σ = 0 by default — ERRATA 5)::

    f_∥ = −P ( f_g + Kp (e + σ‖e‖η) + Kd qd ),   e = q − q*,   u = Γ f_∥,   Γ = (PB)⁺

so that the generalized force exerted by the actuators, ``f = B u = R f_∥`` (``R = BΓ``), has
null-space component ``P f = f_∥`` exactly when ``rank(PB) = n − rank(A)`` (ERRATA 4; the
paper's ``f = −R(...)`` is the same force, since ``Γ P = Γ``). Closed loop (projected dynamics
``M̄ qdd + C̄ qd = P(f + f_g)``, valid for ``qd ∈ N``)::

    M̄ qdd + C̄ qd = −P (Kp e + Kd qd)          (σ = 0)

With ``V = ½ qdᵀ M̄ qd + ½ eᵀ Kp e`` (eq. (V)) and the skew symmetry of ``dM̄/dt − 2C̄``,
``dV/dt = −qdᵀ Kd qd ≤ 0`` (``P qd = qd``). LaSalle gives convergence to
``{qd = 0, P(q)(q − q*) = 0}``: q* is locally (almost globally) asymptotically stable — not
globally (a pendulum's antipode is another rest point).
"""

from __future__ import annotations

import warnings
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

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
    TargetPolicy,
    align_quaternions,
    check_on_manifold,
    check_quaternion_blocks,
    project_configuration,
)

__all__ = ["Regulator"]


def _has_rheonomic(model: Model, active: frozenset[str]) -> bool:
    return any(c.kind == "rheonomic" and c.name in active for c in model.constraints)


@dataclass(frozen=True, eq=False)
class Regulator(ProjectedController):
    """Set-point regulator ``f_∥ = −P(f_g + Kp e + Kd qd)``, ``u = (PB)⁺ f_∥``.

    Parameters
    ----------
    model : Model
    target : array_like, shape (n,)
        Desired configuration q* in dependent coordinates. Off-manifold targets are projected
        onto the manifold of the active constraints (``target_policy="project"``, separately
        for every active set met) or rejected (``"reject"``: :class:`~nonmin.errors.AssemblyError`).
    Kp, Kd : float or array_like, shape (n,) or (n, n)
        Symmetric positive-definite stiffness and damping gains.
    sigma : float
        The paper's "σ‖e‖η" term. **Default 0; keep it 0** (ERRATA 5): the term is dry
        (Coulomb) friction of magnitude ``σ‖Kp e‖``, the closed loop is discontinuous at
        ``qd = 0`` and every rest state with ``‖Pe‖ ≤ σ‖e‖`` is an equilibrium — the system
        *sticks* where it first stops (Theorem 2 is false for σ > 1). On a curved manifold
        ``‖Pe‖ ≪ ‖e‖`` far from the target, so even σ < 1 sticks there (measured: the pendulum
        of ``examples/sigma_sticking.py`` stays 2.2 rad away with σ = 0.5 and with σ = 1.5).
        A ``RuntimeWarning`` is issued for every σ > 0. ``η = qd/‖qd‖`` if ``qd ≠ 0`` else
        ``ξ(q) = P ξ0 / ‖P ξ0‖``.
    xi0 : array_like, shape (n,), optional
        Vector defining ``ξ(q)``; default ``(1, …, 1)/√n``.
    target_policy : {"project", "reject"}
    metric : {"euclidean", "mass"}
        Metric of the projection (see :mod:`nonmin.control._targets`); the regulator's own rest
        point is the Euclidean-nearest one.
    fixed : sequence of int
        Coordinates the projection keeps at their target value (e.g. an object's pose).
    quaternion_blocks : sequence of 4-index sequences
        Unit-quaternion coordinates; the target's sign is chosen per block for the shortest
        rotation (no unwinding).
    u_min, u_max : float or array_like, shape (k,), optional
        Actuator limits; the output is clipped and saturation is reported (the Lyapunov
        guarantee holds only while no actuator saturates).
    on_infeasible : {"raise", "least_squares"}
        What to do where ``rank(PB) < n − rank(A)``: raise
        :class:`~nonmin.errors.InfeasibleActuationError`, or apply the least-squares force
        and flag it (``ControlInfo.feasible``, ``ControlState.infeasible_steps``).
    rtol : float, optional
        Rank tolerance (A and PB).

    Examples
    --------
    >>> import numpy as np
    >>> from nonmin.model import FunctionModel, FunctionConstraint
    >>> from nonmin.control import Regulator
    >>> rod = FunctionConstraint.holonomic(
    ...     "rod", phi=lambda q: [0.5 * (q @ q - 1.0)], jacobian=lambda q: q[None, :],
    ...     adot_qd=lambda q, qd: [qd @ qd])
    >>> pend = FunctionModel(
    ...     name="pendulum", coordinate_names=("x", "y"), mass=lambda q: np.eye(2),
    ...     coriolis=lambda q, qd: np.zeros((2, 2)), conservative=lambda q: [0.0, -9.81],
    ...     potential=lambda q: 9.81 * q[1], constraints=(rod,), actuator_names=("push",),
    ...     input_matrix_fn=lambda q: [[np.cos(0.3)], [np.sin(0.3)]])
    >>> reg = Regulator(pend, target=[2.0, 0.0], Kp=20.0, Kd=8.0)  # projected to (1, 0)
    >>> u = reg(0.0, [0.0, -1.0], [0.0, 0.0])
    >>> u.shape
    (1,)
    """

    model: Model
    target: ArrayLike
    Kp: ArrayLike = 1.0
    Kd: ArrayLike = 1.0
    sigma: float = 0.0
    xi0: ArrayLike | None = None
    target_policy: TargetPolicy = "project"
    metric: Metric = "euclidean"
    fixed: Sequence[int] = ()
    quaternion_blocks: Sequence[Sequence[int]] = ()
    u_min: ArrayLike | None = field(default=None, kw_only=True)
    u_max: ArrayLike | None = field(default=None, kw_only=True)
    on_infeasible: InfeasiblePolicy = field(default="raise", kw_only=True)
    rtol: float | None = field(default=None, kw_only=True)
    _cache: dict[frozenset[str], FloatArray] = field(
        default_factory=dict, init=False, repr=False, compare=False
    )

    def __post_init__(self) -> None:
        self._validate_common()
        n = self.model.n
        s = object.__setattr__
        tgt = np.asarray(self.target, dtype=float)
        if tgt.shape != (n,) or not np.isfinite(tgt).all():
            raise InputError(f"target must be a finite vector of shape ({n},), got {tgt!r}")
        s(self, "_q_star", tgt.copy())
        s(self, "_Kp", gain_matrix(self.Kp, "Kp", n))
        s(self, "_Kd", gain_matrix(self.Kd, "Kd", n))
        sig = float(self.sigma)
        if not np.isfinite(sig) or sig < 0.0:
            raise InputError(f"sigma must be a finite number ≥ 0, got {self.sigma!r}")
        if sig > 0.0:
            warnings.warn(
                f"Regulator(sigma={sig}): the term sigma*|e|*eta is dry friction; the closed "
                "loop sticks at rest states with |Pe| <= sigma*|e| (always possible for "
                "sigma > 1, where Theorem 2 of the paper is false, ERRATA 5; and far from the "
                "target on curved manifolds even for sigma < 1). Use sigma = 0.",
                RuntimeWarning,
                stacklevel=3,
            )
        xi = np.ones(n) / np.sqrt(n) if self.xi0 is None else np.asarray(self.xi0, dtype=float)
        if xi.shape != (n,) or not np.isfinite(xi).all() or not np.linalg.norm(xi) > 0:
            raise InputError(f"xi0 must be a finite non-zero vector of shape ({n},), got {xi!r}")
        s(self, "_xi0", xi)
        if self.target_policy not in ("project", "reject"):
            raise InputError(f"target_policy must be 'project' or 'reject', got {self.target_policy!r}")
        if self.metric not in ("euclidean", "mass"):
            raise InputError(f"metric must be 'euclidean' or 'mass', got {self.metric!r}")
        s(self, "_qblocks", check_quaternion_blocks(self.quaternion_blocks, n))

    # ------------------------------------------------------------------ target
    def target_for(self, active: Iterable[str] | None = None, t: float = 0.0) -> FloatArray:
        """The target used with the given active constraints (projected or checked)."""
        act = self.model.resolve_active(active)
        cacheable = not _has_rheonomic(self.model, act)
        if cacheable and act in self._cache:
            return self._cache[act]
        q_star: FloatArray = self._q_star  # type: ignore[attr-defined]
        if self.target_policy == "reject":
            check_on_manifold(self.model, q_star, t=t, active=act)
            out = q_star
        else:
            out = project_configuration(
                self.model, q_star, t=t, active=act, metric=self.metric, fixed=self.fixed, rtol=self.rtol
            )
        if cacheable:
            self._cache[act] = out
        return out

    # ------------------------------------------------------------------ law
    def law(
        self, t: float, q: FloatArray, qd: FloatArray, ev: Evaluation, active: frozenset[str]
    ) -> LawOutput:
        """``f_∥ = −P(f_g + Kp(e + σ‖e‖η) + Kd qd)`` and ``V = ½ qdᵀM̄qd + ½ eᵀKp e``."""
        q_star = align_quaternions(q, self.target_for(active, t), self._qblocks)  # type: ignore[attr-defined]
        e = q - q_star
        Kp: FloatArray = self._Kp  # type: ignore[attr-defined]
        Kd: FloatArray = self._Kd  # type: ignore[attr-defined]
        spring = e
        if self.sigma > 0.0:
            nv = float(np.linalg.norm(qd))
            if nv > 0.0:
                eta = qd / nv
            else:
                px = ev.P @ self._xi0  # type: ignore[attr-defined]
                npx = float(np.linalg.norm(px))
                eta = px / npx if npx > 0 else np.zeros_like(px)
            spring = e + self.sigma * float(np.linalg.norm(e)) * eta
        f_par = -(ev.P @ (ev.f_g + Kp @ spring + Kd @ qd))
        Mb, _ = mbar(ev)
        V = 0.5 * float(qd @ Mb @ qd) + 0.5 * float(e @ Kp @ e)
        return LawOutput(f_par, q_star, e, V)

    def lyapunov(
        self, q: ArrayLike, qd: ArrayLike, *, t: float = 0.0, active: Iterable[str] | None = None
    ) -> float:
        """``V = ½ qdᵀ M̄ qd + ½ eᵀ Kp e`` (paper eq. (V)); non-increasing along the closed loop
        for σ = 0, no saturation and a dissipative passive force."""
        return super().lyapunov(q, qd, t=t, active=active)

    def describe(self) -> dict[str, Any]:
        """Plain summary of the gains and options."""
        return {
            "type": "Regulator",
            "model": self.model.name,
            "target": self._q_star.tolist(),  # type: ignore[attr-defined]
            "Kp": self._Kp.tolist(),  # type: ignore[attr-defined]
            "Kd": self._Kd.tolist(),  # type: ignore[attr-defined]
            "sigma": self.sigma,
            "target_policy": self.target_policy,
            "metric": self.metric,
        }
