"""Consistent initial states: assemble ``q0`` onto ``φ = 0`` and ``qd0`` onto ``A qd + φ_t = 0``.

Both projections are minimum-kinetic-metric corrections (ERRATA, "Drift"):

* position: Gauss–Newton in the mass metric, ``q ← q + Sᵀ(−A⁺φ)``
  (:func:`nonmin.core.position_correction`), the minimizer of ``½ Δqᵀ M Δq`` subject to the
  linearized constraints ``A Δq = −φ``; M only needs to be positive definite on N(A);
* velocity: ``qd = qd_guess + Δ`` with ``Δ`` the minimizer of ``½ Δᵀ M Δ`` subject to
  ``A (qd_guess + Δ) + φ_t = 0``. With ``φ_t = 0`` this is the mass-orthogonal projection onto
  N(A), i.e. the plastic impact map ``M̄⁻¹ P M qd`` (:func:`nonmin.core.impact_map`); a
  rheonomic ``φ_t`` adds the particular solution of minimum kinetic energy.

Coordinates listed in ``fixed`` keep their guessed values (and velocities): they are appended
as extra rows ``q_j − q_j,guess = 0``.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from ..core import position_correction
from ..errors import (
    AssemblyError,
    InputError,
    NonFiniteError,
    NotPositiveDefiniteError,
    UnknownNameError,
)
from ._protocol import FloatArray, Model, State, _as_vector

__all__ = ["AssemblyResidual", "assemble", "assembly_residual", "consistent"]

#: Default absolute tolerance on ‖φ‖∞ and ‖A qd + φ_t‖∞.
ASSEMBLY_TOL = 1e-10


def _fixed_indices(model: Model, fixed: Iterable[int | str] | None) -> list[int]:
    if fixed is None:
        return []
    if isinstance(fixed, str | int):
        fixed = [fixed]
    out: list[int] = []
    names = model.coordinate_names
    for f in fixed:
        if isinstance(f, str):
            if f not in names:
                raise UnknownNameError(f"fixed: unknown coordinate {f!r}; known: {list(names)}")
            out.append(names.index(f))
        else:
            i = int(f)
            if not 0 <= i < model.n:
                raise InputError(f"fixed: coordinate index must be in [0, {model.n}), got {i}")
            out.append(i)
    return sorted(set(out))


def _with_fixed(A: FloatArray, r: FloatArray, fixed: list[int], n: int) -> tuple[FloatArray, FloatArray]:
    if not fixed:
        return A, r
    E = np.zeros((len(fixed), n))
    E[np.arange(len(fixed)), fixed] = 1.0
    return np.vstack([A, E]), np.concatenate([r, np.zeros(len(fixed))])


def _norm(x: FloatArray) -> float:
    return float(np.max(np.abs(x))) if x.size else 0.0


def assemble(
    model: Model,
    q_guess: ArrayLike,
    qd_guess: ArrayLike | None = None,
    *,
    t: float = 0.0,
    active: Iterable[str] | None = None,
    fixed: Iterable[int | str] | None = None,
    tol: float = ASSEMBLY_TOL,
    max_iter: int = 100,
    rtol: float | None = None,
) -> State:
    """A consistent :class:`State` near ``(q_guess, qd_guess)``.

    Parameters
    ----------
    model : Model
    q_guess : array_like, shape (n,)
    qd_guess : array_like, shape (n,), optional
        Zero if omitted.
    t : float
        Time (rheonomic constraints).
    active : iterable of str, optional
        Active constraints (default ``model.default_active``); active unilateral rows are
        assembled as equalities ``gap = 0``.
    fixed : iterable of int or str, optional
        Coordinates (indices or names) whose guessed position and velocity are kept.
    tol : float
        Absolute tolerance on ``‖φ‖∞`` and ``‖A qd + φ_t‖∞``.
    max_iter : int
        Maximum number of Gauss–Newton iterations.
    rtol : float, optional
        Rank tolerance of the pseudo-inverse (see :mod:`nonmin.core.linalg`).

    Returns
    -------
    State
        ``q`` with ``‖φ(q)‖∞ ≤ tol`` and ``qd`` with ``‖A qd + φ_t‖∞ ≤ tol``.

    Raises
    ------
    AssemblyError
        If Gauss–Newton does not reach ``tol`` (the message gives the residual), or if the
        velocity equations cannot be satisfied.
    """
    n = model.n
    act = model.resolve_active(active)
    q = _as_vector(q_guess, "q_guess", n).copy()
    qd = np.zeros(n) if qd_guess is None else _as_vector(qd_guess, "qd_guess", n).copy()
    if not (np.isfinite(q).all() and np.isfinite(qd).all()):
        raise NonFiniteError("q_guess and qd_guess must be finite")
    if not tol > 0:
        raise InputError(f"tol must be > 0, got {tol}")
    idx = _fixed_indices(model, fixed)
    q_fixed, qd_fixed = q[idx].copy(), qd[idx].copy()
    zeros = np.zeros(n)

    # ---- positions: Gauss–Newton in the mass metric
    res = np.inf
    it = 0
    for it in range(max_iter + 1):
        ct = model.constraint_terms(t, q, zeros, act)
        hol = ct.holonomic
        phi = ct.phi[hol]
        res = _norm(phi)
        if not np.isfinite(res):
            raise AssemblyError(f"assemble: the constraint residual became non-finite after {it} iterations")
        if res <= tol or it == max_iter:
            break
        A, r = _with_fixed(ct.A[hol], phi, idx, n)
        try:
            dq = position_correction(model.mass_matrix(q), A, r, rtol=rtol)
        except NotPositiveDefiniteError as exc:
            raise AssemblyError(f"assemble: M is not positive definite on N(A) at iteration {it}: {exc}") from exc
        q = q + dq
        q[idx] = q_fixed  # exactly, not only to round-off
        if _norm(dq) <= 1e-3 * tol and res > tol:
            # stagnation: a least-squares point that is not on the manifold
            ct = model.constraint_terms(t, q, zeros, act)
            res = _norm(ct.phi[ct.holonomic])
            break
    if not res <= tol:
        raise AssemblyError(
            f"assemble: could not assemble the positions of model {model.name!r}: "
            f"‖φ‖∞ = {res:.3e} > tol = {tol:.1e} after {it} Gauss–Newton iterations "
            "(constraints incompatible with the guess or with each other?)"
        )

    # ---- velocities: minimum kinetic-metric correction onto A qd + φ_t = 0
    for _ in range(2):
        ct = model.constraint_terms(t, q, qd, act)
        vel = ct.velocity
        if _norm(vel) <= 0.1 * tol:
            break
        A, r = _with_fixed(ct.A, vel, idx, n)
        try:
            qd = qd + position_correction(model.mass_matrix(q), A, r, rtol=rtol)
            qd[idx] = qd_fixed
        except NotPositiveDefiniteError as exc:
            raise AssemblyError(f"assemble: M is not positive definite on N(A): {exc}") from exc
    vres = _norm(model.constraint_terms(t, q, qd, act).velocity)
    if not vres <= tol:
        raise AssemblyError(
            f"assemble: could not satisfy the velocity constraints of model {model.name!r}: "
            f"‖A qd + φ_t‖∞ = {vres:.3e} > tol = {tol:.1e} (inconsistent rheonomic rates or "
            "fixed velocities?)"
        )
    return model.state(q, qd, t=t, active=act)


@dataclass(frozen=True)
class AssemblyResidual:
    """Residuals of a state against its active constraints.

    Attributes
    ----------
    position : float
        ``‖φ‖∞`` over the active rows with a position level.
    velocity : float
        ``‖A qd + φ_t‖∞`` over the active rows.
    penetration : float
        Largest violation ``max(0, −gap)`` of the *inactive* unilateral constraints.
    per_constraint : dict of str to (float, float)
        ``(‖φ‖∞, ‖A qd + φ_t‖∞)`` of each active constraint.
    """

    position: float
    velocity: float
    penetration: float
    per_constraint: dict[str, tuple[float, float]]

    def ok(self, tol: float = ASSEMBLY_TOL) -> bool:
        """True when all three residuals are at most ``tol``."""
        return max(self.position, self.velocity, self.penetration) <= tol


def assembly_residual(model: Model, state: State) -> AssemblyResidual:
    """Residuals of ``state`` (positions, velocities, penetrations of inactive contacts)."""
    ct = model.constraint_terms(state.t, state.q, state.qd, state.active)
    per: dict[str, tuple[float, float]] = {}
    for name, sl in model.row_slices(state.active).items():
        hol = ct.holonomic[sl]
        per[name] = (_norm(ct.phi[sl][hol]), _norm(ct.velocity[sl]))
    unil = [c.name for c in model.constraints if c.kind == "unilateral" and c.name not in state.active]
    pen = 0.0
    if unil:
        gaps = model.constraint_terms(state.t, state.q, state.qd, unil).phi
        pen = float(max(0.0, -float(np.min(gaps))))
    return AssemblyResidual(
        position=_norm(ct.phi[ct.holonomic]),
        velocity=_norm(ct.velocity),
        penetration=pen,
        per_constraint=per,
    )


def consistent(model: Model, state: State, tol: float = ASSEMBLY_TOL) -> bool:
    """True when ``state`` satisfies its active constraints to ``tol`` (see :func:`assembly_residual`)."""
    return assembly_residual(model, state).ok(tol)
