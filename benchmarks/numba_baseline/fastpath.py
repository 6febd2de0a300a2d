"""The compiled engine of :func:`nonmin.sim.simulate`: eligibility and the chunked driver.

``simulate(..., engine="auto")`` runs a fixed-step RK4 simulation with the mass-metric
projection in one compiled loop (:mod:`._fast_kernels`) when nothing in it needs Python:

* the method is :class:`~nonmin.sim.RK4` and the stabilization a mass-metric
  :class:`~nonmin.sim.Projection` (the defaults);
* no controller, no events, no automatic contact (no unilateral constraint with
  ``contact=True``);
* the model returns a program from :meth:`nonmin.model.Model.fast_program` for the active set
  (planar models without springs, dampers, drivers or user-defined joints);
* the compiled backend of :mod:`nonmin.core` is in use (numba installed, backend not
  ``"numpy"``; with ``"auto"`` up to :data:`nonmin.core._fast.AUTO_NUMBA_MAX_N` coordinates or
  degrees of freedom ``n − m``, :func:`nonmin.core._fast.auto_compiled`; with more of both,
  LAPACK is faster).

The loop runs in chunks of steps (about :data:`CHUNK_SECONDS` of wall time each) so the progress
bar moves, ``KeyboardInterrupt`` is honoured between chunks and ``max_steps`` is checked. When a
kernel reports a failure the chunk ends at the last accepted step and the general driver
continues from there, so errors are raised by the same code, with the same types and messages,
as with ``engine="python"``.
"""

from __future__ import annotations

import time
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from .._validation import SYMMETRY_RTOL
from ..core._fast import AUTO_NUMBA_MAX_N, auto_compiled, backend_setting, get_backend
from ..core.linalg import DEFAULT_RTOL, SPD_RTOL
from ..errors import InputError, MissingDependencyError
from ._integrators import RK4
from ._stabilization import (
    CHORD_RATE,
    POSITION_CUT_RTOL,
    ROUNDOFF_FLOOR,
    ROUNDOFF_RESIDUAL_RATIO,
    SINGULAR_CUT_RTOL,
    Projection,
)

FloatArray = NDArray[np.float64]

#: Engines accepted by ``simulate(engine=...)``.
ENGINES = ("auto", "compiled", "engine", "python")

#: Target wall time (s) of one compiled chunk (progress, interrupts, step budget in between).
CHUNK_SECONDS = 0.25

_KERNELS: dict[str, Any] = {}


def _kernels() -> Any:
    """The compiled loop module, or None when numba is missing."""
    if "mod" not in _KERNELS:
        try:
            from . import _fast_kernels
        except ImportError:
            _KERNELS["mod"] = None
        else:
            _KERNELS["mod"] = _fast_kernels
    return _KERNELS["mod"]


def check_engine(engine: object) -> str:
    if not isinstance(engine, str) or engine not in ENGINES:
        raise InputError(f"engine must be one of {ENGINES}, got {engine!r}")
    return engine


def program_for(
    engine: str,
    model: Any,
    integ: Any,
    stab: Any,
    controller: Any,
    events: tuple[Any, ...],
    unilateral: tuple[str, ...],
    active: frozenset[str],
) -> Any | None:
    """The model's compiled program when the compiled engine applies, else None.

    With ``engine="compiled"`` a run that cannot use it raises :class:`InputError` naming the
    reason (``MissingDependencyError`` when numba is missing); with ``"auto"`` it returns None.
    """
    if engine in ("python", "engine"):
        return None
    reason = _ineligible(model, integ, stab, controller, events, unilateral, active)
    prog = None
    if reason is None:
        prog = model.fast_program(active)
        if prog is None:
            reason = (f"model {model.name!r} ({type(model).__name__}) has no compiled program for "
                      f"the active set (planar models without springs, dampers, drivers or "
                      f"user-defined joints have one)")
        elif not hasattr(prog, "I6"):
            reason = f"unknown compiled program type {type(prog).__name__}"
    if reason is not None:
        if engine == "compiled":
            if reason == "numba":
                raise MissingDependencyError(
                    "engine='compiled' needs numba: pip install 'nonmin[fast]'"
                )
            raise InputError(f"engine='compiled' cannot run this simulation: {reason}")
        return None
    return prog


def _ineligible(
    model: Any, integ: Any, stab: Any, controller: Any, events: tuple[Any, ...],
    unilateral: tuple[str, ...], active: frozenset[str],
) -> str | None:  # fmt: skip
    if type(integ) is not RK4:
        return f"method must be 'rk4' (got {getattr(integ, 'name', type(integ).__name__)!r})"
    if not (type(stab) is Projection and stab.metric == "mass" and stab.velocity and not stab.energy):
        return f"stabilization must be the mass-metric 'projection' (got {stab!r})"
    if controller is not None:
        return "a controller is given"
    if events:
        return "events are given"
    if unilateral:
        return f"automatic contact is on for unilateral constraints {list(unilateral)} (contact=True)"
    if not active:
        return "no constraint is active"
    if get_backend() == "numpy":
        return "the nonmin.core backend is 'numpy' (set_backend('auto') or 'numba')"
    m = int(model.num_rows(active))
    if backend_setting() == "auto" and not auto_compiled(model.n, m):
        return (f"n = {model.n} coordinates and n − m = {model.n - m} > {AUTO_NUMBA_MAX_N} degrees "
                "of freedom with backend 'auto' (LAPACK is faster there; set_backend('numba') "
                "forces it)")
    if _kernels() is None:
        return "numba"
    return None


