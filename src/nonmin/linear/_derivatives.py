"""Derivatives of the projection dynamics: forward-mode model terms, analytic kernel derivative.

The accelerations of nonmin (corrected eq. (ddq_sim), the drift-tolerant form of
``docs/theory.md``) are ``q̈ = w + Z S⁻¹ Zᵀ (g − M w)`` with ``g = h + f_p + f``,
``w = −(DA)⁺ D γ``, ``Z`` an orthonormal basis of N(A) and ``S = Zᵀ M Z``; the constraint force
is ``f_c = M q̈ − g`` (eq. (fc_R)). They are characterized by

    Q q̈ = w,        P (M q̈ − g) = 0,        Q = I − P = A⁺A.

Differentiating both at a **fixed rank** r of A (the rank the kernel used) along a direction
of the model terms (δM, δg, δA, δγ) gives, with ``G = (DA)⁺`` (D the kernel's row scaling,
held fixed), ``Ae = DA``:

    δP  = −G δAe P − (G δAe P)ᵀ                               (Golub–Pereyra)
    δG  = −G δAe G + G Gᵀ δAeᵀ (I − Ae G) + P δAeᵀ Gᵀ G
    δw  = −δG D γ − G D δγ
    Q δq̈ = Q (δw + δP q̈)
    S y  = Zᵀ (δg − δM q̈ − M Q δq̈) − Zᵀ δP f_c,     P δq̈ = Z y
    δf_c = δM q̈ + M δq̈ − δg.

The directional derivatives of the model terms come from the engine's programs evaluated on
dual numbers (``engine/include/nonmin/dual.hpp``, ``Program::evaluate_tangent``): exact to
round-off, no step size. Where the rank changes (a singular configuration approached from a
regular one) q̈ is not differentiable; these formulas give the derivative of the rank-r
branch of the solution at the point (the one the kernel returns there).
"""

from __future__ import annotations

import threading
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..core.linalg import DEFAULT_RTOL, SPD_RTOL, range_basis, resolve_rtol
from ..errors import InputError, ModelError, NotPositiveDefiniteError, ShapeError
from ..model import Model

FloatArray = NDArray[np.float64]

__all__ = ["DynamicsDerivatives", "dynamics_derivatives", "term_tangents"]


# --------------------------------------------------------------------------- model terms
_ENGINE_MODULE: Any = None


def _engine() -> Any:
    """The compiled extension (imported on first use, then cached; no type stubs)."""
    global _ENGINE_MODULE
    if _ENGINE_MODULE is None:
        from .. import _engine as eng  # type: ignore[attr-defined]

        _ENGINE_MODULE = eng
    return _ENGINE_MODULE


def _program(model: Model) -> Any:
    prog = model.engine_program()
    if prog is None:
        raise ModelError(
            f"model {model.name!r} ({type(model).__name__}) has no compiled engine program, so its terms "
            "cannot be differentiated in forward mode (a model of Python functions or a planar model "
            "with a user-defined joint); nonmin.linear needs a planar, spatial, SymPy or robot model"
        )
    if not _engine().differentiable(prog):
        raise ModelError(
            f"model {model.name!r}: its engine program ({type(prog).__name__}) has no forward-mode "
            "evaluation (Program::evaluate_tangent); derivatives exist for planar and spatial "
            "models (PlanarProgram, SpatialProgram), SymPy models (TapeProgram) and robots "
            "(TreeProgram)"
        )
    return prog


def _active_rows(model: Model, prog: Any, act: frozenset[str]) -> NDArray[np.intp]:
    rows: list[int] = []
    by_name = {c[0]: (c[2], c[3]) for c in prog.constraints}
    for c in model.constraints:
        if c.name in act:
            r0, dim = by_name[c.name]
            rows.extend(range(r0, r0 + dim))
    return np.asarray(rows, dtype=np.intp)


