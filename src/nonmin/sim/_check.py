"""Verify a model: A = ∂φ/∂q, γ = d(A qd)/dt, Christoffel C, M̄ positive definite, consistent
initial state, and the rank of A, cond(M̄) and μ along a short trajectory."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import InputError, NonminError
from ..model import Model, State

__all__ = ["CheckItem", "ModelReport", "check_model"]

#: Finite-difference tolerances (relative) of the derivative checks.
FD_RTOL = 1e-6
#: Tolerance of the initial-state consistency check.
CONSISTENCY_TOL = 1e-8


@dataclass(frozen=True)
class CheckItem:
    """One check: what, the measured value, the tolerance, and whether it passed."""

    name: str
    value: float
    tolerance: float
    passed: bool
    detail: str = ""


@dataclass(frozen=True)
class ModelReport:
    """Result of :func:`check_model`."""

    model: str
    items: tuple[CheckItem, ...]
    t: np.ndarray = field(repr=False)
    rank: np.ndarray = field(repr=False)
    cond_mbar: np.ndarray = field(repr=False)
    mu: np.ndarray = field(repr=False)
    rank_drops: tuple[float, ...] = ()

    @property
    def passed(self) -> bool:
        return all(i.passed for i in self.items)

    def format(self) -> str:
        """A plain-text table of the checks and the trajectory diagnostics."""
        lines = [f"model {self.model!r}", f"{'check':44s} {'value':>11s} {'tol':>9s}  result"]
        for it in self.items:
            res = "ok" if it.passed else "FAILED"
            lines.append(f"{it.name:44s} {it.value:11.3e} {it.tolerance:9.1e}  {res} {it.detail}")
        if self.t.size:
            lines.append(
                f"along t ∈ [{self.t[0]:.3g}, {self.t[-1]:.3g}] s ({self.t.size} samples): sampled rank A ∈ "
                f"[{int(self.rank.min())}, {int(self.rank.max())}], cond(M̄) ∈ "
                f"[{self.cond_mbar.min():.3g}, {self.cond_mbar.max():.3g}], μ ∈ "
                f"[{self.mu.min():.3g}, {self.mu.max():.3g}]"
            )
            if self.rank_drops:
                shown = ", ".join(f"{t:.4g}" for t in self.rank_drops[:10])
                more = f" (+{len(self.rank_drops) - 10} more)" if len(self.rank_drops) > 10 else ""
                lines.append(
                    f"rank of A drops at t = {shown}{more} s (σ_r/σ₁ of A has a local minimum "
                    f"below {NEAR_SINGULAR:g} there: singular or change points, which samples "
                    "rarely hit exactly)"
                )
            else:
                lines.append("rank of A constant along the trajectory (no near-singular point)")
            if self.cond_mbar.size and float(self.cond_mbar.max()) < 1.0 + 1e-9:
                lines.append("cond(M̄) = 1: one degree of freedom, μ equal to the one eigenvalue of PMP")
        lines.append("PASSED" if self.passed else "FAILED")
        return "\n".join(lines)


def _rel(err: float, ref: float) -> float:
    return err / max(ref, 1.0)


def _derivative_checks(
    model: Model, t: float, q: np.ndarray, qd: np.ndarray, active: frozenset[str]
) -> list[CheckItem]:
    items: list[CheckItem] = []
    n = model.n
    eps = 1e-6 * (1.0 + float(np.linalg.norm(q)))
    ct = model.constraint_terms(t, q, qd, active)
    A = ct.A
    hol = ct.holonomic
    if A.shape[0] and hol.any():
        J = np.zeros((A.shape[0], n))
        for j in range(n):
            dq = np.zeros(n)
            dq[j] = eps
            J[:, j] = (
                model.constraint_residual(t, q + dq, active)
                - model.constraint_residual(t, q - dq, active)
            ) / (2 * eps)
        err = float(np.max(np.abs(J[hol] - A[hol])))
        items.append(
            CheckItem(
                "A = ∂φ/∂q (central differences)",
                _rel(err, float(np.max(np.abs(A)))),
                FD_RTOL,
                _rel(err, float(np.max(np.abs(A)))) <= FD_RTOL,
            )
        )
    if A.shape[0]:
        kinds = []
        for c in model.constraints:
            if c.name in active:
                kinds.extend([c.kind] * c.dim)
        scl = np.array([k != "rheonomic" for k in kinds])
        nv = float(np.linalg.norm(qd))
        if scl.any() and nv > 0:
            h = eps / nv
            Ap = model.constraint_jacobian(t, q + h * qd, active)
            Am = model.constraint_jacobian(t, q - h * qd, active)
            fd = ((Ap - Am) / (2 * h)) @ qd
            err = float(np.max(np.abs(fd[scl] - ct.gamma[scl])))
            ref = float(np.max(np.abs(ct.gamma[scl])))
            items.append(
                CheckItem(
                    "γ = Ȧ qd (central differences)",
                    _rel(err, ref),
                    FD_RTOL,
                    _rel(err, ref) <= FD_RTOL,
                )
            )
    # Christoffel C: Ṁ − 2C skew, and C qd = Ṁ qd − ½ ∂(qdᵀ M qd)/∂q
    nv = float(np.linalg.norm(qd))
    v = qd if nv > 0 else np.linspace(1.0, 2.0, n)
    h = eps / float(np.linalg.norm(v))
    Mdot = (model.mass_matrix(q + h * v) - model.mass_matrix(q - h * v)) / (2 * h)
    C = model.coriolis_matrix(q, v)
    K = Mdot - 2 * C
    scale = max(float(np.max(np.abs(Mdot))), float(np.max(np.abs(C))), 1e-300)
    skew = float(np.max(np.abs(K + K.T))) / scale if scale > 1e-300 else 0.0
    items.append(CheckItem("Ṁ − 2C skew-symmetric (Christoffel C)", skew, FD_RTOL, skew <= FD_RTOL))
    grad = np.zeros(n)
    for j in range(n):
        dq = np.zeros(n)
        dq[j] = eps
        grad[j] = (v @ model.mass_matrix(q + dq) @ v - v @ model.mass_matrix(q - dq) @ v) / (
            2 * eps
        )
    lhs = C @ v
    rhs = Mdot @ v - 0.5 * grad
    ref = max(float(np.max(np.abs(rhs))), float(np.max(np.abs(lhs))))
    err = float(np.max(np.abs(lhs - rhs)))
    items.append(
        CheckItem(
            "C qd = Ṁ qd − ½ ∂(qdᵀMqd)/∂q",
            _rel(err, ref) if ref > 0 else err,
            FD_RTOL,
            (_rel(err, ref) if ref > 0 else err) <= FD_RTOL,
        )
    )
    # f_g = −∂V/∂q
    fg = model.conservative_force(q)
    g = np.zeros(n)
    for j in range(n):
        dq = np.zeros(n)
        dq[j] = eps
        g[j] = -(model.potential_energy(q + dq) - model.potential_energy(q - dq)) / (2 * eps)
    err = float(np.max(np.abs(g - fg)))
    ref = float(np.max(np.abs(fg)))
    items.append(
        CheckItem(
            "f_g = −∂V/∂q (central differences)", _rel(err, ref), FD_RTOL, _rel(err, ref) <= FD_RTOL
        )
    )
    return items


#: A configuration counts as a rank drop where the r-th singular value of the equilibrated A,
#: relative to the largest, has a local minimum below this value (or the rank is lower).
NEAR_SINGULAR = 1e-2


def _rank_drop_times(model: Model, traj: Any, rmax: int) -> tuple[float, ...]:
    """Times where A loses rank (exactly, or at a local minimum of σ_r/σ_1 < NEAR_SINGULAR)."""
    from ..core import range_basis

    if rmax == 0:
        return ()
    ratios = []
    for i in range(len(traj.t)):
        act = traj.active[i] if hasattr(traj, "active") else None
        A = model.constraint_jacobian(float(traj.t[i]), traj.q[i], act)
        b = range_basis(A)
        s = b.s
        ratios.append(float(s[rmax - 1] / s[0]) if s.size >= rmax and s[0] > 0 else 0.0)
    r = np.asarray(ratios)
    out = []
    for i in range(len(r)):
        left = r[i - 1] if i > 0 else np.inf
        right = r[i + 1] if i + 1 < len(r) else np.inf
        if r[i] < NEAR_SINGULAR and r[i] <= left and r[i] <= right:
            out.append(float(traj.t[i]))
    return tuple(out)


def check_model(
    model: Model,
    state: State | None = None,
    *,
    duration: float = 1.0,
    samples: int = 200,
    method: str = "rk4",
) -> ModelReport:
    """Verify a model and report rank of A, cond(M̄) and μ along a short trajectory.

    Parameters
    ----------
    model : Model
    state : State, optional
        Initial state; required unless ``model`` has a library default (pass the Mechanism's
        state).
    duration : float
        Length of the diagnostic trajectory [s] (0 to skip it).
    samples : int
        Number of stored samples along it.

    Returns
    -------
    ModelReport

    Raises
    ------
    InputError
        ``duration`` is not a finite number ≥ 0, or ``samples`` not an integer in [2, 10⁶].
    """
    try:
        dur = float(duration)
    except (TypeError, ValueError):
        raise InputError(f"check_model: duration must be a number of seconds, got {duration!r}") from None
    if not (math.isfinite(dur) and dur >= 0.0):
        raise InputError(f"check_model: duration must be a finite number ≥ 0 [s], got {duration!r}")
    if isinstance(samples, bool) or not isinstance(samples, int | np.integer) or not 2 <= samples <= 1_000_000:
        raise InputError(f"check_model: samples must be an integer in [2, 1000000], got {samples!r}")
    duration = dur
    if state is None:
        state = model.state(np.zeros(model.n))
    t, q, qd, active = state.t, state.q, state.qd, state.active
    items = _derivative_checks(model, t, q, qd, active)
    ct = model.constraint_terms(t, q, qd, active)
    phi = float(np.max(np.abs(ct.phi[ct.holonomic]))) if ct.holonomic.any() else 0.0
    vel = float(np.max(np.abs(ct.velocity))) if ct.velocity.size else 0.0
    items.append(
        CheckItem("initial state: max |φ(q0)|", phi, CONSISTENCY_TOL, phi <= CONSISTENCY_TOL)
    )
    items.append(
        CheckItem("initial state: max |A qd0 + φ_t|", vel, CONSISTENCY_TOL, vel <= CONSISTENCY_TOL)
    )
    from ..core import solve_dynamics

    try:
        terms = model.evaluate(t, q, qd, active)
        sol = solve_dynamics(
            terms.M, terms.h, terms.constraints.A, terms.constraints.gamma, terms.f_passive
        )
        d = np.diagonal(sol.L) ** 2
        items.append(
            CheckItem("M̄ positive definite (min pivot² / max)", float(d.min() / d.max()), 0.0, True)
        )
    except NonminError as exc:
        items.append(CheckItem("M̄ positive definite", float("nan"), 0.0, False, str(exc)))
        return ModelReport(
            model.name, tuple(items), np.zeros(0), np.zeros(0), np.zeros(0), np.zeros(0)
        )
    tt = np.zeros(0)
    rank = cond = mu = np.zeros(0)
    drops: tuple[float, ...] = ()
    if duration > 0:
        from ._simulate import simulate

        traj: Any = simulate(
            model,
            (t, t + duration),
            q,
            qd,
            active=active,
            method=method,
            t_eval=np.linspace(t, t + duration, samples),
            throw=False,
            progress=False,
        )
        tt = np.asarray(traj.t)
        rank = np.asarray(traj.rank)
        cond = np.asarray(traj.cond)
        mu = np.asarray(traj.mu)
        ok = str(getattr(traj.status, "name", traj.status)).lower() != "failed"
        items.append(
            CheckItem(
                "short trajectory integrates",
                0.0 if ok else 1.0,
                0.0,
                ok,
                "" if ok else str(traj.message),
            )
        )
        if rank.size:
            drops = _rank_drop_times(model, traj, int(rank.max()))
    return ModelReport(model.name, tuple(items), tt, rank, cond, mu, drops)
