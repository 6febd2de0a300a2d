"""Backend selection and the compiled fast path of the dynamics kernels.

:func:`nonmin.core.forward_dynamics`, :func:`~nonmin.core.constraint_force` and
:func:`~nonmin.core.solve_dynamics` evaluate with the ahead-of-time compiled C++ engine
(``nonmin._engine``, the core layer ``engine/src/core_*.cpp``), with the reference NumPy kernels,
or with the older numba-compiled kernels (:mod:`nonmin.core._fast_kernels`, optional extra
``fast``; kept while the numba simulation loop uses them). All give the same results to round-off
(tests demand 1e-12 relative); a single call and the same state inside a batch give bitwise
identical results on each compiled backend.

Choosing the backend
--------------------
``"auto"`` (default) and ``"engine"`` use the C++ engine (built with the package), ``"numpy"``
always uses NumPy, ``"numba"`` demands numba (``MissingDependencyError`` naming the extra
``fast`` otherwise). The initial choice comes from the environment variable ``NONMIN_BACKEND``
(read at import); :func:`set_backend` changes it for the process, :func:`use_backend` for a
``with`` block (the setting is process-wide, not per thread).

The compiled paths keep the boundary contract: they accept the same inputs, check finiteness and
the symmetry of M inside the kernel with the same decision rule, and whenever a state is not
regular (invalid input, M̄ not positive definite, shapes they do not handle) the NumPy path is
re-run, which raises the typed error (or, in a round-off borderline case of the SPD test,
returns the NumPy result). The engine needs no compilation at run time; numba's first call
compiles its kernels (cached on disk afterwards).
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager
from types import ModuleType
from typing import Any

import numpy as np

from .. import _engine  # type: ignore[attr-defined]  # the compiled extension (no stubs)
from .. import _validation as V
from ..errors import InputError, missing_dependency
from .linalg import DEFAULT_RTOL, SPD_RTOL, FloatArray, resolve_rtol

__all__ = ["BACKENDS", "get_backend", "set_backend", "use_backend"]

#: Accepted backend names.
BACKENDS = ("auto", "numpy", "numba", "engine")

#: Batches at least this large run on several threads of the engine (one per core; smaller
#: batches on the calling thread). See :func:`engine_threads`.
ENGINE_PARALLEL_MIN_BATCH = 2048

#: Batches at least this large run on numba's parallel driver (smaller ones serially): below, the
#: fork/join cost is not amortized, and on a loaded machine the parallel region waits for a thread
#: that is not scheduled (measured: 8 µs/state at N = 1000 against 1.5 µs serially under load).
#: ``numba.set_num_threads(1)`` (or ``NUMBA_NUM_THREADS=1``) makes every batch serial.
PARALLEL_MIN_BATCH = 4096

_state: dict[str, Any] = {"name": "auto", "kernels": None, "tried": False}
_UNRESOLVED = object()
#: The kernels module when the compiled backend is in use, None for NumPy (resolved lazily).
_active: Any = _UNRESOLVED


def _check_name(name: object) -> str:
    if not isinstance(name, str) or name.lower() not in BACKENDS:
        raise InputError(f"backend must be one of {BACKENDS}, got {name!r}")
    return name.lower()


def _load() -> ModuleType | None:
    """Import the compiled kernels once; None if numba is not importable."""
    if not _state["tried"]:
        _state["tried"] = True
        try:
            from . import _fast_kernels
        except ImportError:
            _fast_kernels = None  # type: ignore[assignment]
        _state["kernels"] = _fast_kernels
    kernels: ModuleType | None = _state["kernels"]
    return kernels


def set_backend(name: str) -> str:
    """Select the backend of the dynamics kernels; returns the previous setting.

    Parameters
    ----------
    name : {"auto", "numpy", "numba", "engine"}
        ``"auto"`` and ``"engine"``: the compiled C++ engine; ``"numba"``: the numba kernels
        (extra ``fast``); ``"numpy"``: the NumPy reference kernels.

    Raises
    ------
    InputError
        Unknown name.
    MissingDependencyError
        ``"numba"`` requested but numba is not installed (extra ``fast``).
    """
    new = _check_name(name)
    if new == "numba" and _load() is None:
        raise missing_dependency("numba", "fast", "the compiled backend of nonmin.core")
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
    """The backend as set (``"auto"``, ``"numpy"``, ``"numba"`` or ``"engine"``)."""
    return str(_state["name"])


def get_backend() -> str:
    """The backend actually used now: ``"engine"``, ``"numpy"`` or ``"numba"``."""
    name = str(_state["name"])
    if name in ("auto", "engine"):
        return "engine"
    if name == "numpy":
        return "numpy"
    return "numba" if _load() is not None else "numpy"


@contextmanager
def use_backend(name: str) -> Iterator[None]:
    """Context manager: evaluate with backend ``name`` inside the block, then restore.

    Parameters
    ----------
    name : {"auto", "numpy", "numba", "engine"}
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
    _active = None if name == "numpy" else _load()
    if _active is None and _state["name"] == "numba":  # NONMIN_BACKEND=numba without numba
        raise missing_dependency("numba", "fast", "NONMIN_BACKEND=numba (compiled nonmin.core)")
    return _active


