"""Shared machinery of the projection controllers: gains, model evaluation, actuation, limits.

Every controller in :mod:`nonmin.control` computes a desired *admissible* generalized force
``f_∥ ∈ N(A)`` (and, for force control, a constraint-direction part) and turns it into
actuator forces with ``Γ = (PB)⁺`` (ERRATA 4). This module holds the pieces they share:

* :func:`gain_matrix` — scalar, diagonal or full symmetric positive-definite gains;
* :func:`evaluate` — one evaluation of the model at ``(t, q, qd, active)`` (M, h, f_g, B, A,
  γ, P, rank) for the controllers;
* :func:`actuate` — ``u = Γ f_∥`` with the feasibility check ``rank(PB) = n − rank(A)``;
* :class:`ControlInfo` and :class:`ControlState` — what a controller reports (saturation flags,
  the smallest singular value of PB, infeasible evaluations) and what it carries in its state.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, replace
from typing import Literal, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..core import range_basis
from ..core.linalg import RangeBasis
from ..errors import (
    InfeasibleActuationError,
    InputError,
    NonFiniteError,
    ShapeError,
)
from ..model import Model

FloatArray = NDArray[np.float64]

InfeasiblePolicy = Literal["raise", "least_squares"]
INFEASIBLE_POLICIES: tuple[str, ...] = ("raise", "least_squares")

__all__ = [
    "ControlInfo",
    "ControlState",
    "Evaluation",
    "actuate",
    "evaluate",
    "gain_matrix",
]


def gain_matrix(x: ArrayLike, name: str, n: int, *, allow_zero: bool = False) -> FloatArray:
    """Coerce a gain to a symmetric positive-definite ``(n, n)`` matrix.

    Parameters
    ----------
    x : float, array_like of shape (n,) or (n, n)
        Scalar (``x I``), diagonal entries, or a full symmetric matrix.
    name : str
        Argument name used in error messages.
    n : int
        Number of coordinates.
    allow_zero : bool
        Accept positive *semi*-definite gains (e.g. a zero feed-back gain).

    Raises
    ------
    ShapeError, NonFiniteError, InputError
    """
    arr = np.asarray(x, dtype=float)
    if arr.ndim == 0:
        G = float(arr) * np.eye(n)
    elif arr.shape == (n,):
        G = np.diag(arr)
    elif arr.shape == (n, n):
        G = arr.copy()
    else:
        raise ShapeError(f"{name} must be a scalar, shape ({n},) or ({n}, {n}), got shape {arr.shape}")
    if not np.isfinite(G).all():
        raise NonFiniteError(f"{name} must be finite, got {G.tolist()}")
    if not np.allclose(G, G.T, rtol=1e-12, atol=0.0):
        raise InputError(f"{name} must be symmetric, got {G.tolist()}")
    ev = np.linalg.eigvalsh(0.5 * (G + G.T))
    bad = ev.min() < 0.0 if allow_zero else ev.min() <= 0.0
    if bad:
        kind = "positive semi-definite" if allow_zero else "positive definite"
        raise InputError(f"{name} must be {kind}, got smallest eigenvalue {ev.min():.3g}")
    return G


def limit_vector(x: ArrayLike | None, name: str, k: int, default: float) -> FloatArray:
    """Actuator limit as a ``(k,)`` vector (scalar broadcast; ``None`` means ``default``)."""
    if x is None:
        return np.full(k, default)
    arr = np.asarray(x, dtype=float)
    if arr.ndim == 0:
        arr = np.full(k, float(arr))
    if arr.shape != (k,):
        raise ShapeError(f"{name} must be a scalar or have shape ({k},) (one per actuator), got {arr.shape}")
    if np.isnan(arr).any():
        raise NonFiniteError(f"{name} must not contain NaN, got {arr.tolist()}")
    return arr


class Evaluation(NamedTuple):
    """Model quantities at one state, as the controllers use them.

    Attributes
    ----------
    M : ndarray, shape (n, n)
    h : ndarray, shape (n,)
        ``f_g − C qd``.
    f_g : ndarray, shape (n,)
        Conservative force ``−∂V/∂q``.
    f_p : ndarray, shape (n,)
        Passive (damper) force.
    B : ndarray, shape (n, k)
    A : ndarray, shape (m, n)
    gamma : ndarray, shape (m,)
        ``A qdd + γ = 0``.
    P : ndarray, shape (n, n)
        Null-space projector of A.
    rank : int
        Numerical rank of A.
    basis : RangeBasis
        Rank-revealing factorization of A (reused for ``A⁺`` solves).
    """

    M: FloatArray
    h: FloatArray
    f_g: FloatArray
    f_p: FloatArray
    B: FloatArray
    A: FloatArray
    gamma: FloatArray
    P: FloatArray
    rank: int
    basis: RangeBasis

    @property
    def dof(self) -> int:
        """``n − rank(A)``."""
        return self.M.shape[0] - self.rank


def state_vectors(model: Model, q: ArrayLike, qd: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Validate ``q`` and ``qd`` as finite ``(n,)`` vectors."""
    n = model.n
    qv = np.asarray(q, dtype=float)
    v = np.asarray(qd, dtype=float)
    for arr, nm in ((qv, "q"), (v, "qd")):
        if arr.shape != (n,):
            raise ShapeError(f"{nm} must have shape ({n},), got shape {arr.shape}")
        if not np.isfinite(arr).all():
            raise NonFiniteError(f"{nm} must be finite, got {arr.tolist()}")
    return qv, v


