"""Linearization of the projection dynamics on the tangent space of the constraint manifold.

State coordinates (``docs/linear.md``). With ``Z_q`` (n × n_z) an orthonormal basis of N(A_h)
at the operating point (A_h: the active rows with a position level — holonomic, rheonomic,
unilateral) and ``Z`` (n × n_v) one of N(A) (all active rows, nonholonomic included):

    z = Z_qᵀ (q − q₀)  ∈ R^{n_z},     v = Zᵀ q̇  ∈ R^{n_v},     x = (z, v).

These are exact local coordinates of the state manifold ``{φ(q) = 0, A(q) q̇ = 0}`` (a graph
over its tangent space), so ``ż = Z_qᵀ q̇`` and ``v̇ = Zᵀ q̈`` hold exactly. A tangent vector
``(δz, δv)`` is the state deviation

    δq = Z_q δz,       δq̇ = Z δv + K Z_q δz,     K δq = −(DA)⁺ D (∂A/∂q · δq) q̇₀,

where ``K`` is the curvature (second-order geometry) of the manifold: differentiating
``A(q) q̇ = 0`` keeps the perturbed velocity admissible (it vanishes at rest). Then

    δż = Z_qᵀ (Z δv + K Z_q δz),
    δv̇ = Zᵀ (∂q̈/∂q δq + ∂q̈/∂q̇ δq̇ + ∂q̈/∂f B_f δu),

with the exact derivatives of :mod:`._derivatives` (forward mode, analytic kernel). For
holonomic systems ``Z_q = Z`` and ``δż = δv``; for nonholonomic rows n_z > n_v. At a singular
configuration N(A) is larger than the tangent space of any branch through the point: the
linearization uses N(A(q₀)) (the span of the tangents of all branches; the rank-r solution of
the kernel there) and says so (:attr:`LinearSystem.singular`, :attr:`LinearSystem.note`).
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..core.linalg import DEFAULT_RTOL, range_basis, resolve_rtol
from ..errors import InputError, MissingDependencyError, ModelError, ShapeError
from ..model import Model
from ._cone import quadratic_cone
from ._derivatives import _kernel_point, _kernel_tangent, _vector, term_tangents

FloatArray = NDArray[np.float64]

__all__ = [
    "BRANCH_STEP",
    "Branches",
    "Equilibrium",
    "LinearSystem",
    "ModeMotion",
    "Modes",
    "branch_tangent",
    "branches",
    "equilibrium",
    "linearize",
    "modes",
]

#: Relative step of the configurations probed near q₀ to tell a singular configuration (rank of
#: A rises at first order along a tangent direction) from redundant constraints (it does not:
#: off the manifold by ~step², far below the rank tolerance).
SINGULAR_PROBE = 1e-6


@dataclass(frozen=True)
class LinearSystem:
    """A linearization ``ẋ = A x + B δu``, ``y = C x + D δu`` in tangent coordinates.

    Attributes
    ----------
    A : ndarray, shape (n_x, n_x)
        State matrix, ``n_x = n_z + n_v``, state ``x = (z, v)`` (module docstring).
    B : ndarray, shape (n_x, p)
        Input matrix of the p inputs.
    C : ndarray, shape (2n, n_x)
        Output map to the dependent coordinates: ``y = (δq, δq̇)``.
    D : ndarray, shape (2n, p)
        Zero.
    q, qd : ndarray, shape (n,)
        Operating point.
    u : ndarray, shape (k,)
        Actuator inputs at the operating point.
    t : float
    active : frozenset of str
    inputs : str
        ``"actuators"`` (δu are the actuator forces), ``"forces"`` (generalized forces) or
        ``"matrix"`` (the columns of a given input map).
    input_map : ndarray, shape (n, p)
        Generalized force of each input (``B(q₀)`` for actuators).
    Zq : ndarray, shape (n, n_z)
        Orthonormal basis of N(A_h(q₀)): ``δq = Zq z``.
    Zv : ndarray, shape (n, n_v)
        Orthonormal basis of N(A(q₀)): ``δq̇ = Zv v + Kq z``.
    Kq : ndarray, shape (n, n_z)
        Curvature term of the velocity map (zero at rest).
    drift : ndarray, shape (n_x,)
        ``ẋ`` at the operating point (zero at an equilibrium): the system is affine,
        ``ẋ = drift + A x + B δu``.
    rank : int
        Rank of the active A at q₀ used by the kernel.
    generic_rank : int
        Largest rank of A found at configurations 1e-6 away along the tangent space.
    singular : bool
        ``rank < generic_rank``: q₀ is a singular configuration (the tangent space used is
        N(A(q₀)), larger than any branch's).
    note : str
        Which tangent space was used, in words.
    branch : ndarray, shape (n,), or None
        At a singular configuration linearized on one branch (``linearize(..., branch=d)``):
        the unit tangent of that branch at q₀ found from ``d``; None otherwise.
    """

    A: FloatArray
    B: FloatArray
    C: FloatArray
    D: FloatArray
    q: FloatArray
    qd: FloatArray
    u: FloatArray
    t: float
    active: frozenset[str]
    inputs: str
    input_map: FloatArray
    Zq: FloatArray
    Zv: FloatArray
    Kq: FloatArray
    drift: FloatArray
    rank: int
    generic_rank: int
    singular: bool
    note: str = field(default="")
    branch: FloatArray | None = None

    @property
    def tangent_dim(self) -> int:
        """n_z: dimension of the configuration tangent space used."""
        return int(self.Zq.shape[1])

    @property
    def velocity_dim(self) -> int:
        """n_v: dimension of the admissible velocities N(A)."""
        return int(self.Zv.shape[1])

    def to_dependent(self, x: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """The state deviation ``(δq, δq̇)`` in dependent coordinates of ``x``, shape (n_x,) or
        (n_x, N) (columns); returns arrays of shape (n,) or (n, N)."""
        xa = np.asarray(x)
        if xa.shape[0] != self.A.shape[0]:
            raise ShapeError(f"x must have {self.A.shape[0]} rows, got shape {xa.shape}")
        nz = self.tangent_dim
        z, v = xa[:nz], xa[nz:]
        return self.Zq @ z, self.Zv @ v + self.Kq @ z

    def from_dependent(self, q: ArrayLike, qd: ArrayLike) -> FloatArray:
        """Tangent coordinates ``x = (Zqᵀ (q − q₀), Zvᵀ q̇)`` of a nearby state, shape (n_x,)."""
        n = self.q.shape[0]
        qv = _vector(q, "q", n)
        vv = _vector(qd, "qd", n)
        return np.concatenate([self.Zq.T @ (qv - self.q), self.Zv.T @ vv])

    def to_control(self) -> Any:
        """The system as a python-control ``StateSpace`` (extra ``control``)."""
        try:
            import control  # type: ignore[import-not-found, import-untyped, unused-ignore]
        except ImportError:
            raise MissingDependencyError(
                "LinearSystem.to_control needs python-control: pip install 'nonmin[control]'"
            ) from None
        return control.ss(self.A, self.B, self.C, self.D)


def _position_rows(model: Model, act: frozenset[str]) -> NDArray[np.bool_]:
    mask: list[bool] = []
    for c in model.constraints:
        if c.name in act:
            mask.extend([c.kind != "nonholonomic"] * c.dim)
    return np.asarray(mask, dtype=bool)


def _null_basis(A: FloatArray, tol: float) -> tuple[FloatArray, int]:
    n = A.shape[1]
    if A.shape[0] == 0:
        return np.eye(n), 0
    r = int(range_basis(A, tol).rank)
    norms = np.linalg.norm(A, axis=1)
    live = norms > tol * max(float(norms.max()), 1e-300)
    Ae = np.where(live[:, None], A / np.where(live, norms, 1.0)[:, None], 0.0)
    Vh = np.linalg.svd(Ae, full_matrices=True)[2]
    return Vh[r:].T.copy(), r


def _input_map(model: Model, inputs: Any, B: FloatArray) -> tuple[str, FloatArray]:
    n = model.n
    if inputs is None:
        inputs = "actuators" if model.k > 0 else "forces"
    if isinstance(inputs, str):
        if inputs == "actuators":
            return "actuators", B
        if inputs == "forces":
            return "forces", np.eye(n)
        raise InputError(f"inputs must be 'actuators', 'forces' or an (n, p) array, got {inputs!r}")
    arr = np.asarray(inputs, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[0] != n:
        raise ShapeError(f"inputs must have shape ({n}, p), got shape {arr.shape}")
    return "matrix", arr


def linearize(
    model: Model,
    q: ArrayLike,
    qd: ArrayLike | None = None,
    f: ArrayLike | None = None,
    *,
    u: ArrayLike | None = None,
    inputs: str | ArrayLike | None = None,
    t: float = 0.0,
    active: Iterable[str] | None = None,
    rtol: float | None = None,
    branch: ArrayLike | int | None = None,
) -> LinearSystem:
    """Linearize the constrained dynamics at ``(q, q̇)`` in minimal tangent coordinates.

    Parameters
    ----------
    model : Model
        A planar model or a robot (its engine program is differentiated in forward mode).
    q : array_like, shape (n,)
        Configuration (on the manifold of the active position-level constraints).
    qd : array_like, shape (n,), optional
        Velocity in N(A(q)) (zero by default: linearization about a rest state).
    f : array_like, shape (n,), optional
        Applied generalized force at the operating point (besides the model's own).
    u : array_like, shape (k,), optional
        Actuator inputs at the operating point.
    inputs : {"actuators", "forces"} or array_like of shape (n, p), optional
        What δu is: actuator forces (default when the model has actuators), generalized forces
        (default otherwise), or the columns of a given input map.
    t : float
        Time (rheonomic constraints are frozen at t).
    active : iterable of str, optional
        Active constraints (default ``model.default_active``).
    rtol : float, optional
        Rank tolerance (default :data:`nonmin.core.DEFAULT_RTOL`).
    branch : array_like of shape (n,) or int, optional
        At a singular configuration: a velocity direction choosing the branch through q to
        linearize on (e.g. the velocity with which a motion arrives there), or a branch label:
        an index in :func:`branches` ``(model, q)``. The tangent of the
        branch nearest to it is found (:func:`branch_tangent`) and the result is the
        linearization of the dynamics *on that branch* at q: the limit of the (exact)
        linearizations at the branch's configurations ``q(±ε), q(±2ε)`` (ε =
        :data:`BRANCH_STEP`), symmetric and Richardson-extrapolated (error O(ε⁴)), in the
        branch's tangent coordinates; ``LinearSystem.branch`` is that tangent. Without it (the
        default) a singular configuration is linearized on N(A(q)), the span of the tangents
        of every branch (the kernel's rank-r solution there). Ignored at a regular
        configuration (one branch).

    Returns
    -------
    LinearSystem

    Examples
    --------
    >>> import numpy as np, nonmin
    >>> mech = nonmin.library.a01_pendulum()
    >>> lin = nonmin.linearize(mech.model, [0.0, -1.0])
    >>> lin.A.shape, bool(np.allclose(np.linalg.eigvals(lin.A).imag.max(), np.sqrt(9.81)))
    ((2, 2), True)
    """
    if not isinstance(model, Model):
        raise InputError(f"model must be a nonmin Model, got {type(model).__name__}")
    n, k = model.n, model.k
    qv = _vector(q, "q", n)
    vv = _vector(qd, "qd", n)
    uv = _vector(u, "u", k)
    fv = _vector(f, "f", n)
    tol = DEFAULT_RTOL if rtol is None else resolve_rtol(rtol)
    act = model.resolve_active(active)
    t = float(t)
    if isinstance(branch, int | np.integer) and not isinstance(branch, bool):
        found = branches(model, qv, t=t, active=act, rtol=rtol)
        if not 0 <= int(branch) < len(found):
            raise InputError(
                f"branch must be a velocity direction or a label in range({len(found)}) (the branches "
                f"found at q by nonmin.linear.branches), got {branch!r}"
            )
        branch = found[int(branch)][:, 0]
    dv = None if branch is None else _vector(branch, "branch", n)
    lin = _linearize_point(model, qv, vv, fv, uv, inputs, t, act, tol)
    r, nz = lin.rank, lin.tangent_dim
    generic = _generic_rank(model, qv, lin.Zq, t, act, tol, r)
    if generic <= r:
        note = f"regular configuration: tangent space N(A(q)) of dimension {nz} (rank A = {r})"
        return replace(lin, generic_rank=r, singular=False, note=note)
    if dv is None:
        note = (
            f"singular configuration: rank A = {r} here and {generic} at configurations "
            f"{SINGULAR_PROBE:g} away along the tangent space; the tangent space used is N(A(q)) of "
            f"dimension {nz}, the span of the tangents of every branch through q (the linearization "
            f"of the kernel's rank-{r} solution there); pass branch= (a velocity direction, or a "
            "label: an index in nonmin.linear.branches(model, q)) to linearize on one branch"
        )
        return replace(lin, generic_rank=generic, singular=True, note=note)
    return _branch_linearization(model, lin, dv, fv, inputs, tol, generic)


def _linearize_point(
    model: Model,
    qv: FloatArray,
    vv: FloatArray,
    fv: FloatArray,
    uv: FloatArray,
    inputs: Any,
    t: float,
    act: frozenset[str],
    tol: float,
    chart: tuple[FloatArray, FloatArray] | None = None,
) -> LinearSystem:
    """The linearization at (q, q̇) on N(A(q)) (no singularity probe: ``generic_rank = rank``).

    With ``chart = (Zb, Zvb)`` (bases near those of N(A_h(q)) and N(A(q))) the same dynamics is
    linearized in the chart ``x = (Zbᵀ (q − q₀), Zvbᵀ q̇)`` instead: ``δq = W δz`` with
    ``W = Zq (Zbᵀ Zq)⁻¹``, ``q̇ = U v`` with ``U = Zv (Zvbᵀ Zv)⁻¹``, whose derivative along δq
    at fixed v is ``(I − U Zvbᵀ) K δq`` (δZv = −G δAe Zv); exact, no approximation — used to
    express linearizations at nearby points in one chart (branches)."""
    n = model.n
    base = term_tangents(model, qv, vv, np.zeros((0, n)), t=t, active=act)
    A_all = base["A"]
    pos = _position_rows(model, act)
    Zv, r = _null_basis(A_all, tol)
    Zq, _ = _null_basis(A_all[pos], tol) if np.any(pos) else (np.eye(n), 0)
    nz, nv = Zq.shape[1], Zv.shape[1]
    kind, Bf = _input_map(model, inputs, base["B"])
    g = base["h"] + base["f_passive"] + fv + base["B"] @ uv
    kp = _kernel_point(base["M"], g, A_all, base["gamma"], tol)

    # directions (Zq e_i, 0): ∂q̈/∂q Zq and ∂A/∂q Zq (for the curvature term)
    t1 = term_tangents(model, qv, vv, Zq.T, None, t=t, active=act)
    dg1 = t1["dh"] + t1["df_passive"] + t1["dB"] @ uv
    Fq, _ = _kernel_tangent(kp, t1["dM"], dg1, t1["dA"], t1["dgamma"])  # (nz, n)
    if np.any(vv) and A_all.shape[0]:
        Kq = -(kp.G @ ((t1["dA"] @ vv) * kp.d[None, :]).T)  # (n, nz)
    else:
        Kq = np.zeros((n, nz))
    # directions (0, Zv e_j) and (0, Kq e_i): ∂q̈/∂q̇
    DV = np.vstack([Zv.T, Kq.T])
    t2 = term_tangents(model, qv, vv, np.zeros_like(DV), DV, t=t, active=act)
    dg2 = t2["dh"] + t2["df_passive"]
    Fqd, _ = _kernel_tangent(kp, t2["dM"], dg2, t2["dA"], t2["dgamma"])
    Fv, Fk = Fqd[:nv], Fqd[nv:]
    p = Bf.shape[1]
    Fu, _ = _kernel_tangent(
        kp,
        np.zeros((p, n, n)),
        Bf.T.copy(),
        np.zeros((p, *A_all.shape)),
        np.zeros((p, A_all.shape[0])),
    )

    if chart is None:
        Zb, Zvb = Zq, Zv
        W, U, KW = Zq, Zv, Kq
        FW, FU = Fq.T + Fk.T, Fv.T
    else:
        Zb, Zvb = chart
        if Zb.shape != Zq.shape or Zvb.shape != Zv.shape:
            raise ModelError(
                f"linearize: the tangent dimensions changed near the operating point ({Zq.shape[1]}, "
                f"{Zv.shape[1]} here, {Zb.shape[1]}, {Zvb.shape[1]} expected); try a smaller rtol"
            )
        Mi = np.linalg.inv(Zb.T @ Zq)
        Ni = np.linalg.inv(Zvb.T @ Zv)
        W, U = Zq @ Mi, Zv @ Ni
        KqW = Kq @ Mi  # K applied to the columns of W
        corr = Zvb.T @ KqW
        KW = KqW - U @ corr
        FU = Fv.T @ Ni
        FW = (Fq.T + Fk.T) @ Mi - FU @ corr
    Asys = np.zeros((nz + nv, nz + nv))
    Asys[:nz, :nz] = Zb.T @ KW
    Asys[:nz, nz:] = Zb.T @ U
    Asys[nz:, :nz] = Zvb.T @ FW
    Asys[nz:, nz:] = Zvb.T @ FU
    Bsys = np.vstack([np.zeros((nz, p)), Zvb.T @ Fu.T])
    C = np.block([[W, np.zeros((n, nv))], [KW, U]])
    D = np.zeros((2 * n, p))
    drift = np.concatenate([Zb.T @ vv, Zvb.T @ kp.qdd])
    Zq, Zv, Kq = Zb, Zvb, KW
    return LinearSystem(
        A=Asys, B=Bsys, C=C, D=D, q=qv, qd=vv, u=uv, t=t, active=act, inputs=kind, input_map=Bf,
        Zq=Zq, Zv=Zv, Kq=Kq, drift=drift, rank=r, generic_rank=r, singular=False,
    )  # fmt: skip


def _generic_rank(
    model: Model, q: FloatArray, Zq: FloatArray, t: float, act: frozenset[str], tol: float, r: int
) -> int:
    """Largest rank of the active A at configurations SINGULAR_PROBE·(1 + ‖q‖) away along
    three fixed pseudo-random tangent directions (a diagnostic; no derivative uses it)."""
    if Zq.shape[1] == 0:
        return r
    rng = np.random.default_rng(20261126)
    step = SINGULAR_PROBE * (1.0 + float(np.linalg.norm(q)))
    best = r
    zero = np.zeros_like(q)
    for _ in range(3):
        d = Zq @ rng.standard_normal(Zq.shape[1])
        d /= np.linalg.norm(d)
        A = model.constraint_terms(t, q + step * d, zero, act).A
        if A.shape[0]:
            best = max(best, int(range_basis(np.asarray(A, dtype=float), tol).rank))
    return best


# --------------------------------------------------------------------------- branches
#: Distance (relative to 1 + ‖q‖) of the branch configurations q(±ε), q(±2ε) whose exact
#: linearizations give a branch's linearization at a singular configuration (the symmetric,
#: Richardson-extrapolated limit has an error O(ε⁴); round-off grows like u/ε through the
#: smallest singular value of A ~ ε there).
BRANCH_STEP = 1e-2

#: Multiples of the step at which the branch is sampled on both sides; the symmetric averages
#: are extrapolated to step 0 by Lagrange interpolation in step² (error O(step^(2·levels))).
BRANCH_LEVELS = (1, 2, 3, 4)


def _richardson_weights(levels: tuple[int, ...]) -> list[float]:
    x = [float(lev * lev) for lev in levels]
    w = []
    for i, xi in enumerate(x):
        p = 1.0
        for j, xj in enumerate(x):
            if j != i:
                p *= xj / (xj - xi)
        w.append(p)
    return w


def _project(
    model: Model, q: FloatArray, t: float, act: frozenset[str], pos: NDArray[np.bool_]
) -> FloatArray:
    """The configuration on the manifold of the active position-level rows nearest to q
    (Gauss–Newton with minimal-norm steps)."""
    zero = np.zeros_like(q)
    scale = 1.0 + float(np.abs(q).max(initial=0.0))
    for _ in range(50):
        ct = model.constraint_terms(t, q, zero, act)
        phi = np.asarray(ct.phi, dtype=float)[pos]
        if float(np.abs(phi).max(initial=0.0)) <= 1e-15 * scale:
            return q
        A = np.asarray(ct.A, dtype=float)[pos]
        step = np.linalg.lstsq(A, phi, rcond=None)[0]
        q = q - step
        if float(np.abs(step).max()) <= 1e-16 * scale:
            return q
    raise ModelError(
        "linearize(branch=...): the configurations near q along the branch direction could not be "
        f"assembled (max |φ| = {float(np.abs(phi).max()):.3g}); is q on the manifold?"
    )


def branch_tangent(
    model: Model,
    q: ArrayLike,
    direction: ArrayLike,
    *,
    t: float = 0.0,
    active: Iterable[str] | None = None,
    rtol: float | None = None,
) -> FloatArray:
    """The unit tangent, at a singular configuration q, of the branch through q nearest to a
    direction.

    The direction is projected on N(A_h(q)) (A_h: the active position-level rows); the
    configuration q + ε d is assembled onto the manifold (minimal-norm Gauss–Newton, which
    lands on the branch nearest to it) and d is replaced by the direction of the chord
    ``q(+ε) − q(−ε)`` through the assembled points, until it no longer changes: a fixed point is
    a direction along which the manifold passes through q to second order, the tangent of a
    branch (to O(ε²), ε = 0.1·:data:`BRANCH_STEP`·(1 + ‖q‖)); it is then projected on the
    branch's limit tangent space, extrapolated from N(A_h) at the branch's configurations
    ±k·:data:`BRANCH_STEP`·(1 + ‖q‖), k = 1…4 (``A_h t`` ~1e-12 on A02). On a branch of
    dimension > 1 the result is one tangent vector of it.

    Parameters
    ----------
    model : Model
    q : array_like, shape (n,)
        A configuration on the manifold (typically a singular one).
    direction : array_like, shape (n,)
        A velocity direction (e.g. the velocity arriving at q), not in the range of A_hᵀ.
    t : float
    active : iterable of str, optional
    rtol : float, optional

    Returns
    -------
    ndarray, shape (n,)
        Unit tangent, oriented like ``direction``.

    Raises
    ------
    InputError
        When the direction has no component in N(A_h(q)) or no branch tangent is found near it.
    """
    n = model.n
    qv = _vector(q, "q", n)
    d0 = _vector(direction, "direction", n)
    tol = DEFAULT_RTOL if rtol is None else resolve_rtol(rtol)
    act = model.resolve_active(active)
    pos = _position_rows(model, act)
    A_h = np.asarray(model.constraint_terms(float(t), qv, np.zeros(n), act).A, dtype=float)[pos]
    Zq, _ = _null_basis(A_h, tol) if A_h.shape[0] else (np.eye(n), 0)
    d = _branch_tangent(model, qv, d0, Zq, float(t), act, pos)
    Zb = _branch_bases(model, qv, np.zeros(n), d, float(t), act, pos, tol)[2]
    d = Zb @ (Zb.T @ d)
    return d / float(np.linalg.norm(d))


@dataclass(frozen=True)
class Branches:
    """The branches through a configuration (:func:`branches`): a sequence of tangent bases.

    Indexing, ``len`` and iteration give the bases (``branches(model, q)[i]`` is branch label
    ``i`` of :func:`linearize`).

    Attributes
    ----------
    bases : tuple of ndarray, each of shape (n, k_b)
        Orthonormal bases of the branches' tangent spaces (k_b = 1 for a curve).
    certified : bool
        True when the list is complete: the second-order tangent cone was decomposed exactly
        into linear subspaces (:func:`nonmin.linear._cone.quadratic_cone`) and each subspace was
        confirmed as the limit tangent space of a branch through q (or q is regular). False
        when some step could not be made exact; the list then also holds what the sampled
        search found, and a branch can be missing (:attr:`note` says why).
    method : {"regular", "second-order cone", "second-order cone + sampling"}
    note : str
    """

    bases: tuple[FloatArray, ...]
    certified: bool
    method: str
    note: str

    def __len__(self) -> int:
        return len(self.bases)

    def __getitem__(self, i: int) -> FloatArray:
        return self.bases[i]

    def __iter__(self) -> Iterator[FloatArray]:
        return iter(self.bases)


def _left_null_localized(A: FloatArray, tol: float) -> FloatArray:
    """A basis (columns) of N(Aᵀ) in reduced row-echelon form: each vector has a pivot entry 1
    where the others are 0, so self-stresses of disjoint loops come out separated."""
    norms = np.linalg.norm(A, axis=1)
    live = norms > tol * max(float(norms.max(initial=0.0)), 1e-300)
    d = np.where(live, 1.0 / np.where(live, norms, 1.0), 0.0)
    Ae = A * d[:, None]
    U = np.linalg.svd(Ae, full_matrices=True)[0]
    r = int(range_basis(A, tol).rank)
    X = (U[:, r:] * d[:, None]).T.copy()  # rows: left-null vectors of A (w = D u)
    X[:, ~live] = 0.0
    dead = np.flatnonzero(~live)
    p, m = X.shape
    big = float(np.abs(X).max(initial=0.0))
    row = 0
    for j in range(m):
        if row == p:
            break
        i = row + int(np.argmax(np.abs(X[row:, j])))
        if abs(X[i, j]) <= 1e-9 * big:
            continue
        X[[row, i]] = X[[i, row]]
        X[row] /= X[row, j]
        for i2 in range(p):
            if i2 != row:
                X[i2] -= X[i2, j] * X[row]
        row += 1
    # rows of A that vanish at q are constraints whose own row is 0: their left-null direction
    # is e_i (its second-order form is its own Hessian)
    E = np.zeros((len(dead), m))
    E[np.arange(len(dead)), dead] = 1.0
    return np.vstack([X[:row], E]).T


def _second_order_forms(
    model: Model,
    q: FloatArray,
    Zq: FloatArray,
    t: float,
    act: frozenset[str],
    pos: NDArray[np.bool_],
    tol: float,
) -> list[FloatArray]:
    """H_i = Zqᵀ (Σ_j w_ij ∇²φ_j) Zq for a localized basis w_i of N(A_hᵀ) (module _cone): the
    Hessians from γ, the second time derivative of φ along q̇ (polarized: φ''[x, y] =
    (Q(x + y) − Q(x − y))/4 with Q(v) the part of γ(q, v) even in v)."""
    A_h = np.asarray(model.constraint_terms(t, q, np.zeros_like(q), act).A, dtype=float)[pos]
    W = _left_null_localized(A_h, tol)
    k = Zq.shape[1]

    def gam(v: FloatArray) -> FloatArray:
        return np.asarray(model.constraint_terms(t, q, v, act).gamma, dtype=float)[pos]

    def even(v: FloatArray) -> FloatArray:
        return gam(v) + gam(-v)

    Hs = np.zeros((W.shape[1], k, k))
    for a in range(k):
        for b in range(a, k):
            x, y = Zq[:, a], Zq[:, b]
            val = (even(x + y) - even(x - y)) / 8.0 if a != b else (even(x) - 2 * gam(0 * x)) / 2.0
            Hs[:, a, b] = Hs[:, b, a] = W.T @ val
    return [H for H in Hs]


def _confirm_branch(
    model: Model,
    q: FloatArray,
    B: FloatArray,
    t: float,
    act: frozenset[str],
    pos: NDArray[np.bool_],
    tol: float,
) -> str:
    """'' when the subspace B (n × l) is the tangent space of a branch through q; else why not.

    For each basis vector b of B, the configurations q + s·b (s = ±k·ε, k = 1…4, ε =
    :data:`BRANCH_STEP`·(1 + ‖q‖)) assembled onto the manifold (Gauss–Newton lands on the
    branch nearest to them) must stay within 10 s² of the line (a curve of the manifold
    tangent to b), and the limit at q of N(A_h) along it must contain B. That limit may be
    larger than B: a branch lying in the singular set (A_h loses rank all along it)."""
    scale = 1.0 + float(np.linalg.norm(q))
    for j in range(B.shape[1]):
        b = B[:, j]
        try:
            eps, states, Zb, _ = _branch_bases(model, q, np.zeros_like(q), b, t, act, pos, tol)
        except (InputError, ModelError) as exc:
            return f"no branch along a second-order admissible direction ({exc})"
        for lev, (qs, _) in states.items():
            off = float(np.linalg.norm(qs - q - lev * eps * b))
            if off > 10.0 * (lev * eps) ** 2 * scale:
                return (
                    f"the manifold near q + {lev * eps:.2g}·b is {off:.2g} away from that line: no "
                    "branch tangent to a second-order admissible direction (a higher-order obstruction)"
                )
        if Zb.shape[1] < B.shape[1] or float(np.linalg.norm(B - Zb @ (Zb.T @ B))) > 1e-6:
            return (
                f"the limit tangent space (dimension {Zb.shape[1]}) along a second-order admissible "
                f"subspace (dimension {B.shape[1]}) does not contain it"
            )
    return ""


def branches(
    model: Model,
    q: ArrayLike,
    *,
    t: float = 0.0,
    active: Iterable[str] | None = None,
    rtol: float | None = None,
    starts: int = 8,
) -> Branches:
    """The branches through a configuration, as orthonormal bases of their tangent spaces (the
    labels ``branch=0, 1, …`` of :func:`linearize` are indices in this list).

    Deterministic, from the second-order tangent cone (``docs/linear.md``): with Zq a basis of
    N(A_h(q)) (A_h: the active position-level rows) and w_i a basis of N(A_hᵀ), a branch's
    tangent v = Zq c satisfies cᵀ H_i c = 0, H_i = Zqᵀ (Σ_j w_ij ∇²φ_j) Zq (from γ, exact).
    The common zero set of these forms is decomposed exactly into linear subspaces
    (:func:`nonmin.linear._cone.quadratic_cone`: semidefinite forms restrict to their kernel,
    indefinite rank-2 forms split into two hyperplanes); each subspace is then confirmed as
    the limit tangent space of a branch (:func:`branch_tangent`'s chord fixed point and the
    limit of N(A_h) along it). :attr:`Branches.certified` says the list is complete. When a
    step cannot be made exact (a curved cone, a pencil with no splitting member found) or a
    subspace is not confirmed, the sampled search is added (±e_i, e_i ± e_j of Zq and
    ``starts`` fixed pseudo-random directions snapped to the nearest branch) and the result is
    not certified. Branches tangent to each other at q are one entry (second order cannot tell
    them apart). Ordered by their first basis vector (largest component positive, then
    lexicographically).

    Parameters
    ----------
    model : Model
    q : array_like, shape (n,)
        A configuration on the manifold.
    t : float
    active : iterable of str, optional
    rtol : float, optional
    starts : int
        Pseudo-random start directions of the sampled search (used only when not certified).

    Returns
    -------
    Branches
        One orthonormal basis (n, k_b) per branch; at a regular configuration the single basis
        of N(A_h(q)).
    """
    n = model.n
    qv = _vector(q, "q", n)
    tol = DEFAULT_RTOL if rtol is None else resolve_rtol(rtol)
    act = model.resolve_active(active)
    pos = _position_rows(model, act)
    t = float(t)
    zero = np.zeros(n)
    A_h = np.asarray(model.constraint_terms(t, qv, zero, act).A, dtype=float)[pos]
    Zq, r = _null_basis(A_h, tol) if A_h.shape[0] else (np.eye(n), 0)
    nz = Zq.shape[1]
    if nz == 0 or _generic_rank(model, qv, Zq, t, act, tol, r) <= r:
        return Branches((Zq,), True, "regular", f"regular configuration: rank A = {r}")
    cone = quadratic_cone(_second_order_forms(model, qv, Zq, t, act, pos, tol))
    found: list[FloatArray] = []
    problems = [] if cone.exact else [cone.reason]
    for L in cone.subspaces:
        B = Zq @ L
        why = _confirm_branch(model, qv, B, t, act, pos, tol)
        if why:
            problems.append(why)
        else:
            found.append(B)
    method = "second-order cone"
    if problems:
        method += " + sampling"
        for B in _sampled_branches(model, qv, Zq, t, act, pos, tol, starts):
            if not any(
                C.shape[1] == B.shape[1] and float(np.linalg.norm(B - C @ (C.T @ B))) <= 1e-6
                for C in found
            ):
                found.append(B)

    def key(B: FloatArray) -> tuple[float, ...]:
        b = B[:, 0] * (1.0 if B[int(np.argmax(np.abs(B[:, 0]))), 0] > 0 else -1.0)
        return tuple(-np.round(b, 6))

    out = []
    for B in sorted(found, key=key):
        j = int(np.argmax(np.abs(B[:, 0])))
        out.append(B if B[j, 0] > 0 else -B)
    note = (
        f"singular configuration (rank A = {r}, tangent space of dimension {nz}): "
        f"{len(out)} branch(es) from the second-order tangent cone"
    )
    if problems:
        note += "; not certified complete: " + "; ".join(problems)
    return Branches(tuple(out), not problems, method, note)


def _sampled_branches(
    model: Model,
    qv: FloatArray,
    Zq: FloatArray,
    t: float,
    act: frozenset[str],
    pos: NDArray[np.bool_],
    tol: float,
    starts: int,
) -> list[FloatArray]:
    """Branches found by snapping start directions to the nearest branch (may miss some)."""
    nz = Zq.shape[1]
    zero = np.zeros_like(qv)
    dirs: list[FloatArray] = []
    eye = np.eye(nz)
    for i in range(nz):
        dirs.append(eye[i])
        for j in range(i + 1, nz):
            dirs += [eye[i] + eye[j], eye[i] - eye[j]]
    rng = np.random.default_rng(20261126)
    dirs += list(rng.standard_normal((int(starts), nz)))
    found: list[FloatArray] = []
    for c in dirs:
        d0 = Zq @ c
        if any(
            float(np.linalg.norm(B.T @ d0)) >= (1.0 - 1e-6) * float(np.linalg.norm(d0))
            for B in found
        ):
            continue
        try:
            d = _branch_tangent(model, qv, d0, Zq, t, act, pos)
        except (InputError, ModelError):
            continue
        if any(float(np.linalg.norm(B.T @ d)) >= 1.0 - 1e-6 for B in found):
            continue
        found.append(_branch_bases(model, qv, zero, d, t, act, pos, tol)[2])
    return found


def _branch_tangent(
    model: Model,
    q: FloatArray,
    d0: FloatArray,
    Zq: FloatArray,
    t: float,
    act: frozenset[str],
    pos: NDArray[np.bool_],
) -> FloatArray:
    d = Zq @ (Zq.T @ d0)
    nd = float(np.linalg.norm(d))
    if nd <= 1e-12 * max(float(np.linalg.norm(d0)), 1e-300):
        raise InputError(
            "branch must be a velocity direction with a component in the tangent space N(A(q)) of the "
            f"position-level constraints, got {d0.tolist()}"
        )
    d = d / nd
    eps = 0.1 * BRANCH_STEP * (1.0 + float(np.linalg.norm(q)))  # a chord: a small step
    # one-sided first: q + ε d lands on the branch nearest to it
    qp = _project(model, q + eps * d, t, act, pos)
    d1 = Zq @ (Zq.T @ (qp - q))
    d = d1 / float(np.linalg.norm(d1))
    change = np.inf
    for _ in range(50):
        qp = _project(model, q + eps * d, t, act, pos)
        qm = _project(model, q - eps * d, t, act, pos)
        c = Zq @ (Zq.T @ (qp - qm))
        c /= float(np.linalg.norm(c))
        change = float(np.linalg.norm(c - d))
        d = c
        if change <= 1e-12:
            break
    off = float(np.linalg.norm(qp - q - eps * d))
    if change > 1e-6 or off > 10.0 * eps * eps * (1.0 + float(np.linalg.norm(q))):
        raise InputError(
            f"branch: no branch through q was found along the given direction (last change "
            f"{change:.2g}, distance of the branch point from the chord {off:.2g} at step {eps:.2g})"
        )
    return d if float(d @ d0) >= 0.0 else -d


def _branch_linearization(
    model: Model,
    lin: LinearSystem,
    d0: FloatArray,
    fv: FloatArray,
    inputs: Any,
    tol: float,
    generic: int,
) -> LinearSystem:
    q0, act, t = lin.q, lin.active, lin.t
    pos = _position_rows(model, act)
    d = _branch_tangent(model, q0, d0, lin.Zq, t, act, pos)
    eps, states, Zb, Zvb = _branch_bases(model, q0, lin.qd, d, t, act, pos, tol)
    nz = Zb.shape[1]
    d = Zb @ (Zb.T @ d)
    d /= float(np.linalg.norm(d))
    pts = {
        s: _linearize_point(model, qs, qds, fv, lin.u, inputs, t, act, tol, chart=(Zb, Zvb))
        for s, (qs, qds) in states.items()
    }
    Asys = _extrapolate({s: p.A for s, p in pts.items()})
    Bsys = _extrapolate({s: p.B for s, p in pts.items()})
    drift = _extrapolate({s: p.drift for s, p in pts.items()})
    C = _extrapolate({s: p.C for s, p in pts.items()})
    n = model.n
    Kq = C[n:, :nz]
    steps = ", ".join(f"±{lev * eps:.2g}" for lev in BRANCH_LEVELS)
    note = (
        f"singular configuration: rank A = {lin.rank} here and {generic} nearby; linearized on the "
        f"branch through q with tangent `branch` (tangent space of dimension {nz}, the limit of "
        f"N(A) along the branch): the exact linearizations, in one chart, at the branch's "
        f"configurations {steps} away, extrapolated to q (error O(step^{2 * len(BRANCH_LEVELS)}))"
    )
    return replace(
        lin, A=Asys, B=Bsys, C=C, D=np.zeros((2 * n, Bsys.shape[1])), Zq=Zb, Zv=Zvb, Kq=Kq,
        drift=drift, generic_rank=generic, singular=True, note=note, branch=d,
    )  # fmt: skip


def _extrapolate(values: dict[int, FloatArray]) -> FloatArray:
    """The limit at step 0 of values at ±lev·step (symmetric averages, Lagrange in step²)."""
    weights = _richardson_weights(BRANCH_LEVELS)
    return sum(  # type: ignore[return-value]
        w * 0.5 * (values[lev] + values[-lev])
        for lev, w in zip(BRANCH_LEVELS, weights, strict=True)
    )


def _branch_bases(
    model: Model,
    q0: FloatArray,
    qd0: FloatArray,
    d: FloatArray,
    t: float,
    act: frozenset[str],
    pos: NDArray[np.bool_],
    tol: float,
) -> tuple[float, dict[int, tuple[FloatArray, FloatArray]], FloatArray, FloatArray]:
    """The branch's states at ±lev·ε along d and the bases of the limit of N(A_h), N(A)."""
    eps = BRANCH_STEP * (1.0 + float(np.linalg.norm(q0)))
    levels = [sgn * lev for lev in BRANCH_LEVELS for sgn in (1, -1)]
    states: dict[int, tuple[FloatArray, FloatArray]] = {}
    proj_q: dict[int, FloatArray] = {}
    proj_v: dict[int, FloatArray] = {}
    for s in levels:
        qs = _project(model, q0 + s * eps * d, t, act, pos)
        A_all = np.asarray(model.constraint_terms(t, qs, np.zeros_like(qs), act).A, dtype=float)
        Zs, _ = _null_basis(A_all, tol)
        Zh, _ = _null_basis(A_all[pos], tol) if np.any(pos) else (np.eye(model.n), 0)
        states[s] = (qs, Zs @ (Zs.T @ qd0))  # the operating velocity made admissible there
        proj_q[s], proj_v[s] = Zh @ Zh.T, Zs @ Zs.T
    dims = {(round(float(np.trace(proj_q[s]))), round(float(np.trace(proj_v[s])))) for s in levels}
    if len(dims) != 1:
        raise ModelError(
            f"linearize(branch=...): the tangent dimensions differ along the branch {sorted(dims)}; "
            "try a smaller rtol"
        )
    nz, nv = dims.pop()

    def top(P: FloatArray, k: int) -> FloatArray:
        V = np.linalg.eigh(0.5 * (P + P.T))[1]
        Zt = np.ascontiguousarray(V[:, ::-1][:, :k])
        if k == 1 and float(Zt[:, 0] @ d) < 0:
            Zt = -Zt
        return Zt

    # one chart for every point: the bases of the limit of N(A) along the branch
    return eps, states, top(_extrapolate(proj_q), nz), top(_extrapolate(proj_v), nv)


# --------------------------------------------------------------------------- equilibria
@dataclass(frozen=True)
class Equilibrium:
    """A static equilibrium on the constraint manifold (:func:`equilibrium`).

    Attributes
    ----------
    q : ndarray, shape (n,)
        Configuration: ``φ(q) = 0`` (position-level rows) and ``q̈(q, 0) = 0``.
    u : ndarray, shape (k,)
        The actuator inputs held.
    residual : float
        ``max(‖φ‖∞, ‖q̈‖∞)`` at q.
    iterations : int
    converged : bool
    """

    q: FloatArray
    u: FloatArray
    residual: float
    iterations: int
    converged: bool


def equilibrium(
    model: Model,
    q_guess: ArrayLike,
    *,
    u: ArrayLike | None = None,
    f: ArrayLike | None = None,
    t: float = 0.0,
    active: Iterable[str] | None = None,
    tol: float = 1e-12,
    max_iter: int = 50,
    rtol: float | None = None,
    throw: bool = True,
) -> Equilibrium:
    """A static equilibrium near ``q_guess``: Gauss–Newton on ``[φ(q); q̈(q, 0)] = 0``.

    The Jacobian ``[A_h; ∂q̈/∂q]`` is exact (forward-mode terms, analytic kernel), so the
    iteration converges quadratically near a regular equilibrium.

    Parameters
    ----------
    model : Model
    q_guess : array_like, shape (n,)
        Start (need not satisfy the constraints).
    u : array_like, shape (k,), optional
        Actuator inputs held during the search (zero by default).
    f : array_like, shape (n,), optional
        Extra applied generalized force.
    t : float
    active : iterable of str, optional
    tol : float
        Stop when ``‖φ‖∞ ≤ tol·(1 + ‖q‖∞)`` and ``‖q̈‖∞ ≤ tol·(1 + ‖g‖)``-scaled, or the step
        falls below ``tol·(1 + ‖q‖)``.
    max_iter : int
    rtol : float, optional
        Rank tolerance.
    throw : bool
        Raise :class:`~nonmin.errors.ModelError` when the iteration does not converge
        (default); otherwise return the last iterate with ``converged=False``.

    Returns
    -------
    Equilibrium
    """
    if not isinstance(model, Model):
        raise InputError(f"model must be a nonmin Model, got {type(model).__name__}")
    n, k = model.n, model.k
    q = _vector(q_guess, "q_guess", n).copy()
    uv = _vector(u, "u", k)
    fv = _vector(f, "f", n)
    if not (isinstance(max_iter, int) and max_iter >= 1):
        raise InputError(f"max_iter must be an integer ≥ 1, got {max_iter!r}")
    tol_r = DEFAULT_RTOL if rtol is None else resolve_rtol(rtol)
    act = model.resolve_active(active)
    pos = _position_rows(model, act)
    zero = np.zeros(n)
    res = np.inf
    for it in range(1, max_iter + 1):
        tt = term_tangents(model, q, zero, np.eye(n), None, t=t, active=act)
        g = tt["h"] + tt["f_passive"] + fv + tt["B"] @ uv
        kp = _kernel_point(tt["M"], g, tt["A"], tt["gamma"], tol_r)
        dg = tt["dh"] + tt["df_passive"] + tt["dB"] @ uv
        Fq, _ = _kernel_tangent(kp, tt["dM"], dg, tt["dA"], tt["dgamma"])
        phi = tt["phi"][pos]
        scale_a = 1.0 + float(np.abs(g).max(initial=0.0)) / max(
            float(np.diag(tt["M"]).max(initial=1.0)), 1e-300
        )
        res_phi = float(np.abs(phi).max(initial=0.0))
        res_a = float(np.abs(kp.qdd).max(initial=0.0))
        res = max(res_phi, res_a)
        if res_phi <= tol * (1.0 + float(np.abs(q).max())) and res_a <= tol * scale_a:
            return Equilibrium(q=q, u=uv, residual=res, iterations=it - 1, converged=True)
        J = np.vstack([tt["A"][pos], Fq.T])
        rvec = np.concatenate([phi, kp.qdd])
        step = np.linalg.lstsq(J, -rvec, rcond=None)[0]
        q = q + step
        if float(np.linalg.norm(step)) <= tol * (1.0 + float(np.linalg.norm(q))):
            tt = term_tangents(model, q, zero, np.zeros((0, n)), t=t, active=act)
            g = tt["h"] + tt["f_passive"] + fv + tt["B"] @ uv
            kp = _kernel_point(tt["M"], g, tt["A"], tt["gamma"], tol_r)
            res = max(
                float(np.abs(tt["phi"][pos]).max(initial=0.0)),
                float(np.abs(kp.qdd).max(initial=0.0)),
            )
            return Equilibrium(q=q, u=uv, residual=res, iterations=it, converged=True)
    if throw:
        raise ModelError(
            f"equilibrium: no static equilibrium found from q_guess in {max_iter} Gauss–Newton steps "
            f"(last residual {res:.3g}); try another guess or larger max_iter"
        )
    return Equilibrium(q=q, u=uv, residual=res, iterations=max_iter, converged=False)


# --------------------------------------------------------------------------- modes
@dataclass(frozen=True)
class ModeMotion:
    """Samples of one mode's motion (:meth:`Modes.motion`): ``t`` (T,), ``q``, ``qd`` (T, n)."""

    t: FloatArray
    q: FloatArray
    qd: FloatArray


@dataclass(frozen=True)
class Modes:
    """Small-oscillation modes about an equilibrium (:func:`modes`).

    Attributes
    ----------
    eigenvalues : ndarray of complex, shape (n_x,)
        All eigenvalues of the linearization's state matrix.
    frequencies : ndarray, shape (p,)
        Natural frequency ``ω_n = |λ|`` (rad/s) of each mode, increasing.
    damped_frequencies : ndarray, shape (p,)
        ``|Im λ|`` (rad/s).
    damping_ratios : ndarray, shape (p,)
        ``ζ = −Re λ / |λ|`` (negative: the mode grows).
    shapes : ndarray of complex, shape (n, p)
        Mode shapes in dependent coordinates (``δq = Zq z`` of the eigenvector), scaled to a
        largest entry of 1 (real for undamped modes).
    system : LinearSystem
        The linearization they come from.
    mode_eigenvalues : ndarray of complex, shape (p,)
        The eigenvalue of each mode (the one with Im λ ≥ 0 of a pair).
    model : Model
        The model (for :meth:`motion`).
    """

    eigenvalues: NDArray[np.complex128]
    frequencies: FloatArray
    damped_frequencies: FloatArray
    damping_ratios: FloatArray
    shapes: NDArray[np.complex128]
    system: LinearSystem
    mode_eigenvalues: NDArray[np.complex128] = field(
        default_factory=lambda: np.zeros(0, dtype=np.complex128)
    )
    model: Any = field(default=None, repr=False, compare=False)

    def motion(
        self, i: int = 0, amplitude: float = 0.1, periods: float = 2.0, samples: int = 80
    ) -> ModeMotion:
        """The motion of mode i, ready to animate (``nonmin.viz.animate(m.motion(0), model,
        "mode.gif")``): ``q(t) = q_eq + amplitude · Re(shape e^{λt})`` assembled onto the
        manifold of the active position-level constraints at every sample, ``q̇`` the
        linear velocity made admissible there.

        Parameters
        ----------
        i : int
            Mode index (as in :attr:`frequencies`).
        amplitude : float
            Largest excursion of a dependent coordinate (shapes are scaled to a largest
            entry of 1).
        periods : float
            Duration in periods ``2π/|Im λ|`` (or in time constants ``1/|λ|`` for a real λ).
        samples : int
            Number of samples.

        Returns
        -------
        ModeMotion
            ``t`` (T,), ``q`` and ``qd`` (T, n).
        """
        if self.model is None or self.mode_eigenvalues.size != self.frequencies.size:
            raise InputError("Modes.motion needs the Modes returned by nonmin.modes")
        if not (isinstance(i, int | np.integer) and 0 <= int(i) < self.frequencies.size):
            raise InputError(f"i must be a mode index in range({self.frequencies.size}), got {i!r}")
        if not (np.isfinite(amplitude) and np.isfinite(periods) and periods > 0 and samples >= 2):
            raise InputError(
                f"amplitude must be finite, periods > 0 and samples ≥ 2, got {amplitude!r}, "
                f"{periods!r}, {samples!r}"
            )
        lam = complex(self.mode_eigenvalues[int(i)])
        shape = self.shapes[:, int(i)]
        scale = abs(lam.imag) if abs(lam.imag) > 0 else abs(lam)
        span = periods * (2.0 * np.pi if abs(lam.imag) > 0 else 1.0) / max(scale, 1e-300)
        t = np.linspace(0.0, span, int(samples))
        lin = self.system
        model = self.model
        pos = _position_rows(model, lin.active)
        qs, qds = [], []
        for tk in t:
            e = np.exp(lam * tk)
            q = _project(model, lin.q + amplitude * np.real(shape * e), lin.t, lin.active, pos)
            A = np.asarray(
                model.constraint_terms(lin.t, q, np.zeros_like(q), lin.active).A, dtype=float
            )
            Z, _ = _null_basis(A, DEFAULT_RTOL)
            qs.append(q)
            qds.append(Z @ (Z.T @ (amplitude * np.real(lam * shape * e))))
        return ModeMotion(t=t, q=np.array(qs), qd=np.array(qds))

    @property
    def stable(self) -> bool:
        """No eigenvalue with a positive real part (beyond 1e-9 of the largest |λ|)."""
        lam = self.eigenvalues
        scale = float(np.abs(lam).max(initial=0.0))
        return bool(np.all(lam.real <= 1e-9 * max(scale, 1e-300)))


def modes(
    model: Model,
    q_eq: ArrayLike,
    *,
    u: ArrayLike | None = None,
    t: float = 0.0,
    active: Iterable[str] | None = None,
    rtol: float | None = None,
    branch: ArrayLike | int | None = None,
) -> Modes:
    """Eigenfrequencies, damping ratios and mode shapes about the rest state ``(q_eq, 0)``.

    One mode per complex-conjugate pair of eigenvalues of :func:`linearize`'s state matrix; a
    real pair ``±a`` (a statically unstable degree of freedom) is one mode with frequency ``a``
    and damping ratio −1, and any other real eigenvalue is a mode of its own (``ζ = ±1``).
    Only tangent coordinates enter, so the virtual mass and the constraint directions add no
    spurious modes.

    Parameters
    ----------
    model : Model
    q_eq : array_like, shape (n,)
        An equilibrium configuration (e.g. :func:`equilibrium`'s ``q``); at another
        configuration the modes are those of the linearization there (``drift`` ≠ 0).
    u : array_like, shape (k,), optional
        Actuator inputs held.
    t : float
    active : iterable of str, optional
    rtol : float, optional
    branch : array_like, shape (n,), optional
        At a singular configuration, the modes on the branch nearest to this velocity
        direction (:func:`linearize`); default: on N(A(q)), the span of every branch's tangent.

    Returns
    -------
    Modes
    """
    lin = linearize(
        model, q_eq, None, u=u, t=t, active=active, rtol=rtol, inputs="forces", branch=branch
    )
    lam, V = np.linalg.eig(lin.A)
    scale = float(np.abs(lam).max(initial=0.0))
    tiny = 1e-9 * max(scale, 1e-300)
    keep = [i for i in range(lam.size) if lam[i].imag > tiny]  # one of each conjugate pair
    real = [i for i in range(lam.size) if abs(lam[i].imag) <= tiny]
    used: set[int] = set()
    for i in sorted(real, key=lambda i: -lam[i].real):  # a real pair ±a is one (divergent) mode
        if i in used:
            continue
        used.add(i)
        keep.append(i)
        for j in real:
            if j not in used and abs(lam[j].real + lam[i].real) <= 1e-8 * max(
                abs(lam[i].real), tiny
            ):
                used.add(j)
                break
    order = sorted(keep, key=lambda i: (abs(lam[i]), lam[i].real))
    nz = lin.tangent_dim
    freqs, dfreq, zeta, shapes = [], [], [], []
    for i in order:
        w = abs(lam[i])
        freqs.append(w)
        dfreq.append(abs(lam[i].imag))
        zeta.append(-lam[i].real / w if w > 0 else 0.0)
        s = lin.Zq @ V[:nz, i]
        j = int(np.argmax(np.abs(s)))
        if abs(s[j]) > 0:
            s = s / s[j]
        shapes.append(s)
    n = model.n
    shp = np.array(shapes).T if shapes else np.zeros((n, 0), dtype=complex)
    return Modes(
        eigenvalues=lam,
        frequencies=np.array(freqs, dtype=float),
        damped_frequencies=np.array(dfreq, dtype=float),
        damping_ratios=np.array(zeta, dtype=float),
        shapes=shp.astype(np.complex128),
        system=lin,
        mode_eigenvalues=np.array([lam[i] for i in order], dtype=np.complex128),
        model=model,
    )