_NO_MU = np.ones(1)
_PARAMS: dict[tuple[bool, float, bool], FloatArray] = {}


def _params(has_f: bool, tol: float, want_pl: bool) -> FloatArray:
    """Cached ``[has_f, mu, has_mu, rtol, spd_rtol, sym_rtol, want_pl]`` (mu not given)."""
    key = (has_f, tol, want_pl)
    p = _PARAMS.get(key)
    if p is None:
        p = np.array([float(has_f), 1.0, 0.0, tol, SPD_RTOL, V.SYMMETRY_RTOL, float(want_pl)])
        if len(_PARAMS) < 64:
            _PARAMS[key] = p
    return p


#: Parameter vectors for the default rtol and no μ, indexed ``[has_f][want_pl]``.
_DEFAULT_PARAMS = tuple(
    tuple(_params(bool(hf), DEFAULT_RTOL, bool(pl)) for pl in (0, 1)) for hf in (0, 1)
)

#: In ``"auto"`` mode the compiled path is used up to this n, and above it when the constraints
#: leave at most this many degrees of freedom (``n − m``, see :func:`auto_compiled`); otherwise
#: the NumPy path (LAPACK) is used. Measured (one BLAS thread, ``benchmarks/core_bench.py
#: --large``, medians, 00:11 UTC): an A02 N = 40 evaluation (n = 243, A 242 × 243, one degree of
#: freedom) takes 0.52 ms compiled (certified sparse LQ, null-space form) against 15.3 ms with
#: NumPy's SVD, and 11–12.5 ms against 17–19 ms where the compiled path also needs LAPACK's SVD
#: (near a singular configuration); with many degrees of freedom the compiled path forms and
#: factorizes the n × n M̄ in scalar loops (random sparse n = 243, m = 121: 11.3 against
#: 10.9 ms). ``set_backend("numba")`` forces the compiled path at any size.
AUTO_NUMBA_MAX_N = 64


def auto_compiled(n: int, m: int) -> bool:
    """Whether ``"auto"`` takes the compiled path for n coordinates and m constraint rows."""
    return n <= AUTO_NUMBA_MAX_N or n - m <= AUTO_NUMBA_MAX_N

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
    if kern is _ENGINE:
        return engine_solve(M, h, A, adot_qd, f, mu, rtol, what)
    # Coerce once (no copy for float64 C-contiguous arrays); finiteness and symmetry are checked
    # inside the kernel.
    Mm = M if type(M) is _ND and M.dtype is _F64 and M.flags.c_contiguous else _prep(M, "M")
    hv = h if type(h) is _ND and h.dtype is _F64 and h.flags.c_contiguous else _prep(h, "h")
    Am = A if type(A) is _ND and A.dtype is _F64 and A.flags.c_contiguous else _prep(A, "A")
    if (Mm.ndim and Am.ndim >= 2 and _state["name"] == "auto"
            and not auto_compiled(Mm.shape[-1], Am.shape[-2])):
        return None  # many coordinates and degrees of freedom: LAPACK is faster (measured)
    gv = (
        adot_qd
        if type(adot_qd) is _ND and adot_qd.dtype is _F64 and adot_qd.flags.c_contiguous
        else _prep(adot_qd, "adot_qd")
    )
    has_f = f is not None
    if has_f:
        fv = f if type(f) is _ND and f.dtype is _F64 and f.flags.c_contiguous else _prep(f, "f")
    else:
        fv = hv
    has_mu = mu is not None
    if Mm.ndim == 2 and hv.ndim == 1 and Am.ndim == 2 and gv.ndim == 1 and fv.ndim == 1:
        # ------------------------------------------------------------ single state
        n, n2 = Mm.shape
        m, nA = Am.shape
        if n2 != n or hv.shape[0] != n or nA != n or gv.shape[0] != m or n == 0:
            return None
        if has_f and fv.shape[0] != n:
            return None
        want_pl = what == ALL
        if rtol is None and not has_mu:
            params = _DEFAULT_PARAMS[has_f][want_pl]
        elif has_mu:
            tol = DEFAULT_RTOL if rtol is None else resolve_rtol(rtol)
            mu_v = V.positive_scalar_or_batch(mu, "mu")
            if mu_v.ndim:
                return None
            params = np.array([float(has_f), float(mu_v), 1.0, tol, SPD_RTOL, V.SYMMETRY_RTOL,
                               float(want_pl)])  # fmt: skip
        else:
            params = _params(has_f, resolve_rtol(rtol), want_pl)
        if not want_pl:
            out = np.empty(2 * n + 3)
            if kern.solve_one(Mm, hv, fv, Am, gv, params, out):
                return None
            if what == QDD_RANK:
                return out[:n], int(out[2 * n])
            return out[:n] if what == QDD else out[n : 2 * n]
        out = np.empty(2 * n + 3 + 2 * n * n)  # P and L follow the scalars
        if kern.solve_one(Mm, hv, fv, Am, gv, params, out):
            return None
        o = 2 * n + 3
        P = out[o : o + n * n].reshape(n, n)
        L = out[o + n * n :].reshape(n, n)
        rank = np.asarray(int(out[2 * n]), dtype=np.intp)
        mu_used = mu_v if has_mu else np.asarray(out[2 * n + 1])
        return out[:n], out[n : 2 * n], P, L, rank, mu_used
    if what == QDD_RANK:
        return None  # (single states only)
    if (
        Mm.ndim == 3 and hv.ndim == 2 and Am.ndim == 3 and gv.ndim == 2 and fv.ndim == 2
        and Mm.shape[0] == hv.shape[0] == Am.shape[0] == gv.shape[0] == fv.shape[0] == 1
        and (not has_mu or np.ndim(mu) == 0)
    ):  # a batch of one state: the (cheaper) single-state path  # fmt: skip
        one = solve(Mm[0], hv[0], Am[0], gv[0], fv[0] if has_f else None, mu, rtol, what)
        if one is None or what != ALL:
            return None if one is None else one[None]
        return (one[0][None], one[1][None], one[2][None], one[3][None], one[4][None],
                one[5] if has_mu else one[5][None])  # fmt: skip
    return _solve_batch(kern, Mm, hv, Am, gv, fv, has_f, mu, rtol, what)


