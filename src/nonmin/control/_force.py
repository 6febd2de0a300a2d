"""Hybrid position/force control without Lagrange multipliers (corrected eq. (fc_fp)).

Split the generalized force ``f = B u = f_∥ + f_⊥`` (``f_∥ = P f``, ``f_⊥ = Q f``). The
constraint force of the projection dynamics is ``f_c = −S (f + h − M Ω qd)`` (eq. (fc_R)),
``S = I − M M̄⁻¹ P``; since ``S f_⊥ = f_⊥`` (``P f_⊥ = 0``) this is the corrected eq. (fc_fp)
(ERRATA 2)::

    f_⊥ + f_c = −S (f_∥ + h) + S M Ω qd.

So ``f_∥`` alone sets the motion (in N(A)) and, for given ``f_∥``, the constraint force is an
*affine* function of ``f_⊥``: ``f_c = c₀ − S f_∥ − f_⊥`` with ``c₀ = f_c|_{f=0}``. We evaluate
``c₀`` with the drift-tolerant kernel (:func:`nonmin.core.solve_dynamics` with ``f = 0``: for
admissible ``qd`` it equals ``−S h + S M Ω qd``), so the commanded force is exact for the same
dynamics the simulator integrates.

Which part of ``f_c`` is commanded: ``f_c ∈ R(Aᵀ)`` and the force carried by the rows of a named
constraint is read off as ``λ_F = E f_c`` with ``E`` the rows of ``(Aᵀ)⁺`` belonging to it
(unique when those rows are independent of the others; for a gap function with a unit
gradient, λ is the normal force in newtons, ``λ > 0`` pushing the bodies apart). Imposing
``E f_c = λ*`` and ``P B u = f_∥`` gives the linear system for u (``E Q = E``)::

    [ P B ]       [ f_∥                  ]
    [ E B ] u  =  [ E (c₀ − S f_∥) − λ*  ]

solved for the minimum-norm u. It is solvable for every target exactly when its matrix has
rank ``(n − rank A) + m_F``, i.e. when ``R(B)`` reaches the commanded constraint directions as
well as N(A); otherwise :class:`~nonmin.errors.InfeasibleActuationError` is raised.
When none of the named constraints is active the controller is just its motion controller, so
one controller serves free motion, impact and sustained contact.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike

from ..core import pseudo_inverse, solve_dynamics
from ..errors import InfeasibleActuationError, InputError
from ..model import Model
from ._base import LawOutput, ProjectedController
from ._common import Evaluation, FloatArray, InfeasiblePolicy, actuate, mbar

ForceTarget = float | ArrayLike | Callable[[float], ArrayLike]

__all__ = ["ForceControl", "constraint_force_components"]


def constraint_force_components(
    model: Model,
    t: float,
    q: ArrayLike,
    f_c: ArrayLike,
    names: Iterable[str],
    *,
    active: Iterable[str] | None = None,
    rtol: float | None = None,
) -> dict[str, FloatArray]:
    """Force carried by each named active constraint: the rows of ``(Aᵀ)⁺ f_c``.

    A read-out of a generalized constraint force ``f_c ∈ R(Aᵀ)`` (e.g. ``Trajectory.f_c``),
    not a multiplier solve. For a gap function with a unit gradient the value is the normal
    contact force (positive = pushing the bodies apart).

    Returns
    -------
    dict of str to ndarray, shape (dim,)
    """
    act = model.resolve_active(active)
    qv = np.asarray(q, dtype=float)
    fc = np.asarray(f_c, dtype=float)
    A = model.constraint_jacobian(t, qv, act)
    lam = pseudo_inverse(A, rtol).T @ fc if A.shape[0] else np.zeros(0)
    rows = model.row_slices(act)
    out = {}
    for nm in names:
        if nm not in rows:
            raise InputError(f"constraint {nm!r} is not active (active: {sorted(act)})")
        out[nm] = lam[rows[nm]]
    return out


@dataclass(frozen=True, eq=False)
class ForceControl(ProjectedController):
    """Hybrid position/force controller: a motion controller in N(A) plus commanded constraint forces.

    Parameters
    ----------
    motion : ProjectedController
        The motion controller (e.g. :class:`~nonmin.control.Regulator` or
        :class:`~nonmin.control.Tracker`) that sets ``f_∥``; its model is this controller's.
    forces : mapping of str to float, array_like or callable ``t -> array``
        Desired force carried by each named constraint (one value per row; see module
        docstring for the sign and units). Applied only while that constraint is active.
    u_min, u_max : float or array_like, shape (k,), optional
        Actuator limits (clipping spoils the commanded force; reported as saturation).
    on_infeasible : {"raise", "least_squares"}
    rtol : float, optional
    """

    motion: ProjectedController
    forces: Mapping[str, ForceTarget]
    u_min: ArrayLike | None = field(default=None, kw_only=True)
    u_max: ArrayLike | None = field(default=None, kw_only=True)
    on_infeasible: InfeasiblePolicy = field(default="raise", kw_only=True)
    rtol: float | None = field(default=None, kw_only=True)

    def __post_init__(self) -> None:
        if not isinstance(self.motion, ProjectedController):
            raise InputError(
                f"motion must be a ProjectedController (Regulator, Tracker), got {type(self.motion).__name__}"
            )
        self._validate_common()
        if not isinstance(self.forces, Mapping) or not self.forces:
            raise InputError("forces must be a non-empty mapping {constraint name: desired force}")
        for nm in self.forces:
            self.model.constraint(nm)  # raises UnknownNameError
        object.__setattr__(self, "forces", dict(self.forces))

    @property
    def model(self) -> Model:  # type: ignore[override]
        """The motion controller's model."""
        return self.motion.model

    def desired_force(self, name: str, t: float) -> FloatArray:
        """The commanded force of constraint ``name`` at time t, shape (dim,)."""
        spec = self.model.constraint(name)
        target = self.forces[name]
        val = target(t) if callable(target) else target
        arr = np.atleast_1d(np.asarray(val, dtype=float))
        if arr.shape != (spec.dim,) or not np.isfinite(arr).all():
            raise InputError(
                f"desired force of {name!r} must be finite with shape ({spec.dim},), got {arr!r}"
            )
        return arr

    def law(
        self, t: float, q: FloatArray, qd: FloatArray, ev: Evaluation, active: frozenset[str]
    ) -> LawOutput:
        """The motion controller's ``f_∥`` (the force part is in :meth:`actuation`)."""
        return self.motion.law(t, q, qd, ev, active)

    def actuation(
        self,
        t: float,
        q: FloatArray,
        qd: FloatArray,
        ev: Evaluation,
        out: LawOutput,
        active: frozenset[str],
    ) -> tuple[FloatArray, bool, FloatArray]:
        """Solve ``[PB; EB] u = [f_∥; E(c₀ − S f_∥) − λ*]`` (module docstring)."""
        names = [nm for nm in self.forces if nm in active]
        if not names:
            return actuate(ev, out.f_par, policy=self.on_infeasible, rtol=self.rtol, t=t)
        rows = self.model.row_slices(active)
        idx = np.concatenate([np.arange(rows[nm].start, rows[nm].stop) for nm in names])
        lam_star = np.concatenate([self.desired_force(nm, t) for nm in names])
        sol = solve_dynamics(ev.M, ev.h + ev.f_p, ev.A, ev.gamma, rtol=self.rtol)
        c0 = sol.f_c
        Mb, _ = mbar(ev, float(sol.mu))
        f_par = out.f_par
        S_fpar = f_par - ev.M @ np.linalg.solve(Mb, ev.P @ f_par)
        E = pseudo_inverse(ev.A, self.rtol)[:, idx].T
        G = np.vstack([ev.P @ ev.B, E @ ev.B])
        rhs = np.concatenate([f_par, E @ (c0 - S_fpar) - lam_star])
        U, s, Vh = np.linalg.svd(G, full_matrices=False)
        from ..core.linalg import resolve_rtol

        bscale = float(np.sqrt(np.max(np.sum(ev.B * ev.B, axis=0)))) if ev.B.size else 0.0
        ref = max(float(s[0]) if s.size else 0.0, bscale, np.finfo(float).tiny)
        keep = s > resolve_rtol(self.rtol) * ref
        need = ev.dof + idx.size
        rank = int(np.count_nonzero(keep))
        feasible = rank >= need
        if not feasible and self.on_infeasible == "raise":
            raise InfeasibleActuationError(
                f"at t = {t:.6g}: cannot command the force of {names} together with the motion: "
                f"rank([PB; EB]) = {rank} < (n − rank A) + m_F = {need}; the actuators do not "
                "reach the constraint directions (R(B) must contain N(A) and the commanded "
                "constraint-force directions)"
            )
        inv_s = np.where(keep, 1.0 / np.where(keep, s, 1.0), 0.0)
        u = Vh.T @ (inv_s * (U.T @ rhs))
        sig_pb: FloatArray = (
            np.asarray(np.linalg.svd(ev.P @ ev.B, compute_uv=False), dtype=float)
            if ev.B.size
            else np.zeros(0)
        )
        return u, feasible, sig_pb

    def measured_force(
        self, t: float, q: ArrayLike, f_c: ArrayLike, *, active: Iterable[str] | None = None
    ) -> dict[str, FloatArray]:
        """Read the force carried by the commanded constraints off ``f_c`` (active ones only)."""
        act = self.model.resolve_active(active)
        names = [nm for nm in self.forces if nm in act]
        return constraint_force_components(self.model, t, q, f_c, names, active=act, rtol=self.rtol)