def _vector(x: ArrayLike | None, name: str, n: int, default: float = 0.0) -> FloatArray:
    if x is None:
        return np.full(n, default)
    arr = np.asarray(x, dtype=np.float64)
    if arr.shape != (n,):
        raise ShapeError(f"{name} must have shape ({n},), got shape {arr.shape}")
    if not np.isfinite(arr).all():
        from ..errors import NonFiniteError

        raise NonFiniteError(f"{name} must be finite, got {arr.tolist()}")
    return arr


def _directions(x: ArrayLike | None, name: str, n: int, d: int | None) -> FloatArray:
    if x is None:
        return np.zeros((d or 0, n))
    arr = np.asarray(x, dtype=np.float64)
    if arr.ndim == 1:
        arr = arr[None, :]
    if arr.ndim != 2 or arr.shape[1] != n or (d is not None and arr.shape[0] != d):
        want = f"({d}, {n})" if d is not None else f"(d, {n})"
        raise ShapeError(f"{name} must have shape {want}, got shape {np.shape(x)}")
    return np.ascontiguousarray(arr)


def term_tangents(
    model: Model,
    q: ArrayLike,
    qd: ArrayLike,
    dq: ArrayLike,
    dqd: ArrayLike | None = None,
    *,
    t: float = 0.0,
    active: Iterable[str] | None = None,
) -> dict[str, FloatArray]:
    """The model terms at ``(t, q, qd)`` and their exact directional derivatives (forward mode).

    Parameters
    ----------
    model : Model
        A model with a differentiable engine program (planar, spatial, SymPy models, robots).
    q, qd : array_like, shape (n,)
    dq : array_like, shape (d, n) or (n,)
        Directions of q.
    dqd : array_like, shape (d, n), optional
        Directions of qd (zero by default).
    t : float
    active : iterable of str, optional
        Active constraints (default ``model.default_active``).

    Returns
    -------
    dict
        Values ``M`` (n, n), ``h``, ``f_passive`` (n,), ``B`` (n, k), ``A`` (m, n), ``gamma``,
        ``phi``, ``velocity`` (m,) of the *active* rows, and their derivatives along each
        direction: ``dM`` (d, n, n), ``dh``, ``df_passive`` (d, n), ``dB`` (d, n, k),
        ``dA`` (d, m, n), ``dgamma``, ``dphi``, ``dvelocity`` (d, m).
    """
    eng = _engine()
    n = model.n
    qv = _vector(q, "q", n)
    vv = _vector(qd, "qd", n)
    DQ = _directions(dq, "dq", n, None)
    DV = _directions(dqd, "dqd", n, DQ.shape[0]) if dqd is not None else np.zeros_like(DQ)
    act = model.resolve_active(active)
    prog = _program(model)
    raw = eng.term_tangents(prog, float(t), qv, vv, DQ, DV, model.active_mask(act), eng.NEED_ALL)
    rows = _active_rows(model, prog, act)
    out: dict[str, FloatArray] = {}
    for key, val in raw.items():
        arr = np.asarray(val)
        base = key[1:] if key.startswith("d") else key
        if base in ("A", "gamma", "phi", "velocity"):
            arr = arr[..., rows, :] if base == "A" else arr[..., rows]
        out[key] = arr
    return out


# --------------------------------------------------------------------------- the kernel
@dataclass(frozen=True)
class _KernelPoint:
    """The kernel's solution at one state, with what its derivative needs."""

    M: FloatArray
    qdd: FloatArray
    f_c: FloatArray
    rank: int
    G: FloatArray  # (DA)⁺ (n, m)
    d: FloatArray  # row scaling (m,)
    Ae: FloatArray  # D A (m, n)
    P: FloatArray
    Z: FloatArray  # (n, n − r) orthonormal basis of N(A)
    Y: FloatArray  # (n, r) orthonormal basis of R(Aᵀ)
    S_cho: FloatArray  # Cholesky factor of Zᵀ M Z
    gamma_e: FloatArray  # D γ