def _solve_batch(kern: ModuleType, Mm: FloatArray, hv: FloatArray, Am: FloatArray,
                 gv: FloatArray, fv: FloatArray, has_f: bool, mu: Any, rtol: float | None,
                 what: int) -> Any:  # fmt: skip
    if Mm.ndim < 2 or Am.ndim < 2 or hv.ndim < 1 or gv.ndim < 1 or fv.ndim < 1:
        return None
    n = Mm.shape[-1]
    m = Am.shape[-2]
    if Mm.shape[-2] != n or hv.shape[-1] != n or Am.shape[-1] != n or gv.shape[-1] != m:
        return None
    if n == 0 or fv.shape[-1] != n:
        return None
    tol = resolve_rtol(rtol)
    has_mu = mu is not None
    mu_v = V.positive_scalar_or_batch(mu, "mu") if has_mu else _NO_MU
    shapes = [Mm.shape[:-2], hv.shape[:-1], Am.shape[:-2], gv.shape[:-1]]
    if has_f:
        shapes.append(fv.shape[:-1])
    if has_mu:
        shapes.append(mu_v.shape)
    bshape = shapes[0]
    if any(s != bshape for s in shapes[1:]):
        try:
            bshape = tuple(np.broadcast_shapes(*shapes))
        except ValueError:
            return None
    N = 1
    for s in bshape:
        N *= s

    def flat(x: FloatArray, core: tuple[int, ...]) -> FloatArray:
        if x.shape[: x.ndim - len(core)] != bshape:
            x = np.broadcast_to(x, bshape + core)
        return np.ascontiguousarray(x.reshape((N, *core)))

    Mb = flat(Mm, (n, n))
    hb = flat(hv, (n,))
    Ab = flat(Am, (m, n))
    gb = flat(gv, (m,))
    fb = flat(fv, (n,)) if has_f else hb
    mub = flat(mu_v, ()) if has_mu else _NO_MU
    want_pl = what == ALL
    qdd = np.empty((N, n))
    fc = np.empty((0 if what == QDD else N, n))  # empty: the kernel skips f_c
    if want_pl:
        P = np.empty((N, n, n))
        L = np.empty((N, n, n))
    else:
        P = L = np.empty((1, 1, 1))
    status = np.empty(N, dtype=np.int64)
    rank = np.empty(N, dtype=np.intp)
    mu_out = np.empty(N)
    ratio = np.empty(N)
    args = (Mb, hb, fb, has_f, Ab, gb, mub, has_mu, tol, SPD_RTOL, V.SYMMETRY_RTOL, qdd, fc, P, L,
            want_pl, status, rank, mu_out, ratio)  # fmt: skip
    nthreads = kern.num_threads() if N >= PARALLEL_MIN_BATCH else 1
    if nthreads > 1:
        kern.solve_batch_parallel(*args, nthreads)
    else:
        kern.solve_batch_serial(*args)
    if status.any():
        return None
    return _batch_result(what, bshape, n, qdd, fc, P, L, rank, mu_v if has_mu else None, mu_out)


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