def evaluate(
    model: Model,
    t: float,
    q: FloatArray,
    qd: FloatArray,
    active: Iterable[str] | None,
    rtol: float | None,
) -> Evaluation:
    """Evaluate the model once for a controller (see :class:`Evaluation`)."""
    terms = model.evaluate(t, q, qd, active)
    A = terms.constraints.A
    basis = range_basis(np.asarray(A, dtype=float), rtol)
    P = basis.nullspace_projector()
    return Evaluation(
        M=terms.M,
        h=terms.h,
        f_g=model.conservative_force(q),
        f_p=terms.f_passive,
        B=terms.B,
        A=A,
        gamma=terms.constraints.gamma,
        P=P,
        rank=int(basis.rank),
        basis=basis,
    )


def actuate(
    ev: Evaluation,
    f_par: FloatArray,
    *,
    policy: InfeasiblePolicy,
    rtol: float | None,
    t: float,
) -> tuple[FloatArray, bool, FloatArray]:
    """Minimum-norm actuator forces ``u = Γ f_∥``, ``Γ = (PB)⁺`` (ERRATA 4).

    With ``rank(PB) = n − rank(A)`` the generalized force ``B u`` has exactly the null-space
    component ``P B u = f_∥`` (``PB (PB)⁺`` is the orthogonal projector onto ``R(PB) = N``).
    The rank of PB is decided as in :func:`nonmin.core.actuation_projectors` (singular values
    above ``rtol`` times the larger of ``σ_max(PB)`` and the largest column norm of B), from
    one SVD that also gives the singular values reported in :class:`ControlInfo`.

    Returns
    -------
    u : ndarray, shape (k,)
    feasible : bool
        Whether the actuation condition held.
    sigma : ndarray, shape (min(n, k),)
        Singular values of PB (descending).

    Raises
    ------
    InfeasibleActuationError
        When ``policy == "raise"`` and ``rank(PB) < n − rank(A)``.
    """
    from ..core.linalg import resolve_rtol

    n, k = ev.B.shape
    dof = ev.dof
    if k == 0:
        if dof > 0 and policy == "raise":
            raise InfeasibleActuationError(
                f"at t = {t:.6g}: the model has no actuators but n − rank(A) = {dof} > 0"
            )
        return np.zeros(0), dof == 0, np.zeros(0)
    PB = ev.P @ ev.B
    U, s, Vh = np.linalg.svd(PB, full_matrices=False)
    bscale = float(np.sqrt(np.max(np.sum(ev.B * ev.B, axis=0))))
    ref = max(float(s[0]) if s.size else 0.0, bscale, np.finfo(float).tiny)
    keep = s > resolve_rtol(rtol) * ref
    rank_pb = int(np.count_nonzero(keep))
    feasible = rank_pb >= dof
    if not feasible and policy == "raise":
        raise InfeasibleActuationError(
            f"at t = {t:.6g}: actuation is infeasible: rank(PB) = {rank_pb} < n − rank(A) = "
            f"{dof} (n = {n}, singular values of PB: {np.array2string(s, precision=3)}); the "
            "actuators cannot produce every admissible force (need N(A) ⊆ R(PB)); pass "
            "on_infeasible='least_squares' to apply the least-squares force instead"
        )
    inv_s = np.where(keep, 1.0 / np.where(keep, s, 1.0), 0.0)
    u = Vh.T @ (inv_s * (U.T @ f_par))
    return u, feasible, s