def _kernel_point(
    M: FloatArray, g: FloatArray, A: FloatArray, gamma: FloatArray, tol: float
) -> _KernelPoint:
    n = M.shape[0]
    m = A.shape[0]
    if m:
        basis = range_basis(A, tol)
        r = int(basis.rank)
        d = basis.d
        Ae = A * d[:, None]
        U, s, Vh = np.linalg.svd(Ae, full_matrices=True)
        Y = Vh[:r].T
        Z = Vh[r:].T
        G = (Y / s[:r]) @ U[:, :r].T
    else:
        r = 0
        d = np.zeros(0)
        Ae = np.zeros((0, n))
        Y = np.zeros((n, 0))
        Z = np.eye(n)
        G = np.zeros((n, 0))
    ge = d * gamma
    w = -G @ ge
    S = Z.T @ M @ Z
    k = Z.shape[1]
    if k:
        try:
            L = np.linalg.cholesky(S)
        except np.linalg.LinAlgError:
            raise NotPositiveDefiniteError(
                "M is not positive definite on N(A) at this state: Zᵀ M Z has no Cholesky factor"
            ) from None
        if np.min(np.diag(L)) ** 2 <= SPD_RTOL * max(float(np.max(np.diag(S))), 1e-300):
            raise NotPositiveDefiniteError(
                "M is not positive definite on N(A) at this state (Zᵀ M Z)"
            )
        y = np.linalg.solve(L.T, np.linalg.solve(L, Z.T @ (g - M @ w)))
        qdd = w + Z @ y
    else:
        L = np.zeros((0, 0))
        qdd = w
    P = Z @ Z.T
    return _KernelPoint(
        M=M, qdd=qdd, f_c=M @ qdd - g, rank=r, G=G, d=d, Ae=Ae, P=P, Z=Z, Y=Y, S_cho=L, gamma_e=ge
    )


