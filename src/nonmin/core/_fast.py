"""Backend selection and the compiled fast path of the dynamics kernels.

:func:`nonmin.core.forward_dynamics`, :func:`~nonmin.core.constraint_force` and
:func:`~nonmin.core.solve_dynamics` evaluate with the ahead-of-time compiled C++ engine
(``nonmin._engine``, the core layer ``engine/src/core_*.cpp``) or with the reference NumPy
kernels. Both give the same results to round-off (tests demand 1e-12 relative); a single call
and the same state inside a batch give bitwise identical results on the engine.

Choosing the backend
--------------------
``"auto"`` (default) and ``"engine"`` use the C++ engine (built with the package), ``"numpy"``
always uses NumPy. (The numba kernels of nonmin ≤ 0.1 are gone: see ``benchmarks/numba_baseline``.)
The initial choice comes from the environment variable ``NONMIN_BACKEND``
(read at import); :func:`set_backend` changes it for the process, :func:`use_backend` for a
``with`` block (the setting is process-wide, not per thread).

The compiled paths keep the boundary contract: they accept the same inputs, check finiteness and
the symmetry of M inside the kernel with the same decision rule, and whenever a state is not
regular (invalid input, M̄ not positive definite, shapes they do not handle) the NumPy path is
re-run, which raises the typed error (or, in a round-off borderline case of the SPD test,
returns the NumPy result). The engine needs no compilation at run time.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np

from .. import _engine  # type: ignore[attr-defined]  # the compiled extension (no stubs)
from .. import _validation as V
from ..errors import InputError
from .linalg import DEFAULT_RTOL, SPD_RTOL, FloatArray, resolve_rtol

__all__ = ["BACKENDS", "get_backend", "set_backend", "use_backend"]

#: Accepted backend names.
BACKENDS = ("auto", "numpy", "engine")

#: Batches at least this large run on several threads of the engine (one per core; smaller
#: batches on the calling thread). See :func:`engine_threads`.
ENGINE_PARALLEL_MIN_BATCH = 2048

_state: dict[str, Any] = {"name": "auto"}
_UNRESOLVED = object()
#: The engine marker when the engine is in use, None for NumPy (resolved lazily).
_active: Any = _UNRESOLVED


def _check_name(name: object) -> str:
    if not isinstance(name, str) or name.lower() not in BACKENDS:
        raise InputError(f"backend must be one of {BACKENDS}, got {name!r}")
    return name.lower()


def set_backend(name: str) -> str:
    """Select the backend of the dynamics kernels; returns the previous setting.

    Parameters
    ----------
    name : {"auto", "numpy", "engine"}
        ``"auto"`` and ``"engine"``: the compiled C++ engine; ``"numpy"``: the NumPy reference
        kernels.

    Raises
    ------
    InputError
        Unknown name.
    """
    new = _check_name(name)
    old: str = _state["name"]
    _set(new)
    return old


#: ``ENGINE_FAST[0]``: the engine's fast entry (``nonmin._engine.core_fast``) while the backend
#: is the engine, else None; the public kernels call it first (a regular single state of
#: float64 C-contiguous arrays), and take the general path when it returns None.
ENGINE_FAST: list[Any] = [None]


def _set(name: str) -> None:
    global _active
    _state["name"] = name
    _active = _UNRESOLVED
    ENGINE_FAST[0] = _engine.core_fast if name in ("auto", "engine") else None


def backend_setting() -> str:
    """The backend as set (``"auto"``, ``"numpy"`` or ``"engine"``)."""
    return str(_state["name"])


def get_backend() -> str:
    """The backend actually used now: ``"engine"`` or ``"numpy"``."""
    return "numpy" if _state["name"] == "numpy" else "engine"


@contextmanager
def use_backend(name: str) -> Iterator[None]:
    """Context manager: evaluate with backend ``name`` inside the block, then restore.

    Parameters
    ----------
    name : {"auto", "numpy", "engine"}
        Backend used inside the ``with`` block (see :func:`set_backend`).
    """
    old = set_backend(name)
    try:
        yield
    finally:
        _set(old)


def _init_from_env() -> None:
    env = os.environ.get("NONMIN_BACKEND", "auto").strip().lower() or "auto"
    if env not in BACKENDS:
        raise InputError(
            f"environment variable NONMIN_BACKEND must be one of {BACKENDS}, got {env!r}"
        )
    _set(env)


_init_from_env()


_ND = np.ndarray
_F64 = np.dtype(np.float64)


def _prep(x: Any, name: str) -> FloatArray:
    if type(x) is _ND and x.dtype is _F64 and x.flags.c_contiguous:
        return x
    return np.ascontiguousarray(V.as_float_array(x, name))


#: Marker of the engine backend in ``_active``.
_ENGINE = object()


def _resolve() -> Any:
    global _active
    name = _state["name"]
    if name in ("auto", "engine"):
        _active = _ENGINE
        return _active
    _active = None
    return _active


#: ``what`` codes of :func:`solve` (``QDD_RANK``: ``(qdd, rank)``, single states only).
QDD, FC, ALL, QDD_RANK = 0, 1, 2, 3


def solve(M: Any, h: Any, A: Any, adot_qd: Any, f: Any, mu: Any, rtol: float | None,
          what: int) -> Any:  # fmt: skip
    """Compiled evaluation, or None when the caller must take the NumPy path.

    Returns ``qdd`` (``what=QDD``), ``f_c`` (``FC``), ``(qdd, f_c, P, L, rank, mu)`` (``ALL``),
    all with the broadcast batch shape, or ``(qdd, rank)`` (``QDD_RANK``, a single state;
    None for a batch). None is returned when the backend is NumPy or when the
    inputs are not regular (shapes, non-finite entries, asymmetric M, M̄ not positive definite):
    the NumPy path then raises the typed error.
    """
    kern = _active
    if kern is _UNRESOLVED:
        kern = _resolve()
    if kern is None:
        return None
    return engine_solve(M, h, A, adot_qd, f, mu, rtol, what)


# --------------------------------------------------------------------------- the C++ engine

_FAST = _engine.core_fast
_SOLVE_ONE = _engine.core_solve_one
_SOLVE_BATCH = _engine.core_solve_batch
_SYM = V.SYMMETRY_RTOL


def engine_threads(N: int) -> int:
    """Threads of the engine for a batch of N states (one per usable core from
    :data:`ENGINE_PARALLEL_MIN_BATCH` states on; ``NONMIN_THREADS`` caps it)."""
    if N < ENGINE_PARALLEL_MIN_BATCH:
        return 1
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:  # (not Linux)
        cores = os.cpu_count() or 1
    cap = os.environ.get("NONMIN_THREADS")
    if cap and cap.isdigit() and int(cap) > 0:
        cores = min(cores, int(cap))
    return max(1, cores)


def engine_solve(M: Any, h: Any, A: Any, adot_qd: Any, f: Any, mu: Any, rtol: float | None,
                 what: int) -> Any:  # fmt: skip
    """:func:`solve` on the C++ engine (``nonmin._engine.core_solve_one`` / ``core_solve_batch``).

    Same returns as :func:`solve`; None when the NumPy path must run (invalid input, M̄ not
    positive definite, n = 0): it raises the typed error.
    """
    if what != ALL:  # the fast entry (a regular single state, arguments as given)
        res = _FAST(M, h, A, adot_qd, f, mu, rtol, what)
        if res is not None:
            return res
    tol = DEFAULT_RTOL if rtol is None else resolve_rtol(rtol)
    mu_v: Any = None
    mu_s = 0.0
    if mu is not None:
        mu_v = V.positive_scalar_or_batch(mu, "mu")
        if mu_v.ndim == 0:
            mu_s = float(mu_v)
    if mu_v is None or mu_v.ndim == 0:
        try:
            res = _SOLVE_ONE(M, h, A, adot_qd, f, mu_s, tol, SPD_RTOL, _SYM, what)
        except TypeError:  # lists, objects: coerce once and retry
            res = _SOLVE_ONE(*_coerce(M, h, A, adot_qd, f), mu_s, tol, SPD_RTOL, _SYM, what)
        if res is not None:
            if type(res) is int:
                return None  # not regular: the NumPy path raises
            if what == ALL:
                q, fc, P, L, rank, mu_used = res
                return (q, fc, P, L, np.asarray(rank, dtype=np.intp),
                        mu_v if mu_v is not None else np.asarray(mu_used))  # fmt: skip
            return res
    if what == QDD_RANK:
        return None  # (single states only)
    Mm, hv, Am, gv, fv = _coerce(M, h, A, adot_qd, f)
    return _engine_batch(Mm, hv, Am, gv, fv, mu_v, tol, what)


def _coerce(M: Any, h: Any, A: Any, g: Any, f: Any) -> tuple[Any, Any, Any, Any, Any]:
    return (_prep(M, "M"), _prep(h, "h"), _prep(A, "A"), _prep(g, "adot_qd"),
            None if f is None else _prep(f, "f"))  # fmt: skip


def _engine_batch(Mm: FloatArray, hv: FloatArray, Am: FloatArray, gv: FloatArray,
                  fv: FloatArray | None, mu_v: FloatArray | None, tol: float, what: int) -> Any:  # fmt: skip
    if Mm.ndim < 2 or Am.ndim < 2 or hv.ndim < 1 or gv.ndim < 1 or (fv is not None and fv.ndim < 1):
        return None
    n = Mm.shape[-1]
    m = Am.shape[-2]
    if (n == 0 or Mm.shape[-2] != n or hv.shape[-1] != n or Am.shape[-1] != n
            or gv.shape[-1] != m or (fv is not None and fv.shape[-1] != n)):  # fmt: skip
        return None
    parts: list[tuple[FloatArray, tuple[int, ...]]] = [
        (Mm, (n, n)), (hv, (n,)), (Am, (m, n)), (gv, (m,))]  # fmt: skip
    if fv is not None:
        parts.append((fv, (n,)))
    if mu_v is not None:
        parts.append((mu_v, ()))
    st = strided(parts)
    if st is None:
        return None
    bshape, N, bufs = st
    (Mb, sM), (hb, sh), (Ab, sA), (gb, sg) = bufs[:4]
    fb, sf = bufs[4] if fv is not None else (None, 0)
    mub, smu = bufs[-1] if mu_v is not None else (None, 0)
    want_pl = what == ALL
    qdd = np.empty((N, n))
    fc = np.empty((0 if what == QDD else N, n))
    P = np.empty((N, n, n) if want_pl else (0,))
    L = np.empty((N, n, n) if want_pl else (0,))
    status = np.empty(N, dtype=np.int64)
    rank = np.empty(N, dtype=np.int64)
    mu_out = np.empty(N)
    ratio = np.empty(N)
    _SOLVE_BATCH(Mb, hb, fb, Ab, gb, mub, sM, sh, sf, sA, sg, smu, N, n, m, tol, SPD_RTOL, _SYM,
                 qdd, fc, P, L, status, rank, mu_out, ratio, engine_threads(N))  # fmt: skip
    if status.any():
        return None
    return _batch_result(what, bshape, n, qdd, fc, P, L, rank, mu_v, mu_out)


def _batch_result(what: int, bshape: tuple[int, ...], n: int, qdd: FloatArray, fc: FloatArray,
                  P: FloatArray, L: FloatArray, rank: Any, mu_v: Any, mu_out: FloatArray) -> Any:  # fmt: skip
    """A batched kernel's flat outputs in the batch shape, as :func:`solve` returns them."""
    if what == QDD:
        return qdd.reshape((*bshape, n))
    if what == FC:
        return fc.reshape((*bshape, n))
    return (
        qdd.reshape((*bshape, n)),
        fc.reshape((*bshape, n)),
        P.reshape((*bshape, n, n)),
        L.reshape((*bshape, n, n)),
        rank.astype(np.intp, copy=False).reshape(bshape),
        np.asarray(mu_v) if mu_v is not None else mu_out.reshape(bshape),
    )


