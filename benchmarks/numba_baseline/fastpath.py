"""The numba loop of nonmin ≤ 0.1 (``simulate(engine="compiled")``), frozen as the baseline of
issue 17's target 4 ("planar: no regression against today's compiled loop").

The package dropped numba (its first use compiled for minutes; the C++ engine covers every run).
This directory keeps that loop unchanged, outside ``src``, so ``loop_bench.py --planar`` can still
time the engine against it: ``core_kernels.py`` (the core's numba kernels), ``planar_kernels.py``
(the pin/line/rod block), ``loop_kernels.py`` (RK4 + mass-metric projection + samples),
``borrow.py`` (reference-count-free views) and this driver. Needs ``pip install numba``.

:func:`simulate` runs the loop from a given state (the engine's first sample, so both start from
the same projected state) to ``t1``; it builds the program data the way
``PlanarModel.fast_program`` did (constant M and gravity, the layout's pin/line/rod inputs).
"""

from __future__ import annotations

import time
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from nonmin._validation import SYMMETRY_RTOL
from nonmin.core.linalg import DEFAULT_RTOL, SPD_RTOL
from nonmin.sim._simulate import DRIFT_RANK_FACTOR
from nonmin.sim._stabilization import (
    CHORD_RATE,
    ROUNDOFF_FLOOR,
    SINGULAR_CUT_RTOL,
    Projection,
)

from . import loop_kernels

FloatArray = NDArray[np.float64]

#: The projection's cutoff rule of nonmin ≤ 0.1, frozen with the loop: a first Gauss–Newton
#: residual within ROUNDOFF_RESIDUAL_RATIO of its round-off floor was cut at POSITION_CUT_RTOL
#: (nonmin now takes the full rank there when A has no singular value below SINGULAR_CUT_RTOL).
POSITION_CUT_RTOL = 1e-2
ROUNDOFF_RESIDUAL_RATIO = 1e3

#: Target wall time (s) of one compiled chunk.
CHUNK_SECONDS = 0.25


def _kernels() -> Any:
    return loop_kernels


class PlanarProgram(NamedTuple):
    """A planar model's dynamics under one active set, as the numba loop reads it."""

    n: int
    m: int
    M: FloatArray
    f: FloatArray
    A0: FloatArray
    I6: Any
    SL: FloatArray
    prm: FloatArray
    rows: Any
    var_idx: Any
    counts: Any
    angle_rows: Any
    G: FloatArray
    angle_const: FloatArray


def program(model: Any, active: frozenset[str]) -> PlanarProgram:
    """The program of a planar model (no springs, dampers, drivers or user-defined joints)."""
    lay = model._layout(active)
    if lay.m == 0 or lay.drivers or lay.generic or model._stiff or model._damped:
        raise ValueError("the numba loop covers pin/line/rod/angle models without forces")

    def c(x: Any, dtype: Any = None) -> Any:
        return np.array(x, dtype=dtype, order="C", copy=True)

    return PlanarProgram(
        n=lay.n, m=lay.m, M=c(model._M, dtype=np.float64), f=c(model._fg, dtype=np.float64),
        A0=c(lay.A0), I6=c(lay.I6, dtype=np.intp), SL=c(lay.SL), prm=c(lay.k_prm),
        rows=c(lay.k_rows, dtype=np.intp), var_idx=c(lay.var_idx, dtype=np.intp),
        counts=np.array([lay.P, lay.NL, lay.NR], dtype=np.intp),
        angle_rows=c(lay.angle_rows, dtype=np.intp), G=c(lay.G, dtype=np.float64).reshape(-1, lay.n),
        angle_const=c(lay.angle_const, dtype=np.float64),
    )  # fmt: skip


class _NoBar:
    def update(self, t: float) -> None:
        pass


def simulate(prog: PlanarProgram, t0: float, t1: float, dt: float, q: FloatArray, qd: FloatArray,
             t_out: FloatArray | None) -> FastResult:  # fmt: skip
    """RK4 at ``dt`` with the mass-metric projection from ``(t0, q, qd)`` to ``t1``; samples at
    ``t_out`` after ``t0`` (None: every step), as ``simulate(engine="compiled")`` ran it."""
    out_i = 0 if t_out is None else int(np.searchsorted(t_out, t0, side="right"))
    return run(prog, t=t0, t1=t1, dt=dt, q=np.array(q, dtype=float), qd=np.array(qd, dtype=float),
               t_out=t_out, out_i=out_i, rank_rtol=None, drift_factor=DRIFT_RANK_FACTOR,
               stab=Projection(), max_steps=10**9, active_row=np.ones(0, dtype=bool), k=0,
               progress=_NoBar())  # fmt: skip


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
