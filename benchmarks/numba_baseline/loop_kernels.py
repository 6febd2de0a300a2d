"""Compiled (numba) fixed-step RK4 loop with mass-metric projection, for planar programs.

Imported lazily by :mod:`._fastpath` (extra ``fast``). One call of :func:`rk4_planar` advances
a :class:`nonmin.model.planar.PlanarProgram` by up to ``max_steps`` steps of exactly the
algorithm of the general driver (:func:`nonmin.sim.simulate` with ``method="rk4"`` and
``stabilization="projection"``), without returning to Python:

1. RK4 stages ``F(t, y) = (qd, qdd)``, ``qdd`` from the drift-tolerant projection dynamics
   (corrected eq. (ddq_sim)) by the core's compiled kernel
   (:func:`nonmin.core._fast_kernels.solve_one`), with the drift-aware rank tolerance of
   :func:`nonmin.sim._simulate.drift_rank_rtol`;
2. the post-step projection of :class:`nonmin.sim.Projection` (Gauss–Newton in the mass metric
   to the round-off floor, then the velocity correction = plastic impact map); the velocity
   correction and ``F`` at the projected state reuse the last Gauss–Newton factorization through
   :func:`nonmin.core._fast_kernels.solve_near` (exact to round-off: the held null-space basis
   and minimum-norm solution refined to the new A) instead of factorizing again;
3. samples at the requested times (the quintic Hermite interpolant of the projected step ends,
   :func:`_hermite`, then the projection) or at every step, with the diagnostics the
   :class:`~nonmin.sim.Trajectory` records.

The loop's pieces (:func:`_advance`, :func:`_project`, :func:`_point`, :func:`_rhs`) are
inlined into :func:`rk4_planar`, each at one call site: every array is a borrowed view
(:func:`nonmin.core._borrow.borrow`), but a call between compiled functions still passes each
member of the workspace tuples through ``NRT_incref``/``NRT_decref`` (counted with gdb
breakpoints: ~600–700 such calls per projection or sample when they were separate functions).

The model terms come from the same kernel (:func:`nonmin.model.planar._fast_kernels.pin_line_rod`)
and formulas as :meth:`PlanarModel.evaluate`, so the compiled and the general driver agree to
round-off (tested). Any kernel status other than OK (non-finite values, M̄ not positive
definite) stops the loop *before* the failing step: the general driver then takes over from the
last accepted state and raises the typed error (or recovers, exactly as it would have).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from nonmin.sim._integrators import hermite_into

from .borrow import borrow
from .core_kernels import (
    KNOWN_M_DIAGONAL,
    KNOWN_M_VALID,
    KNOWN_PATTERN,
    _pattern,
    _pattern_dot,
    orthonormalize_row,
    scratch,
    solve_again,
    solve_near,
    solve_work,
)
from .planar_kernels import pin_line_rod_work

#: Return codes of :func:`rk4_planar`.
DONE = 0  # reached t1 or the step budget of the call
FAILED = 1  # a kernel status ≠ OK or a non-finite acceleration: hand over to the general driver


#: Entries of the ``cfg`` parameter vector of :func:`rk4_planar`.
(BASE_RTOL, DRIFT_FACTOR, VEL_RTOL, PTOL, MAX_ITER, SPD_RTOL, SYM_RTOL, FLOOR, WARM, POS_CUT, CHORD,
 SING_CUT, RES_RATIO) = range(13)

#: Status of a non-finite acceleration (the core kernel's codes are 0–4).
NONFINITE_QDD = 5


@njit(cache=True)
def workspace(n, m, S, n_var, T):  # type: ignore[no-untyped-def]
    """Scratch arrays of the loop (``S`` kernel sides, ``n_var`` variable entries of A) and the
    warm-start rotation ``T`` (m × m) of the Jacobi SVD, carried from call to call. ``ws[17]``
    and ``ws[18] = [valid, rtol]`` tag the factorization held in the core scratch ``ws[11]``
    with the ``q`` and rank tolerance it was taken at; ``ws[19]`` is the ``q`` of the last
    :func:`~nonmin.core._fast_kernels.solve_near` (whether its result is still held, the core
    knows: see :func:`_solve_at`). ``A = ws[3]`` is a view of the flat buffer ``ws[1]`` the model kernel
    writes (row-major, one spare entry). ``ws[20]`` and ``ws[21]`` are the row patterns
    ``[count, k …]`` of A (every entry that can be nonzero: the program's constant nonzeros and
    its variable entries) and of the constant M, set by :func:`carry`: the loop's products
    with them skip only entries that are always zero (bitwise the dense sums). ``ws[22][0]``
    is the ``known`` argument of the core kernels (what :func:`carry` established about M and
    A's pattern)."""
    buf = np.empty(m * n + 1)
    return (np.full(2 * n + 2, np.nan), buf, np.empty((2, m)), buf[: m * n].reshape((m, n)),
            np.empty(m), np.zeros(n), np.empty(2 * n + 3), np.empty((n, n)), np.empty((n, n)),
            np.empty(n), np.empty(n), scratch(n, m), T, np.empty((9, S)), np.empty(n_var),
            np.empty(m), np.empty((n, n)), np.empty(n), np.zeros(2), np.full(n, np.nan),
            np.zeros((m, n + 1), dtype=np.int64), np.zeros((n, n + 1), dtype=np.int64),
            np.zeros(1, dtype=np.int64))  # fmt: skip


@njit(cache=True)
def carry(n, m, S, n_var, A0, var_idx, M):  # type: ignore[no-untyped-def]
    """The state :func:`rk4_planar` carries from call to call: ``(ws, (k1, kp, y1, yp, (K, ys)),
    flag)`` — the :func:`workspace` (warm-start rotation included; A's buffer holds the
    program's constant entries ``A0``; the patterns of A — ``A0``'s nonzeros and the variable
    entries ``var_idx`` — and of the constant ``M``), ``k1 = F(t, y)`` and the loop's other
    buffers, and ``flag[0] = 1`` when ``k1`` is known."""
    loop = (np.empty(2 * n), np.empty(2 * n), np.empty(2 * n), np.empty(2 * n),
            (np.empty((3, 2 * n)), np.empty(2 * n)))  # fmt: skip
    ws = workspace(n, m, S, n_var, np.eye(m))
    for i in range(A0.shape[0]):
        ws[1][i] = A0[i]
    live = A0[: m * n] != 0.0
    for k in range(var_idx.shape[0]):
        if var_idx[k] < m * n:
            live[var_idx[k]] = True
    _pattern(live.reshape((m, n)), m, n, ws[20])
    _pattern(M, n, n, ws[21])
    # what the core kernels need not check or scan again: M (constant) finite and exactly
    # symmetric, diagonal or not; A's static pattern, in the core scratch's pattern slot
    known = 0
    finite = True
    sym = True
    diag = True
    for i in range(n):
        for j in range(n):
            finite &= math.isfinite(M[i, j])
            sym &= M[i, j] == M[j, i]
            diag &= i == j or M[i, j] == 0.0
    if finite and sym:
        known |= KNOWN_M_VALID
        if diag:
            known |= KNOWN_M_DIAGONAL
    Ap = ws[11][30]
    if Ap.shape[0] == m:  # (the core's many-row path only)
        for i in range(m):
            for k in range(n + 1):
                Ap[i, k] = ws[20][i, k]
        known |= KNOWN_PATTERN
    ws[22][0] = known
    return ws, loop, np.zeros(1, dtype=np.int64)


@njit(cache=True, inline="always")
def _equal(a, b, n):  # type: ignore[no-untyped-def]
    """``a[:n] == b[:n]`` entry by entry (a NaN entry never equal)."""
    for i in range(n):
        if a[i] != b[i]:
            return False
    return True


@njit(cache=True, inline="always")
def _evaluate(prog, q, qd, ws):  # type: ignore[no-untyped-def]
    """``A = ws[3]``, ``φ = ws[2][0]``, ``γ = ws[2][1]`` of the program at ``(q, qd)``.

    ``x = ws[0]`` keeps the ``(q, qd)`` of the last evaluation: at the same ``q`` (bitwise) only γ
    is computed again (A and φ depend on ``q`` alone); e.g. the evaluation of ``F`` right after
    a projection, whose velocity correction left ``q`` as it was.
    """
    _M, _f, A0, I6, SL, prm, rows, var_idx, counts, arows, G, ac = prog
    x, buf, PG, A = ws[0], ws[1], ws[2], ws[3]
    n = q.shape[0]
    m = A.shape[0]
    same = _equal(x, q, n)  # (x starts as NaN: never equal)
    for i in range(n):
        x[i] = q[i]
        x[n + 1 + i] = qd[i]
    x[n] = 0.0
    x[2 * n + 1] = 0.0
    for i in range(m):
        PG[1, i] = 0.0
    if not same:
        for k in range(var_idx.shape[0]):  # the variable entries back to their constant part
            buf[var_idx[k]] = A0[var_idx[k]]
        for i in range(m):
            PG[0, i] = 0.0
    if I6.shape[1] > 0:
        pin_line_rod_work(x, I6, SL, prm, rows, var_idx, counts[0], counts[1], counts[2], buf, PG,
                          ws[13], ws[14], same)  # fmt: skip
    if same:
        return
    for k in range(arows.shape[0]):
        s = 0.0
        for j in range(n):
            s += G[k, j] * q[j]
        PG[0, arows[k]] = s - ac[k]


@njit(cache=True, inline="always")
def _drift_rtol(A, phi, base, factor, nrm, P):  # type: ignore[no-untyped-def]
    """:func:`nonmin.sim._simulate.drift_rank_rtol` (every row holonomic; scratch ``nrm``; A's
    row pattern ``P``)."""
    m = A.shape[0]
    if m == 0:
        return base
    big = 0.0
    for i in range(m):
        s = 0.0
        for t in range(P[i, 0]):
            a = A[i, P[i, 1 + t]]
            s += a * a
        nrm[i] = math.sqrt(s)
        if nrm[i] > big:
            big = nrm[i]
    drift = -1.0
    for i in range(m):
        if nrm[i] > base * big:
            d = abs(phi[i]) / nrm[i]
            if d > drift:
                drift = d
    if drift < 0.0:
        return base
    return min(max(base, factor * drift), 1e-2)


@njit(cache=True, inline="always")
def _matvec_rows(A, v, out, P):  # type: ignore[no-untyped-def]
    """``out = A v`` over A's row pattern ``P``."""
    for i in range(A.shape[0]):
        out[i] = _pattern_dot(A, i, P, v, 0.0)


@njit(cache=True, inline="always")
def _solve(prog, ws, cfg, h, gam, rtol, want_pl):  # type: ignore[no-untyped-def]
    """The core kernel on the workspace's A at ``q = ws[9]`` (warm-started Jacobi SVD); result
    in ``ws[6]``. The factorization stays in the scratch, tagged with ``q`` and ``rtol``."""
    # flags computed at run time: literal arguments would make numba compile solve_work once per
    # literal combination (~20 s each on first use)
    st = solve_work(prog[0], h, h, cfg[WARM] < 0.0, ws[3], gam, 1.0, cfg[WARM] < 0.0, rtol,
                    cfg[SPD_RTOL], cfg[SYM_RTOL], want_pl != 0, ws[6], ws[7], ws[8], ws[11],
                    ws[12], cfg[WARM] != 0.0, False, ws[22][0])  # fmt: skip
    q, tag = ws[9], ws[18]
    for i in range(q.shape[0]):
        ws[17][i] = q[i]
    tag[0] = 1.0 if st == 0 else 0.0
    tag[1] = rtol
    return st


@njit(cache=True, inline="always")
def _again(prog, ws, h, gam, want_pl):  # type: ignore[no-untyped-def]
    """New ``h`` and ``γ`` on the factorization held (:func:`nonmin.core._fast_kernels.solve_again`)."""
    # has_f = False computed at run time (see _solve)
    return solve_again(prog[0], h, h, want_pl < 0, gam, want_pl != 0, ws[6], ws[7], ws[8], ws[11])


@njit(cache=True, inline="always")
def _solve_at(prog, ws, cfg, h, gam, rtol, want_pl, near):  # type: ignore[no-untyped-def]
    """:func:`_solve`, or :func:`_again` when the factorization held was taken at this very
    ``q`` with this ``rtol`` (M is constant: planar bodies): the velocity projection and the
    evaluation of ``F`` at the projected state share one factorization. With ``near`` (``q``
    is the projection's result, within its correction of the ``q`` of the factorization held)
    a certified LQ held at a cutoff ``≥ rtol`` is reused exactly by
    :func:`nonmin.core._fast_kernels.solve_near` (fresh factorization if that declines); a
    second ``solve_near`` at the same ``q`` (velocity projection, then ``F``) reuses the first
    one's refined null-space basis (the core drops it when a new factorization replaces the
    one held)."""
    q, tag, fq, nq = ws[9], ws[18], ws[17], ws[19]
    n = q.shape[0]
    if tag[0] != 0.0 and tag[1] == rtol and _equal(fq, q, n):
        return _again(prog, ws, h, gam, want_pl)
    if near != 0 and want_pl == 0 and tag[0] != 0.0 and tag[1] >= rtol:
        st = solve_near(prog[0], h, h, False, ws[3], gam, cfg[SPD_RTOL], ws[6], ws[11],
                        _equal(nq, q, n), ws[22][0])  # fmt: skip
        if st == 0:
            for i in range(n):
                nq[i] = q[i]
            return st
    return _solve(prog, ws, cfg, h, gam, rtol, want_pl)


@njit(cache=True, inline="always")
def _rhs(prog, ws, cfg, t, yy, kk, near):  # type: ignore[no-untyped-def]
    """``kk = F(t, yy) = (qd, qdd)``; returns a status (0 = OK). ``near``: ``yy`` is a
    projected state (see :func:`_solve_at`)."""
    q, qd, out = ws[9], ws[10], ws[6]
    n = q.shape[0]
    for i in range(n):
        q[i] = yy[i]
        qd[i] = yy[n + i]
    _evaluate(prog, q, qd, ws)
    rtol = _drift_rtol(ws[3], ws[2][0], cfg[BASE_RTOL], cfg[DRIFT_FACTOR], ws[15], ws[20])
    st = _solve_at(prog, ws, cfg, prog[1], ws[2][1], rtol, 0, near)
    if st != 0:
        return st
    for i in range(n):
        if not math.isfinite(out[i]):
            return NONFINITE_QDD
        kk[i] = yy[n + i]
        kk[n + i] = out[i]
    return 0


@njit(cache=True, inline="always")  # (one call site; inlined: no reference counting of its tuples)
def _advance(prog, ws, cfg, t, yy, kk1, h, res, stages):  # type: ignore[no-untyped-def]
    """One raw RK4 step of size h from ``(t, yy)`` with ``k1 = kk1`` given, into ``res``.

    ``stages = (K, ys)``: ``K`` (3, 2n) receives k2, k3, k4 (one right-hand-side call site, so
    the inlined evaluation is compiled once).
    """
    K, ys = stages
    n2 = yy.shape[0]
    for s in range(3):
        c = h if s == 2 else 0.5 * h
        for i in range(n2):
            ys[i] = yy[i] + c * (kk1[i] if s == 0 else K[s - 1, i])
        st = _rhs(prog, ws, cfg, t + c, ys, K[s], 0)
        if st != 0:
            return st
    for i in range(n2):
        res[i] = yy[i] + (h / 6.0) * (kk1[i] + 2.0 * K[0, i] + 2.0 * K[1, i] + K[2, i])
    return 0


#: :func:`nonmin.sim._integrators.hermite_into` compiled: the general driver's continuous
#: extension, the same function.
_hermite = njit(cache=True)(hermite_into)


@njit(cache=True, inline="always")  # (one call site in rk4_planar)
def _project(prog, ws, cfg, yy):  # type: ignore[no-untyped-def]
    """:meth:`nonmin.sim.Projection.project` in the mass metric, in place on ``yy``."""
    q, qd, out, PG, A, vres, zero = ws[9], ws[10], ws[6], ws[2], ws[3], ws[4], ws[5]
    n = q.shape[0]
    m = A.shape[0]
    for i in range(n):
        q[i] = yy[i]
        qd[i] = yy[n + i]
    prev = np.inf
    it = 0
    cut = max(cfg[POS_CUT], cfg[BASE_RTOL])  # see _stabilization.POSITION_CUT_RTOL
    lin = False  # a linearization (factorization of A) is held
    fresh = False  # the last step was a Gauss–Newton step (A factorized at its q)
    while True:  # evaluate, then correct (at most MAX_ITER linearizations)
        _evaluate(prog, q, qd, ws)
        err = 0.0
        for i in range(m):
            a = abs(PG[0, i])
            if a > err:
                err = a
        if err <= cfg[PTOL] or err == 0.0:
            break  # converged
        floor = True  # every row at its round-off level (see _stabilization.ROUNDOFF_FLOOR)
        real = False  # some row above RES_RATIO × that level (see _stabilization._first_step)
        Ap = ws[20]
        for i in range(m):
            s = 0.0
            for t in range(Ap[i, 0]):
                j = Ap[i, 1 + t]
                s += abs(A[i, j]) * abs(yy[j])
            if abs(PG[0, i]) > cfg[FLOOR] * (1.0 + s):
                floor = False
                if abs(PG[0, i]) > cfg[RES_RATIO] * (cfg[FLOOR] * (1.0 + s)):
                    real = True
                    break
        if floor:
            break
        # the same decisions as Projection.project
        relin = (not lin) or cut == cfg[BASE_RTOL]
        if lin and err > (0.5 if fresh else cfg[CHORD]) * prev:
            if fresh:  # a Gauss–Newton step stalled
                if cut == cfg[BASE_RTOL] and err >= prev:
                    break  # no progress at the full rank: round-off floor reached
                cut = cfg[BASE_RTOL]
            elif err > 0.5 * prev:  # a chord step without real progress: residual along the cut
                cut = cfg[BASE_RTOL]
            relin = True
        if relin:
            if it >= cfg[MAX_ITER]:
                break
            it += 1
            c2 = max(cfg[SING_CUT], cfg[BASE_RTOL])
            st = -1
            if it == 1 and real and cut > c2:  # Projection: first cut by _stabilization._first_step
                st = _solve(prog, ws, cfg, zero, PG[0], c2, 0)
                if st == 0 and out[2 * n] == m:  # full rank at c2: keep that cutoff
                    cut = c2
                elif st == 0:
                    st = -1  # near a singular configuration: the cutoff POS_CUT
            if st == -1:
                st = _solve(prog, ws, cfg, zero, PG[0], cut, 0)
            lin = True
        else:
            st = _again(prog, ws, zero, PG[0], 0)
        fresh = relin
        if st != 0:
            return st
        prev = err
        for i in range(n):
            q[i] = q[i] + out[i]
    _matvec_rows(A, qd, vres, ws[20])
    # near: the factorization held is this projection's last linearization, if it took one
    st = _solve_at(prog, ws, cfg, zero, vres, cfg[VEL_RTOL], 0, 1 if lin else 0)
    if st != 0:
        return st
    for i in range(n):
        yy[i] = q[i]
        yy[n + i] = qd[i] + out[i]
    return 0


@njit(cache=True)
def _cond_mbar(M, work, k, mu, P, Z):  # type: ignore[no-untyped-def]
    """``cond(M̄)`` of the factorization held in the core scratch ``work`` (rank ``n − k``).

    ``M̄ = PMP + μQ`` acts as ``μ`` on ``R(Aᵀ)`` and as ``S = Z M Zᵀ`` on ``N(A)`` (``Z``: k
    orthonormal rows spanning N(A)), so its eigenvalues are ``μ`` and those of the k × k ``S``.
    In the kernel's null-space form ``S`` is already in the scratch; otherwise ``P = I − VᵀV``
    is formed from the kept rows ``V`` and ``Z`` comes from ``P`` by Gram–Schmidt with column
    pivoting (the largest remaining column first; ``P`` is a projector, so its columns span
    N(A)). Equals ``(σ_max(L)/σ_min(L))²`` of the Cholesky factor (what the general driver
    records) up to round-off.
    """
    n = M.shape[0]
    if k <= 0:
        return 1.0
    if work[21][1] != 0.0:  # null-space form: S = Z M Zᵀ left in G by the kernel
        return _cond_from_s(work[6][:k, :k], k, mu)  # (k > 1 symmetrizes into a copy)
    V = work[1]
    r = n - k
    for i in range(n):
        for j in range(n):
            s = 0.0
            for a in range(r):
                s += V[a, i] * V[a, j]
            P[i, j] = (1.0 if i == j else 0.0) - s
    for i in range(k):
        best = -1.0
        jb = 0
        for j in range(n):  # ‖column j of P‖² minus its part along the rows found so far
            s = 0.0
            for a in range(n):
                s += P[a, j] * P[a, j]
            for l in range(i):
                c = 0.0
                for a in range(n):
                    c += Z[l, a] * P[a, j]
                s -= c * c
            if s > best:
                best = s
                jb = j
        for a in range(n):
            Z[i, a] = P[a, jb]
        orthonormalize_row(Z, i, 2)  # twice: reorthogonalization
    S = np.empty((k, k))
    for i in range(k):
        for j in range(k):
            s = 0.0
            for a in range(n):
                t = 0.0
                for b in range(n):
                    t += M[a, b] * Z[j, b]
                s += Z[i, a] * t
            S[i, j] = s
    return _cond_from_s(S, k, mu)


@njit(cache=True)
def _cond_from_s(S, k, mu):  # type: ignore[no-untyped-def]
    """``max(μ, λ_max(S)) / min(μ, λ_min(S))`` for the k × k symmetric ``S``."""
    if k == 1:
        lo = S[0, 0]
        hi = S[0, 0]
    else:
        ev = np.linalg.eigvalsh(0.5 * (S + S.T))
        lo = ev[0]
        hi = ev[k - 1]
    return max(mu, hi) / min(mu, lo)


@njit(cache=True, inline="always")  # (one call site in rk4_planar)
def _point(prog, ws, cfg, tt, yy, recs, k, kk):  # type: ignore[no-untyped-def]
    """The full evaluation recorded at a sample (row ``k`` of ``recs``); ``kk = F(tt, yy)``."""
    rec_t, rec_q, rec_qd, rec_qdd, rec_fc, rec_rank, rec_cond, rec_mu, rec_energy, rec_phi, rec_vel = recs
    M, f = prog[0], prog[1]
    q, qd, out, PG, A, vres = ws[9], ws[10], ws[6], ws[2], ws[3], ws[4]
    n = q.shape[0]
    m = A.shape[0]
    for i in range(n):
        q[i] = yy[i]
        qd[i] = yy[n + i]
    _evaluate(prog, q, qd, ws)
    rtol = _drift_rtol(A, PG[0], cfg[BASE_RTOL], cfg[DRIFT_FACTOR], ws[15], ws[20])
    st = _solve_at(prog, ws, cfg, f, PG[1], rtol, 0, 1)
    if st != 0:
        return st
    for i in range(n):
        if not math.isfinite(out[i]):
            return NONFINITE_QDD
    rec_t[k] = tt
    e_kin = 0.0
    e_pot = 0.0
    for i in range(n):
        rec_q[k, i] = q[i]
        rec_qd[k, i] = qd[i]
        rec_qdd[k, i] = out[i]
        rec_fc[k, i] = out[n + i]
        kk[i] = qd[i]
        kk[n + i] = out[i]
        e_kin += qd[i] * _pattern_dot(M, i, ws[21], qd, 0.0)
        e_pot += f[i] * q[i]
    rec_rank[k] = int(out[2 * n])
    rec_mu[k] = out[2 * n + 1]
    rec_cond[k] = _cond_mbar(M, ws[11], n - int(out[2 * n]), out[2 * n + 1], ws[7], ws[16])
    rec_energy[k] = 0.5 * e_kin - e_pot
    pn = 0.0
    for i in range(m):
        a = abs(PG[0, i])
        if a > pn:
            pn = a
    rec_phi[k] = pn
    _matvec_rows(A, qd, vres, ws[20])
    vn = 0.0
    for i in range(m):
        a = abs(vres[i])
        if a > vn:
            vn = a
    rec_vel[k] = vn
    return 0


@njit(cache=True)
def rk4_planar(prog, t, t1, dt, y, t_out, out_i, every, max_steps, cfg, recs, state):  # type: ignore[no-untyped-def]
    """Advance ``y = (q, qd)`` (in place) from ``t`` by at most ``max_steps`` RK4 steps.

    ``prog = (M, f, A0, I6, SL, prm, rows, var_idx, counts, angle_rows, G, angle_const)`` (a
    :class:`~nonmin.model.planar.PlanarProgram`'s arrays). ``t_out`` holds the requested
    output times (``every`` false; ``out_i`` is the next one) or is ignored (``every`` true:
    one sample per step end). ``cfg``: see :data:`BASE_RTOL` …; ``recs`` the 11 record arrays
    (``t, q, qd, qdd, f_c, rank, cond, mu, energy, ‖φ‖∞, ‖A qd‖∞``) whose length must cover the
    samples of ``max_steps`` steps. ``state = carry(...)`` is the state carried between calls
    (workspace with the warm-start rotation, ``F(t, y)`` and whether it is known), so a run
    split into calls gives bitwise the result of one call. Returns ``(code, t, steps, n_rhs,
    n_rec, out_i)``; on :data:`FAILED` the values describe the last accepted step (samples of
    the failed step are not counted) and ``y`` is that step's state.

    Every array is used through borrowed views (:func:`nonmin.core._borrow.borrow`): no
    reference counting inside the loop. The caller owns all of them for the whole call.
    """
    ws, loop, flag = borrow(state)
    prog = borrow(prog)
    recs = borrow(recs)
    y = borrow(y)
    t_out = borrow(t_out)
    cfg = borrow(cfg)
    k1, kp, y1, yp, stages = loop
    n = prog[0].shape[0]
    n_rhs = 0
    n_rec = 0
    steps = 0
    have_k1 = flag[0] != 0  # k1 = F(t, y) known from the previous step's end
    n_out = t_out.shape[0]
    while t < t1 and steps < max_steps:
        rem = t1 - t
        h = dt
        if h >= rem or rem - h <= 1e-9 * h:
            h = rem
        st = 0
        if not have_k1:
            st = _rhs(prog, ws, cfg, t, y, k1, 0)
            n_rhs += 1
        if st == 0:
            st = _advance(prog, ws, cfg, t, y, k1, h, y1, stages)
            n_rhs += 3
        if st != 0:
            flag[0] = 0
            return FAILED, t, steps, n_rhs, n_rec, out_i
        t_new = t1 if h == t1 - t else t + h
        k = n_rec
        oi = out_i
        oe = oi  # the requested samples of this step: t_out[oi:oe]
        end_tol = 1e-12 * max(1.0, abs(t_new))
        if not every:
            while oe < n_out and t_out[oe] <= t_new + end_tol:
                oe += 1
        n_s = 1 if every else oe - oi
        last_end = every or (n_s > 0 and abs((t_out[oe - 1] - t) - h) <= end_tol)
        have_kp = n_s > 0 or t_new < t1
        # In order: the step end (it = −1: projected, then kp = F(t_new, y1), the next step's
        # k1 and the interpolant's end slope, recorded if it is the last sample), then the
        # samples t_out[oi:oe] (inside the step: the Hermite interpolant, projected, as the
        # general driver; a duplicate of the step end: recorded again). One call site each
        # for _project and _point, which are inlined.
        for it in range(-1, 0 if every else n_s):
            tgt = y1
            tt = t_new
            row = k + n_s - 1
            dst = kp
            inside = False
            if it >= 0:
                s = t_out[oi + it] - t
                row = k + it
                inside = abs(s - h) > end_tol
                if inside:
                    _hermite(y, k1, y1, kp, h, max(s, 0.0), yp)
                    tgt = yp
                    tt = t + s
                    dst = stages[1]
            if it < 0 or inside:
                st = _project(prog, ws, cfg, tgt)
                if st != 0:
                    break
            if it < 0 and not have_kp:
                continue
            if it < 0 and not last_end:
                st = _rhs(prog, ws, cfg, t_new, y1, kp, 1)
                n_rhs += 1
            elif it < 0 or inside or row != k + n_s - 1:  # (else: recorded at it = −1)
                st = _point(prog, ws, cfg, tt, tgt, recs, row, dst)
                n_rhs += 1
            if it >= 0:
                recs[0][row] = t_out[oi + it]
            if st != 0:
                break
        if st != 0:
            flag[0] = 0
            return FAILED, t, steps, n_rhs, n_rec, out_i
        k += n_s
        oi = oe
        n_rec = k
        out_i = oi
        for i in range(2 * n):
            y[i] = y1[i]
        if have_kp:
            for i in range(2 * n):
                k1[i] = kp[i]
        have_k1 = have_kp
        t = t_new
        steps += 1
    flag[0] = 1 if have_k1 else 0
    return DONE, t, steps, n_rhs, n_rec, out_i