class FastResult(NamedTuple):
    """What the compiled engine did: new state, counters and recorded blocks."""

    t: float
    y: FloatArray
    steps: int
    n_rhs: int
    out_i: int
    failed: bool
    blocks: list[dict[str, Any]]


def run(
    prog: Any,
    *,
    t: float,
    t1: float,
    dt: float,
    q: FloatArray,
    qd: FloatArray,
    t_out: FloatArray | None,
    out_i: int,
    rank_rtol: float | None,
    drift_factor: float,
    stab: Projection,
    max_steps: int,
    active_row: NDArray[np.bool_],
    k: int,
    progress: Any,
) -> FastResult:
    """Advance with the compiled loop until ``t1``, a failure or ``max_steps`` steps."""
    kern = _kernels()
    n = prog.n
    base = DEFAULT_RTOL if rank_rtol is None else float(rank_rtol)
    vr = stab.velocity_rank_rtol(rank_rtol)
    vtol = base if vr is None else float(vr)
    cfg = np.array([base, drift_factor, vtol, float(stab.tol), float(stab.max_iter), SPD_RTOL,
                    SYMMETRY_RTOL, ROUNDOFF_FLOOR, 1.0, POSITION_CUT_RTOL, CHORD_RATE,
                    SINGULAR_CUT_RTOL, ROUNDOFF_RESIDUAL_RATIO])  # fmt: skip
    pr = (prog.M, prog.f, prog.A0, prog.I6, prog.SL, prog.prm, prog.rows, prog.var_idx,
          prog.counts, prog.angle_rows, prog.G, prog.angle_const)  # fmt: skip
    every = t_out is None
    tv = np.zeros(0) if t_out is None else np.ascontiguousarray(t_out, dtype=np.float64)
    y = np.concatenate((q, qd))
    steps_total = 0
    rhs_total = 0
    blocks: list[dict[str, Any]] = []
    m = prog.m
    # owned here for the whole run: the loop works on borrowed views of them
    state = kern.carry(n, m, prog.I6.shape[1], prog.var_idx.shape[0], prog.A0, prog.var_idx,
                       prog.M)
    chunk = 64
    failed = False
    while t < t1 and steps_total < max_steps:
        S = min(chunk, max_steps - steps_total)
        if every:
            cap = S
        else:
            hi = int(np.searchsorted(tv, t + (S + 1) * dt, side="right"))
            cap = max(hi - out_i, 0)
        rec = _alloc(cap, n)
        w0 = time.perf_counter()
        code, t, st, nr, nrec, out_i = kern.rk4_planar(pr, t, t1, dt, y, tv, out_i, every, S, cfg, rec, state)
        elapsed = time.perf_counter() - w0
        steps_total += st
        rhs_total += nr
        if nrec:
            blocks.append(_block(rec, nrec, n, k, active_row))
        progress.update(t)
        if code != kern.DONE:
            failed = True
            break
        if st > 0:
            chunk = int(min(max(16, chunk * CHUNK_SECONDS / max(elapsed, 1e-6)), 1 << 20))
    return FastResult(t, y, steps_total, rhs_total, out_i, failed, blocks)


def _alloc(cap: int, n: int) -> tuple[FloatArray, ...]:
    e = np.empty
    return (e(cap), e((cap, n)), e((cap, n)), e((cap, n)), e((cap, n)), e(cap, dtype=np.int64),
            e(cap), e(cap), e(cap), e(cap), e(cap))  # fmt: skip


def _block(rec: tuple[Any, ...], N: int, n: int, k: int, active_row: NDArray[np.bool_]) -> dict[str, Any]:
    rt, rq, rqd, rqdd, rfc, rrank, rcond, rmu, ren, rphi, rvel = rec
    return {
        "t": rt[:N].copy(),
        "q": rq[:N].copy(),
        "qd": rqd[:N].copy(),
        "qdd": rqdd[:N].copy(),
        "f_c": rfc[:N].copy(),
        "u": np.zeros((N, k)),
        "active_mask": np.repeat(active_row[None, :], N, axis=0),
        "rank": rrank[:N].copy(),
        "cond": rcond[:N].copy(),
        "mu": rmu[:N].copy(),
        "energy": ren[:N].copy(),
        "phi_norm": rphi[:N].copy(),
        "velocity_residual_norm": rvel[:N].copy(),
    }
