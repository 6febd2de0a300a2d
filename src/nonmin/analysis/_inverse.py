"""Inverse dynamics of constrained (closed-chain) systems without Lagrange multipliers.

Given a motion ``(q, q̇, q̈)`` and an input matrix B, find the actuator forces u with

    M q̈ + C q̇ = f_g + f_p + B u + f_c,     f_c ∈ R(Aᵀ) = N⊥.

Projecting onto N = N(A) with ``P = I − A⁺A`` removes the unknown constraint force
(``P f_c = 0``, eq. (fc_null_perp)) and leaves ``P B u = f_∥`` with the *required admissible
force* ``f_∥ = P (M q̈ − h − f_p)`` (``h = f_g − C q̇``). Its minimum-norm solution is the
paper's ``u = Γ f_∥``, ``Γ = (PB)⁺`` (eq. (p1_inverse), corrected per ERRATA 4); with a weight
W (SPD, k × k) the minimizer of ``uᵀ W u`` is ``u = L⁻ᵀ (P B L⁻ᵀ)⁺ f_∥`` with ``W = L Lᵀ``.
The generalized force the actuators then exert is ``B u`` (``R f_∥`` when W = I, ``R = BΓ``),
and the constraint force follows from the equations of motion,
``f_c = M q̈ − h − f_p − B u``.

Feasibility, reported rather than assumed:

* the motion is *consistent* with the constraints when ``A q̈ + γ = 0`` (and ``A q̇ + φ_t = 0``);
  otherwise no force whatever produces it (the residual is returned);
* it is *achievable by B* when ``f_∥ ∈ R(PB)``. Every consistent motion is achievable exactly
  when ``rank(PB) = n − rank A`` (the corrected actuation condition, ERRATA 4); an
  under-actuated B achieves only some motions, and u is then the least-squares solution with
  the unproduced force ``f_∥ − P B u`` returned;
* with ``rank(PB) < k`` the actuation is *redundant*: u is the minimum-(weighted-)norm member of
  a ``k − rank(PB)``-dimensional family of inputs that produce the same motion (they differ in
  internal preload, i.e. in ``f_c``).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, fields
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..core import actuation_projectors, nullspace_projector
from ..core.linalg import resolve_rtol
from ..errors import InfeasibleActuationError, InputError, NonFiniteError, ShapeError
from ..model._protocol import Model

FloatArray = NDArray[np.float64]

__all__ = ["FEASIBILITY_RTOL", "InverseDynamics", "inverse_dynamics"]

#: Relative tolerance of the feasibility verdicts: a residual is zero when it is at most
#: ``FEASIBILITY_RTOL`` times the scale of the terms it is made of.
FEASIBILITY_RTOL = 1e-8


@dataclass(frozen=True)
class InverseDynamics:
    """Result of :func:`inverse_dynamics` at one state, or stacked over N states (then every
    array gains a leading axis of length N and the verdicts and ranks are arrays of shape (N,)).

    Attributes
    ----------
    u : ndarray, shape (k,)
        Actuator inputs: minimum-norm (or minimum ``uᵀWu``) solution of ``P B u = f_∥``;
        least-squares when the motion is not achievable.
    f : ndarray, shape (n,)
        Generalized actuator force ``B u``.
    f_c : ndarray, shape (n,)
        Generalized constraint force ``M q̈ − h − f_p − B u`` projected on ``R(Aᵀ)`` (the part
        along N, if any, is ``f_unproduced``).
    f_required : ndarray, shape (n,)
        ``f_∥ = P (M q̈ − h − f_p)``, the admissible force the motion needs.
    f_unproduced : ndarray, shape (n,)
        ``f_∥ − P B u``: the part of the required force B cannot produce (0 when achievable).
    constraint_residual : ndarray, shape (m,)
        ``A q̈ + γ`` (0 when q̈ is consistent with the active constraints).
    velocity_residual : ndarray, shape (m,)
        ``A q̇ + φ_t``.
    consistent : bool
        ``‖A q̈ + γ‖ ≤ FEASIBILITY_RTOL · (‖A‖‖q̈‖ + ‖γ‖)`` and the same for the velocity.
    achievable : bool
        ``‖f_unproduced‖ ≤ FEASIBILITY_RTOL · scale`` (scale: ``‖M q̈‖ + ‖h‖ + ‖f_p‖``).
    rank : int
        Numerical rank r of the active A.
    rank_pb : int
        Rank of PB (decided against the actuators' own scale, as ``actuation_projectors``).
    dof : int
        ``n − r``.
    fully_actuated : bool
        ``rank_pb == dof``: every consistent motion is achievable.
    redundancy : int
        ``k − rank_pb``: dimension of the family of inputs giving the same motion.
    message : str
        One sentence per verdict that failed (empty when all hold).
    """

    u: FloatArray
    f: FloatArray
    f_c: FloatArray
    f_required: FloatArray
    f_unproduced: FloatArray
    constraint_residual: FloatArray
    velocity_residual: FloatArray
    consistent: bool
    achievable: bool
    rank: int
    rank_pb: int
    dof: int
    fully_actuated: bool
    redundancy: int
    message: str

    @property
    def ok(self) -> Any:
        """True when the motion is consistent and achievable (u reproduces it exactly); an
        array of shape (N,) for a trajectory."""
        both = np.logical_and(self.consistent, self.achievable)
        return bool(both) if np.ndim(both) == 0 else both


def _vector(x: ArrayLike, name: str, n: int) -> FloatArray:
    try:
        v = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be an array of numbers of shape ({n},), got {x!r}") from None
    if v.shape != (n,):
        raise ShapeError(f"{name} must have shape ({n},), got shape {v.shape}")
    if not np.isfinite(v).all():
        raise NonFiniteError(f"{name} must be finite, got {v.tolist()}")
    return v


def _weight_factor(weight: ArrayLike | None, k: int) -> FloatArray | None:
    """``L⁻ᵀ`` of ``W = L Lᵀ`` (None for W = I); a vector is a diagonal."""
    if weight is None:
        return None
    try:
        W = np.asarray(weight, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(
            f"weight must be a ({k}, {k}) matrix or a ({k},) vector, got {weight!r}"
        ) from None
    if W.shape == (k,):
        W = np.diag(W)
    if W.shape != (k, k):
        raise ShapeError(f"weight must have shape ({k}, {k}) or ({k},), got shape {W.shape}")
    if not np.isfinite(W).all():
        raise NonFiniteError("weight must be finite")
    if not np.allclose(W, W.T, rtol=1e-12, atol=1e-12 * float(np.max(np.abs(W), initial=0.0))):
        raise InputError("weight must be symmetric")
    try:
        L = np.linalg.cholesky(W)
    except np.linalg.LinAlgError:
        raise InputError(
            "weight must be positive definite (its Cholesky factorization failed)"
        ) from None
    return np.asarray(np.linalg.inv(L).T)


def _min_norm_ls(
    PB: FloatArray, b: FloatArray, bscale: float, tol: float
) -> tuple[FloatArray, int]:
    """Minimum-norm least-squares solution of ``PB x = b`` with the rank rule of
    ``actuation_projectors`` (singular values ≤ tol · max(σ₁, scale of B) are zero)."""
    if PB.shape[1] == 0:
        return np.zeros(0), 0
    U, s, Vh = np.linalg.svd(PB, full_matrices=False)
    ref = max(float(s[0]) if s.size else 0.0, bscale, np.finfo(float).tiny)
    keep = s > tol * ref
    x = Vh[keep].T @ ((U[:, keep].T @ b) / s[keep])
    return x, int(np.count_nonzero(keep))


def inverse_dynamics(
    model: Model,
    q: ArrayLike,
    qd: ArrayLike,
    qdd: ArrayLike,
    *,
    actuation: ArrayLike | None = None,
    weight: ArrayLike | None = None,
    t: float = 0.0,
    active: Iterable[str] | str | None = None,
    rtol: float | None = None,
) -> InverseDynamics:
    """Actuator inputs that produce a motion of a constrained system, with a feasibility diagnosis.

    ``u = Γ f_∥`` with ``Γ = (PB)⁺`` and ``f_∥ = P (M q̈ − h − f_p)`` (paper eq. (p1_inverse),
    corrected per ERRATA 4; see the module docstring); the constraint force is what the
    equations of motion leave, ``f_c = M q̈ − h − f_p − B u`` (no multipliers).

    Parameters
    ----------
    model : Model
    q, qd, qdd : array_like, shape (n,) or (N, n)
        The motion at one instant, or at N instants of a trajectory (q̇ admissible, q̈
        consistent: both are checked).
    actuation : array_like, shape (n, k), optional
        Input matrix B (``f = B u``); default the model's ``input_matrix(q)``.
    weight : array_like, shape (k, k) or (k,), optional
        SPD weight W: u minimizes ``uᵀ W u`` among the inputs that produce the motion
        (default W = I, the minimum-norm u of the paper's Γ).
    t : float or array_like, shape (N,)
        Time (drivers, rheonomic constraints).
    active : iterable of str, optional
        Active constraints (default the model's default active set).
    rtol : float, optional
        Rank tolerance of A and of PB (default :data:`nonmin.core.DEFAULT_RTOL`).

    Returns
    -------
    InverseDynamics
        u, the forces, the residuals and the verdicts ``consistent``, ``achievable``,
        ``fully_actuated`` and ``redundancy`` (stacked over the N states of a trajectory).

    Raises
    ------
    ShapeError, NonFiniteError, InputError
        Arrays of the wrong shape or not finite, a weight that is not SPD.

    Examples
    --------
    A pendulum in Cartesian coordinates (one rod), pushed by a horizontal force: the force
    that holds it at rest at 30° from the vertical.

    >>> import numpy as np, nonmin
    >>> from nonmin.model.planar import PlanarBuilder
    >>> b = PlanarBuilder("p")
    >>> _ = b.point_mass("m", mass=1.0, points=["bob"])
    >>> _ = b.rod("rod", ("ground", (0.0, 0.0)), "bob", length=1.0)
    >>> _ = b.force("push", "bob", direction=(1.0, 0.0))
    >>> m = b.build()
    >>> th = np.pi / 6
    >>> r = nonmin.inverse_dynamics(m, [np.sin(th), -np.cos(th)], [0, 0], [0, 0])
    >>> round(float(r.u[0]), 6), round(9.81 * np.tan(th), 6), r.ok
    (5.66381, 5.66381, True)
    """
    qa = np.asarray(q, dtype=np.float64) if not isinstance(q, np.ndarray) else q
    if np.ndim(qa) == 2:  # a trajectory: one state after the other, results stacked
        Q, QD, QDD = (np.asarray(x, dtype=np.float64) for x in (q, qd, qdd))
        N = Q.shape[0]
        for name, x in (("qd", QD), ("qdd", QDD)):
            if x.shape != Q.shape:
                raise ShapeError(f"{name} must have the shape of q {Q.shape}, got shape {x.shape}")
        try:
            T = np.broadcast_to(np.asarray(t, dtype=np.float64), (N,))
        except ValueError:
            raise ShapeError(
                f"t must be a scalar or have shape ({N},), got shape {np.shape(t)}"
            ) from None
        rows = [
            inverse_dynamics(
                model,
                Q[i],
                QD[i],
                QDD[i],
                actuation=actuation,
                weight=weight,
                t=float(T[i]),
                active=active,
                rtol=rtol,
            )
            for i in range(N)
        ]
        stacked: dict[str, Any] = {}
        for fld in fields(InverseDynamics):
            vals = [getattr(r, fld.name) for r in rows]
            if fld.name == "message":
                bad = [f"state {i}: {m}" for i, m in enumerate(vals) if m]
                stacked[fld.name] = "; ".join(bad[:5]) + (
                    f"; ... ({len(bad)} states)" if len(bad) > 5 else ""
                )
            else:
                stacked[fld.name] = np.array(vals)
        return InverseDynamics(**stacked)
    n = model.n
    qv = _vector(q, "q", n)
    v = _vector(qd, "qd", n)
    a = _vector(qdd, "qdd", n)
    act = model.resolve_active(active)
    tol = resolve_rtol(rtol)
    terms = model.evaluate(float(t), qv, v, act)
    if actuation is None:
        B = np.asarray(terms.B, dtype=np.float64)
    else:
        try:
            B = np.asarray(actuation, dtype=np.float64)
        except (TypeError, ValueError):
            raise InputError(
                f"actuation must be an (n, k) = ({n}, k) matrix, got {actuation!r}"
            ) from None
        if B.ndim != 2 or B.shape[0] != n:
            raise ShapeError(f"actuation must have shape ({n}, k), got shape {B.shape}")
        if not np.isfinite(B).all():
            raise NonFiniteError("actuation must be finite")
    k = B.shape[1]
    Linv_t = _weight_factor(weight, k)
    M = terms.M
    ct = terms.constraints
    A = ct.A
    P, r = nullspace_projector(A, rtol=tol)
    rank = int(r)
    dof = n - rank
    drive = M @ a - terms.h - terms.f_passive
    f_par = P @ drive
    PB = P @ B
    Bw = B if Linv_t is None else B @ Linv_t
    PBw = PB if Linv_t is None else PB @ Linv_t
    bscale = float(np.sqrt(np.max(np.einsum("ij,ij->j", Bw, Bw), initial=0.0)))
    x, rank_pb = _min_norm_ls(PBw, f_par, bscale, tol)
    if rank_pb == dof and k:
        # the paper's route: Γ = (P B_w)⁺ from the core kernel (engine), u = L⁻ᵀ Γ f_∥
        try:
            _, Gamma = actuation_projectors(Bw, P, rtol=tol)
            x = Gamma @ f_par
        except InfeasibleActuationError:  # pragma: no cover - same rank rule as above
            pass
    u = x if Linv_t is None else Linv_t @ x
    f = B @ u
    f_unproduced = f_par - P @ f
    f_c = (drive - f) - f_unproduced  # = Q (M q̈ − h − f_p − B u)
    cres = A @ a + ct.gamma if A.shape[0] else np.zeros(0)
    vres = np.asarray(ct.velocity, dtype=np.float64)
    nA = float(np.linalg.norm(A)) if A.size else 0.0
    c_scale = nA * float(np.linalg.norm(a)) + float(np.linalg.norm(ct.gamma))
    v_scale = nA * float(np.linalg.norm(v))
    consistent = bool(
        float(np.linalg.norm(cres)) <= FEASIBILITY_RTOL * max(c_scale, 1.0)
        and float(np.linalg.norm(vres)) <= FEASIBILITY_RTOL * max(v_scale, 1.0)
    )
    f_scale = (
        float(np.linalg.norm(M @ a))
        + float(np.linalg.norm(terms.h))
        + float(np.linalg.norm(terms.f_passive))
    )
    achievable = bool(
        float(np.linalg.norm(f_unproduced)) <= FEASIBILITY_RTOL * max(f_scale, 1e-300)
    )
    msgs = []
    if not consistent:
        msgs.append(
            f"qdd is not consistent with the active constraints: ‖A q̈ + γ‖ = "
            f"{np.linalg.norm(cres):.3g}, ‖A q̇ + φ_t‖ = {np.linalg.norm(vres):.3g}"
        )
    if not achievable:
        msgs.append(
            f"the motion is not achievable by the actuation: rank(PB) = {rank_pb} < n − rank(A) = {dof} "
            f"and ‖f_∥ − P B u‖ = {np.linalg.norm(f_unproduced):.3g} (least-squares u)"
            if rank_pb < dof
            else f"the motion is not achievable: ‖f_∥ − P B u‖ = {np.linalg.norm(f_unproduced):.3g}"
        )
    return InverseDynamics(
        u=u,
        f=f,
        f_c=f_c,
        f_required=f_par,
        f_unproduced=f_unproduced,
        constraint_residual=np.asarray(cres, dtype=np.float64),
        velocity_residual=vres,
        consistent=consistent,
        achievable=achievable,
        rank=rank,
        rank_pb=rank_pb,
        dof=dof,
        fully_actuated=rank_pb == dof,
        redundancy=k - rank_pb,
        message="; ".join(msgs),
    )