def engine_on() -> bool:
    """Whether the backend in use is the C++ engine."""
    return ENGINE_FAST[0] is not None


def strided(parts: list[tuple[Any, tuple[int, ...]]]
            ) -> tuple[tuple[int, ...], int, list[tuple[FloatArray, int]]] | None:  # fmt: skip
    """Batch layout for the engine's batched kernels.

    ``parts``: (array, core shape) pairs whose leading dimensions broadcast together. Returns
    the broadcast batch shape, its size N and, per array, a float64 C-contiguous buffer with its
    batch stride in entries (0 when one array serves every state: no copy); None if the batch
    shapes do not broadcast.
    """
    shapes = [np.shape(x)[: np.ndim(x) - len(core)] for x, core in parts]
    try:
        bshape = tuple(np.broadcast_shapes(*shapes))
    except ValueError:
        return None
    N = 1
    for d in bshape:
        N *= d
    out = []
    for (x, core), lead in zip(parts, shapes):
        size = 1
        for c in core:
            size *= c
        if lead == bshape:
            out.append((np.ascontiguousarray(x, dtype=np.float64), size))
        elif all(d == 1 for d in lead):
            out.append((np.ascontiguousarray(x, dtype=np.float64), 0))
        else:
            out.append((np.ascontiguousarray(np.broadcast_to(x, bshape + core), dtype=np.float64),
                        size))  # fmt: skip
    return bshape, N, out