class ControlInfo(NamedTuple):
    """What a controller computed at one state (returned by ``controller.info(...)``).

    Attributes
    ----------
    u : ndarray, shape (k,)
        Actuator forces after saturation (what ``controller(...)`` returns).
    u_raw : ndarray, shape (k,)
        Actuator forces before saturation.
    saturated : ndarray of bool, shape (k,)
        Actuators at a limit.
    feasible : bool
        ``rank(PB) = n − rank(A)`` (and, for force control, the force rows are reachable).
    sigma_pb : ndarray, shape (min(n, k),)
        Singular values of ``PB``; the smallest nonzero one measures the distance to an
        actuation singularity.
    f_par : ndarray, shape (n,)
        Commanded admissible (null-space) generalized force ``f_∥``.
    target : ndarray, shape (n,)
        The (projected) reference configuration used.
    error : ndarray, shape (n,)
        ``q − q*``.
    lyapunov : float
        The controller's Lyapunov function at this state (NaN when it has none).
    """

    u: FloatArray
    u_raw: FloatArray
    saturated: NDArray[np.bool_]
    feasible: bool
    sigma_pb: FloatArray
    f_par: FloatArray
    target: FloatArray
    error: FloatArray
    lyapunov: float


@dataclass(frozen=True)
class ControlState:
    """Bookkeeping state of a controller (updated by :meth:`Controller.update`).

    Attributes
    ----------
    steps : int
        Number of accepted steps seen.
    saturated_steps : tuple of int
        Per actuator, the number of accepted steps that ended at a limit.
    saturated : tuple of bool
        Per actuator, whether it was at a limit after the last accepted step.
    infeasible_steps : int
        Accepted steps at which the actuation condition failed (``on_infeasible="least_squares"``).
    min_sigma_pb : float
        Smallest ``σ_min(PB)`` seen (distance to an actuation singularity).
    max_abs_u : tuple of float
        Per actuator, the largest ``|u_raw|`` requested.
    """

    steps: int = 0
    saturated_steps: tuple[int, ...] = ()
    saturated: tuple[bool, ...] = ()
    infeasible_steps: int = 0
    min_sigma_pb: float = float("inf")
    max_abs_u: tuple[float, ...] = ()

    @classmethod
    def initial(cls, k: int) -> ControlState:
        """Fresh state for ``k`` actuators."""
        return cls(
            saturated_steps=(0,) * k, saturated=(False,) * k, max_abs_u=(0.0,) * k
        )

    def record(self, info: ControlInfo) -> ControlState:
        """State after one more accepted step whose evaluation is ``info``."""
        k = info.u.shape[0]
        sat_steps = self.saturated_steps or (0,) * k
        max_u = self.max_abs_u or (0.0,) * k
        s_min = float(info.sigma_pb[-1]) if info.sigma_pb.size else 0.0
        return replace(
            self,
            steps=self.steps + 1,
            saturated_steps=tuple(int(c + int(b)) for c, b in zip(sat_steps, info.saturated)),
            saturated=tuple(bool(b) for b in info.saturated),
            infeasible_steps=self.infeasible_steps + (0 if info.feasible else 1),
            min_sigma_pb=min(self.min_sigma_pb, s_min),
            max_abs_u=tuple(max(a, abs(float(b))) for a, b in zip(max_u, info.u_raw)),
        )


def saturate(u: FloatArray, u_min: FloatArray, u_max: FloatArray) -> tuple[FloatArray, NDArray[np.bool_]]:
    """Clip ``u`` to ``[u_min, u_max]`` and flag the actuators at a limit."""
    us = np.clip(u, u_min, u_max)
    sat = (u <= u_min) | (u >= u_max)
    sat &= np.isfinite(u_min) | np.isfinite(u_max)
    return us, sat


def mbar(ev: Evaluation, mu: float | None = None) -> tuple[FloatArray, float]:
    """``M̄ = PMP + μQ`` (paper eq. (Mbar)) with ``μ = tr(PMP)/(n − r)`` unless given."""
    P = ev.P
    n = P.shape[0]
    PMP = P @ ev.M @ P
    if mu is None:
        dof = ev.dof
        m = float(np.trace(PMP)) / dof if dof > 0 else float(np.trace(ev.M)) / n
        m = m if m > 0 else 1.0
    else:
        m = float(mu)
    return PMP + m * (np.eye(n) - P), m