def _kernel_tangent(
    kp: _KernelPoint, dM: FloatArray, dg: FloatArray, dA: FloatArray, dgamma: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """δq̈ and δf_c (shape (d, n)) for d directions of the terms at fixed rank (module docstring)."""
    G, P, Ae, Z, M, qdd, fc = kp.G, kp.P, kp.Ae, kp.Z, kp.M, kp.qdd, kp.f_c
    n = M.shape[0]
    Q = np.eye(n) - P
    if Ae.shape[0]:
        dAe = dA * kp.d[None, :, None]  # (d, m, n)
        GdAe = G @ dAe  # (d, n, n)
        GdAeP = GdAe @ P
        dP = -GdAeP - np.swapaxes(GdAeP, 1, 2)
        # δG ge = −G δAe G ge + G Gᵀ δAeᵀ (I − Ae G) ge + P δAeᵀ Gᵀ G ge
        Gge = G @ kp.gamma_e
        res = kp.gamma_e - Ae @ Gge  # (I − Ae G) ge: the least-squares residual (0 if consistent)
        dAeT = np.swapaxes(dAe, 1, 2)  # (d, n, m)
        dG_ge = (
            -(GdAe @ Gge)
            + (G @ (G.T @ (dAeT @ res)[..., None]))[..., 0]
            + ((P @ dAeT) @ (G.T @ Gge))
        )
        dw = -dG_ge - (dgamma * kp.d[None, :]) @ G.T
        a = dw + dP @ qdd
        dPfc = dP @ fc
    else:
        a = np.zeros_like(dg)
        dPfc = np.zeros_like(dg)
    aq = a @ Q.T
    if Z.shape[1]:
        rhs = (dg - dM @ qdd - aq @ M.T - dPfc) @ Z  # (d, k)
        L = kp.S_cho
        y = np.linalg.solve(L.T, np.linalg.solve(L, rhs.T)).T
        dqdd = aq + y @ Z.T
    else:
        dqdd = aq
    dfc = dM @ qdd + dqdd @ M.T - dg
    return dqdd, dfc


# --------------------------------------------------------------------------- public API
@dataclass(frozen=True)
class DynamicsDerivatives:
    """Accelerations and constraint forces at one state and their exact first derivatives.

    Attributes
    ----------
    qdd, f_c : ndarray, shape (n,)
        ``q̈`` (corrected eq. (ddq_sim)) and ``f_c`` (eq. (fc_R)) at the state.
    rank : int
        Rank of the active A used (the derivatives are those of the rank-``rank`` branch).
    dqdd_dq, dqdd_dqd : ndarray, shape (n, n)
        ``∂q̈/∂q`` and ``∂q̈/∂q̇`` (u held fixed, so ``∂B/∂q u`` is included).
    dqdd_df : ndarray, shape (n, n)
        ``∂q̈/∂f`` for a generalized force f added to the model's (``M̄⁻¹P``-like, μ-free).
    dqdd_du : ndarray, shape (n, k)
        ``∂q̈/∂u = ∂q̈/∂f · B``.
    dfc_dq, dfc_dqd, dfc_df : ndarray, shape (n, n)
    dfc_du : ndarray, shape (n, k)
    """

    qdd: FloatArray
    f_c: FloatArray
    rank: int
    dqdd_dq: FloatArray
    dqdd_dqd: FloatArray
    dqdd_df: FloatArray
    dqdd_du: FloatArray
    dfc_dq: FloatArray
    dfc_dqd: FloatArray
    dfc_df: FloatArray
    dfc_du: FloatArray


def _directional(
    model: Model,
    t: float,
    q: FloatArray,
    qd: FloatArray,
    u: FloatArray,
    f: FloatArray,
    act: frozenset[str],
    tol: float,
    DQ: FloatArray,
    DV: FloatArray,
) -> tuple[_KernelPoint, dict[str, FloatArray], FloatArray, FloatArray]:
    """Kernel point and (δq̈, δf_c) along the state directions (DQ, DV), u and f fixed."""
    tt = term_tangents(model, q, qd, DQ, DV, t=t, active=act)
    B = tt["B"]
    g = tt["h"] + tt["f_passive"] + f + B @ u
    kp = _kernel_point(tt["M"], g, tt["A"], tt["gamma"], tol)
    dg = tt["dh"] + tt["df_passive"] + tt["dB"] @ u
    dqdd, dfc = _kernel_tangent(kp, tt["dM"], dg, tt["dA"], tt["dgamma"])
    return kp, tt, dqdd, dfc


def dynamics_derivatives(
    model: Model,
    q: ArrayLike,
    qd: ArrayLike | None = None,
    *,
    u: ArrayLike | None = None,
    f: ArrayLike | None = None,
    t: float = 0.0,
    active: Iterable[str] | None = None,
    rtol: float | None = None,
    backend: str = "engine",
    out: DynamicsDerivatives | None = None,
) -> DynamicsDerivatives:
    """``q̈``, ``f_c`` and their derivatives ∂/∂q, ∂/∂q̇, ∂/∂f, ∂/∂u at one state.

    Model terms are differentiated in forward mode in the engine (dual numbers); the kernel's
    solve analytically at the rank it used (module docstring). No finite differences.

    Parameters
    ----------
    model : Model
        Planar, spatial or SymPy model, or robot (a model whose engine program evaluates on
        dual numbers).
    q : array_like, shape (n,)
    qd : array_like, shape (n,), optional
        Velocities (zero by default).
    u : array_like, shape (k,), optional
        Actuator inputs (``f = B(q) u``; zero by default).
    f : array_like, shape (n,), optional
        Extra applied generalized forces (zero by default).
    t : float
    active : iterable of str, optional
    rtol : float, optional
        Rank tolerance of the kernel (default :data:`nonmin.core.DEFAULT_RTOL`).
    backend : {"engine", "numpy"}
        ``"engine"``: the whole pipeline in C++ (``engine/src/derivatives.cpp``);
        ``"numpy"``: the terms' tangents from the engine, the kernel derivative in NumPy (the
        readable specification; same results to round-off).
    out : DynamicsDerivatives, optional
        A result of an earlier ``backend="engine"`` call on a model of the same sizes (n, k):
        its arrays are overwritten in place and it is returned (no allocation, no new arrays:
        for calls in a loop; its earlier values are lost).

    Returns
    -------
    DynamicsDerivatives

    Raises
    ------
    ModelError
        The model has no differentiable engine program.
    ShapeError, NonFiniteError
        Bad q, qd, u or f.
    InputError
        ``out`` is not a result of the engine backend with these sizes.
    NotPositiveDefiniteError
        M is not positive definite on N(A).
    """
    if backend == "engine":
        # the boundary check is cheap here: the model's sizes, program, scratch and masks are
        # prepared once per model (per thread), shapes and types checked in Python, finiteness
        # in the binding (one C++ pass, NonFiniteError naming the argument)
        return _engine_derivatives(model, q, qd, u, f, t, active, rtol, out)
    if not isinstance(model, Model):
        raise InputError(f"model must be a nonmin Model, got {type(model).__name__}")
    n, k = model.n, model.k
    qv = _vector(q, "q", n)
    vv = _vector(qd, "qd", n)
    uv = _vector(u, "u", k)
    fv = _vector(f, "f", n)
    tol = DEFAULT_RTOL if rtol is None else resolve_rtol(rtol)
    act = model.resolve_active(active)
    if backend != "numpy":
        raise InputError(f"backend must be 'engine' or 'numpy', got {backend!r}")
    DQ = np.vstack([np.eye(n), np.zeros((n, n))])
    DV = np.vstack([np.zeros((n, n)), np.eye(n)])
    kp, tt, dqdd, dfc = _directional(model, float(t), qv, vv, uv, fv, act, tol, DQ, DV)
    dqdd_f, dfc_f = _kernel_tangent(
        kp,
        np.zeros((n, n, n)),
        np.eye(n),
        np.zeros((n, *tt["A"].shape)),
        np.zeros((n, tt["A"].shape[0])),
    )
    B = tt["B"]
    return DynamicsDerivatives(
        qdd=kp.qdd,
        f_c=kp.f_c,
        rank=kp.rank,
        dqdd_dq=dqdd[:n].T.copy(),
        dqdd_dqd=dqdd[n:].T.copy(),
        dqdd_df=dqdd_f.T.copy(),
        dqdd_du=dqdd_f.T @ B,
        dfc_dq=dfc[:n].T.copy(),
        dfc_dqd=dfc[n:].T.copy(),
        dfc_df=dfc_f.T.copy(),
        dfc_du=dfc_f.T @ B,
    )


#: Per-thread cache of the C++ pipeline, per model (a few models at a time): the program and its
#: scratch are made once per model.
_LOCAL = threading.local()
_F64 = np.dtype(np.float64)


class _Prepared:
    """One model's engine pipeline: program, scratch, sizes, the default active set's mask."""

    __slots__ = ("default", "default_mask", "k", "masks", "model", "n", "prog", "scratch", "shape", "zeros")

    def __init__(self, model: Model) -> None:
        self.model = model
        self.prog = _program(model)
        self.scratch = _engine().DerivativeScratch(self.prog)
        self.n, self.k = int(model.n), int(model.k)
        self.shape = (2 + 6 * self.n + 2 * self.k, self.n)  # the output block (the binding's doc)
        self.zeros = np.zeros(self.n)
        self.zeros.flags.writeable = False
        self.masks: dict[frozenset[str], NDArray[np.uint8]] = {}
        self.default = model.default_active
        self.default_mask = self.mask(model.resolve_active(None))

    def mask(self, act: frozenset[str]) -> NDArray[np.uint8]:
        got = self.masks.get(act)
        if got is None:
            got = self.masks[act] = self.model.active_mask(act)
        return got


def _prepared(model: Model) -> _Prepared:
    cache: dict[int, _Prepared] | None = getattr(_LOCAL, "prepared", None)
    if cache is None:
        cache = _LOCAL.prepared = {}
    got = cache.get(id(model))
    if got is None or got.model is not model:
        if not isinstance(model, Model):
            raise InputError(f"model must be a nonmin Model, got {type(model).__name__}")
        if len(cache) >= 16:
            cache.clear()
        got = cache[id(model)] = _Prepared(model)
    return got


def _engine_derivatives(
    model: Model,
    q: ArrayLike,
    qd: ArrayLike | None,
    u: ArrayLike | None,
    f: ArrayLike | None,
    t: float,
    active: Iterable[str] | None,
    rtol: float | None,
    out: DynamicsDerivatives | None,
) -> DynamicsDerivatives:
    """The C++ pipeline (engine/src/derivatives.cpp) into one output block (or ``out``'s)."""
    prep = _prepared(model)
    n, k = prep.n, prep.k
    if active is None and model.default_active is prep.default:
        mask = prep.default_mask
    else:
        mask = prep.mask(model.resolve_active(active))
    tol = DEFAULT_RTOL if rtol is None else resolve_rtol(rtol)
    qv = _array(q, "q", n)
    qdv = prep.zeros if qd is None else _array(qd, "qd", n)
    uv = None if u is None or k == 0 else _array(u, "u", k)
    fv = None if f is None else _array(f, "f", n)
    blk: FloatArray | None
    if out is None:
        blk = np.empty(prep.shape)  # every output, one allocation
    else:
        blk = out.__dict__.get("_block") if type(out) is DynamicsDerivatives else None
        if blk is None or blk.shape != prep.shape:
            raise InputError(
                "out must be a DynamicsDerivatives returned by an earlier engine call on a model "
                f"with n = {n}, k = {k}, got {type(out).__name__}"
                + ("" if blk is None else f" of a model with block shape {blk.shape}")
            )
    try:
        rank = _engine().forward_derivatives(
            prep.prog, prep.scratch, float(t), qv, qdv, fv, uv, mask, tol, blk
        )
    except NotPositiveDefiniteError as exc:
        raise NotPositiveDefiniteError(
            f"M is not positive definite on N(A) at this state ({exc})"
        ) from None
    if out is not None:
        out.__dict__["rank"] = rank
        return out
    e = 2 + 6 * n
    res = object.__new__(DynamicsDerivatives)  # frozen: fill its fields without __setattr__
    res.__dict__.update(
        qdd=blk[0], f_c=blk[1], rank=rank,
        dqdd_dq=blk[2 : 2 + n], dqdd_dqd=blk[2 + n : 2 + 2 * n], dqdd_df=blk[2 + 2 * n : 2 + 3 * n],
        dqdd_du=blk[e : e + k].T,
        dfc_dq=blk[2 + 3 * n : 2 + 4 * n], dfc_dqd=blk[2 + 4 * n : 2 + 5 * n], dfc_df=blk[2 + 5 * n : e],
        dfc_du=blk[e + k : e + 2 * k].T,
        _block=blk,
    )  # fmt: skip
    return res


def _array(x: ArrayLike | None, name: str, n: int) -> FloatArray:
    """x as a float64 C-contiguous (n,) array; finiteness is checked by the engine's binding."""
    if type(x) is np.ndarray and x.dtype is _F64 and x.shape == (n,) and x.flags.c_contiguous:
        return x
    arr = np.ascontiguousarray(x, dtype=np.float64)
    if arr.shape != (n,):
        raise ShapeError(f"{name} must have shape ({n},), got shape {arr.shape}")
    return arr