def engine_solver_kernel(kind: int, Mm: FloatArray, Am: FloatArray, x: FloatArray,
                         mu_v: FloatArray | None, e: float, tol: float) -> FloatArray | None:  # fmt: skip
    """The impact map (``kind`` 0, ``x`` = q̇⁻, ``e`` the restitution) or the mass-metric
    position correction (1, ``x`` = φ) on the engine (validated inputs); None when a state is
    not regular (M̄ not positive definite): the NumPy path raises the typed error."""
    n = Mm.shape[-1]
    m = Am.shape[-2]
    parts: list[tuple[Any, tuple[int, ...]]] = [(Mm, (n, n)), (Am, (m, n)), (x, (m,) if kind else (n,))]
    if mu_v is not None:
        parts.append((mu_v, ()))
    st = strided(parts)
    if st is None:
        return None
    bshape, N, bufs = st
    (Mb, sM), (Ab, sA), (xb, sx) = bufs[:3]
    mub, smu = bufs[3] if mu_v is not None else (None, 0)
    out = np.empty((N, n))
    status = np.empty(N, dtype=np.int64)
    rank = np.empty(N, dtype=np.int64)
    _engine.core_solver_kernel(kind, Mb, Ab, xb, mub, sM, sA, sx, smu, N, n, m, e, tol, out,
                               status, rank, engine_threads(N))  # fmt: skip
    if status.any():
        return None
    return out.reshape((*bshape, n))
