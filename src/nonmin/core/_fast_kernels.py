"""Numba-compiled kernels of the projection dynamics (imported lazily by :mod:`._fast`).

One per-state routine, :func:`solve_state`, does the whole evaluation of
:func:`nonmin.core.solve_dynamics` for one ``(M, h, A, γ, f)`` in caller-provided scratch
(:func:`scratch`; a batch driver allocates it once per chunk of states); the single-call
driver :func:`solve_one` and the batched drivers :func:`solve_batch_serial` /
:func:`solve_batch_parallel` all call it, so a state gives bitwise the same result whichever
driver evaluates it.

Per state (``n`` coordinates, ``m`` constraint rows):

1. input checks: every entry finite, ``max|M − Mᵀ| ≤ SYMMETRY_RTOL · max|M|`` (exactly the
   decision of :func:`nonmin._validation.symmetric`); a failure returns a status code and the
   caller re-runs the NumPy path, which raises the typed error;
2. row equilibration ``B = D A`` with the policy of :mod:`nonmin.core.linalg` (rows with norm
   ``≤ rtol · max norm`` are zero rows), augmented with the column ``D γ``;
3. one-sided (Hestenes) Jacobi SVD of ``B`` by plane rotations of its rows: at convergence the
   rows are mutually orthogonal, their norms are the singular values σ_i of ``D A`` and their
   directions the right singular vectors; the same rotations applied to the augmented column give
   ``Uᵀ D γ``. Rows with ``σ_i ≤ rtol · σ_max`` are dropped (same rank policy as
   :func:`nonmin.core.range_basis`; Jacobi and LAPACK's ``gesdd`` can disagree only on a
   singular value within round-off of the cutoff). Difference: a row whose norm has fallen to
   ``≤ eps · ‖DA‖_F`` (e.g. the difference of two duplicated rows) is not rotated any more — its
   σ is round-off, far below any cutoff ``rtol ≥ 1e-15``, and rotating it would only chase noise;
4. with ``V`` (r × n) the kept unit rows: ``Q = VᵀV``, ``PMP = M − QM − MQ + QMQ`` by rank-r
   updates (``K = MVᵀ``, ``G = VK``; no n × n × n products), ``μ = tr(PMP)/(n − r)``
   (``tr(M)/n`` if ``r = n``; 1 if not positive), ``M̄ = PMP + μQ`` (lower triangle);
5. Cholesky of ``M̄`` with the SPD test of :func:`nonmin.core.linalg.cholesky` (fail if a pivot
   ``≤ 0``, or if a pivot ``L_ii² ≤ SPD_RTOL · max M̄_jj``);
6. ``w = −(DA)⁺ D γ``, ``rhs = P(g − Mw) + μw`` with ``g = h + f``, ``qdd = M̄⁻¹ rhs``,
   ``f_c = M qdd − g``.

Status codes: :data:`OK`, :data:`CHOL_FAIL`, :data:`SMALL_PIVOT`, :data:`NONFINITE`,
:data:`ASYMMETRIC`.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numba import njit, prange

OK = 0
CHOL_FAIL = 1
SMALL_PIVOT = 2
NONFINITE = 3
ASYMMETRIC = 4

#: Maximum number of Jacobi sweeps (convergence is quadratic; m ≤ 30 needs < 10).
MAX_SWEEPS = 60

_EPS = float(np.finfo(np.float64).eps)
_TINY = float(np.finfo(np.float64).tiny)


@njit(cache=True)
def scratch(n, m):
    """Scratch arrays of :func:`solve_state` for ``n`` coordinates and ``m`` rows."""
    return (np.empty((m, n + 1)), np.empty((5, m, n)), np.empty((m, m)), np.empty((n, n)),
            np.empty(3 * n + 2 * m))  # fmt: skip


#: No fast-math flags: strict IEEE arithmetic, so the compiled per-state routine gives bitwise the
#: same result whichever driver (single, serial batch, parallel batch) inlines it. (With
#: ``reassoc`` the vectorizer may order sums differently per call site: measured mismatches.)
_FM: set[str] = set()


@njit(cache=True, fastmath=_FM, inline="always")  # numba-level inlining: no call, no refcounts
def solve_state(M, h, f, has_f, A, gam, mu_in, has_mu, rtol, spd_rtol, sym_rtol,
                qdd, fc, P, L, want_pl, B, S, G, W, vec):  # fmt: skip
    """Evaluate one state; returns ``(status, rank, mu, pivot_ratio)``. See module docstring.

    Scratch (from :func:`scratch`, reusable across states): ``B`` (m, n+1), ``S`` (5, m, n),
    ``G`` (m, m), ``W`` (n, n), ``vec`` (3n + 2m).
    """
    n = M.shape[0]
    m = A.shape[0]
    # ---------------------------------------------------------------- 1. input checks
    bad = False  # x − x is 0 for finite x, NaN for ±inf and NaN (a boolean OR: no FP reordering)
    for i in range(n):
        for j in range(n):
            bad |= M[i, j] - M[i, j] != 0.0
        bad |= h[i] - h[i] != 0.0
    if has_f:
        for i in range(n):
            bad |= f[i] - f[i] != 0.0
    for i in range(m):
        for j in range(n):
            bad |= A[i, j] - A[i, j] != 0.0
        bad |= gam[i] - gam[i] != 0.0
    if bad:
        return NONFINITE, 0, 0.0, 0.0
    asym = 0.0
    for i in range(n):
        for j in range(i):
            d = abs(M[i, j] - M[j, i])
            if d > asym:
                asym = d
    if asym > 0.0:  # same decision as _validation.symmetric (max|M| only needed now)
        scale = 0.0
        for i in range(n):
            for j in range(n):
                a = abs(M[i, j])
                if a > scale:
                    scale = a
        if asym > sym_rtol * max(scale, _TINY):
            return ASYMMETRIC, 0, 0.0, 0.0
    # ---------------------------------------------------------------- scratch
    V = S[0]  # kept right singular vectors (rows)
    Kt = S[1]  # (M Vᵀ)ᵀ = V M
    Tt = S[2]  # G V, G = V M Vᵀ
    Et = S[3]
    Ft = S[4]
    g = vec[:n]
    wv = vec[n : 2 * n]
    u = vec[2 * n : 3 * n]
    sig = vec[3 * n : 3 * n + m]
    cv = vec[3 * n + m : 3 * n + 2 * m]
    # ---------------------------------------------------------------- 2. equilibration
    big = 0.0
    for i in range(m):
        s = 0.0
        for j in range(n):
            s += A[i, j] * A[i, j]
        nrm = math.sqrt(s)
        sig[i] = nrm
        if nrm > big:
            big = nrm
    thr = rtol * big
    for i in range(m):
        nrm = sig[i]
        if nrm > thr:
            di = 1.0 / nrm
            for j in range(n):
                B[i, j] = A[i, j] * di
            B[i, n] = di * gam[i]
        else:
            for j in range(n + 1):
                B[i, j] = 0.0
    # ---------------------------------------------------------------- 3. Jacobi SVD
    # Rows of norm ≤ eps·‖B‖_F are round-off (e.g. the difference of two duplicated rows): they
    # are never rotated, else the sweeps would chase noise (their σ is far below any rtol).
    frob2 = 0.0
    for i in range(m):
        for k in range(n):
            frob2 += B[i, k] * B[i, k]
    noise2 = _EPS * _EPS * frob2
    for _sweep in range(MAX_SWEEPS):
        rotated = False
        for i in range(m - 1):
            for j in range(i + 1, m):
                aa = 0.0
                bb = 0.0
                cc = 0.0
                for k in range(n):
                    x = B[i, k]
                    y = B[j, k]
                    aa += x * x
                    bb += y * y
                    cc += x * y
                if aa <= noise2 or bb <= noise2 or abs(cc) <= _EPS * math.sqrt(aa * bb):
                    continue
                rotated = True
                zeta = (bb - aa) / (2.0 * cc)
                if abs(zeta) > 1e150:
                    t = 0.5 / zeta
                else:
                    t = math.copysign(1.0, zeta) / (abs(zeta) + math.sqrt(1.0 + zeta * zeta))
                cs = 1.0 / math.sqrt(1.0 + t * t)
                sn = cs * t
                for k in range(n + 1):
                    x = B[i, k]
                    y = B[j, k]
                    B[i, k] = cs * x - sn * y
                    B[j, k] = sn * x + cs * y
        if not rotated:
            break
    smax = 0.0
    for i in range(m):
        s = 0.0
        for k in range(n):
            s += B[i, k] * B[i, k]
        sig[i] = math.sqrt(s)
        if sig[i] > smax:
            smax = sig[i]
    r = 0
    for i in range(m):
        if sig[i] > rtol * smax:
            inv = 1.0 / sig[i]
            for k in range(n):
                V[r, k] = B[i, k] * inv
            cv[r] = B[i, n] * inv  # (Uᵀ D γ)_i / σ_i
            r += 1
    # w = −(DA)⁺ D γ = −Σ_k v_k (u_kᵀ D γ)/σ_k
    for j in range(n):
        wv[j] = 0.0
    for k in range(r):
        c = cv[k]
        for j in range(n):
            wv[j] -= V[k, j] * c
    # ---------------------------------------------------------------- 4. PMP, μ, M̄
    for k in range(r):  # Kt = V M  (M symmetric: rows of M are its columns)
        for i in range(n):
            s = 0.0
            for j in range(n):
                s += V[k, j] * M[i, j]
            Kt[k, i] = s
    for k in range(r):  # G = V M Vᵀ (r × r), Tt = G V
        for l in range(r):
            s = 0.0
            for j in range(n):
                s += V[k, j] * Kt[l, j]
            G[k, l] = s
    for l in range(r):
        for j in range(n):
            Tt[l, j] = 0.0
        for k in range(r):
            c = G[l, k]
            for j in range(n):
                Tt[l, j] += c * V[k, j]
    tr_pmp = 0.0
    tr_m = 0.0
    for i in range(n):  # diag(PMP) = diag(M − QM − MQ + QMQ)
        s = 0.0
        for k in range(r):
            s += (2.0 * Kt[k, i] - Tt[k, i]) * V[k, i]
        tr_pmp += M[i, i] - s
        tr_m += M[i, i]
    if has_mu:
        mu = mu_in
    else:
        if r < n:
            mu = tr_pmp / (n - r)
        else:
            mu = tr_m / n
        if not mu > 0.0:
            mu = 1.0
    for k in range(r):
        for j in range(n):
            Et[k, j] = Kt[k, j] - mu * V[k, j]
            Ft[k, j] = Kt[k, j] - Tt[k, j]
    dmax = -np.inf
    for i in range(n):  # M̄ = PMP + μQ = M − Vᵀ Et − Ftᵀ V (lower triangle, row by row)
        for j in range(i + 1):
            W[i, j] = M[i, j]
        for k in range(r):
            a = V[k, i]
            b = Ft[k, i]
            for j in range(i + 1):
                W[i, j] -= a * Et[k, j] + b * V[k, j]
        if W[i, i] > dmax:
            dmax = W[i, i]
    # ---------------------------------------------------------------- 5. Cholesky
    status = OK
    ratio = np.inf
    for j in range(n):
        s = 0.0
        for k in range(j):
            s += W[j, k] * W[j, k]
        s = W[j, j] - s
        if not s > 0.0:
            return CHOL_FAIL, r, mu, 0.0
        ljj = math.sqrt(s)
        piv = ljj * ljj
        if piv <= spd_rtol * dmax:
            status = SMALL_PIVOT
            if piv / dmax < ratio:
                ratio = piv / dmax
        W[j, j] = ljj
        for i in range(j + 1, n):
            s2 = 0.0
            for k in range(j):
                s2 += W[i, k] * W[j, k]
            W[i, j] = (W[i, j] - s2) / ljj
    if status != OK:
        return status, r, mu, ratio
    # ---------------------------------------------------------------- 6. right-hand side, solve
    for i in range(n):
        gi = h[i]
        if has_f:
            gi += f[i]
        g[i] = gi
    for i in range(n):  # u = g − M w
        s = 0.0
        for j in range(n):
            s += M[i, j] * wv[j]
        u[i] = g[i] - s
    for k in range(r):  # cv ← V u
        s = 0.0
        for j in range(n):
            s += V[k, j] * u[j]
        cv[k] = s
    for i in range(n):  # rhs = u − Vᵀ(V u) + μ w   (stored in u)
        u[i] += mu * wv[i]
    for k in range(r):
        c = cv[k]
        for i in range(n):
            u[i] -= V[k, i] * c
    for i in range(n):  # L y = rhs
        s = 0.0
        for k in range(i):
            s += W[i, k] * u[k]
        u[i] = (u[i] - s) / W[i, i]
    for i in range(n - 1, -1, -1):  # Lᵀ x = y, column-oriented (contiguous rows of L)
        qdd[i] = u[i] / W[i, i]
        xi = qdd[i]
        for k in range(i):
            u[k] -= W[i, k] * xi
    for i in range(n):  # f_c = M qdd − g
        s = 0.0
        for j in range(n):
            s += M[i, j] * qdd[j]
        fc[i] = s - g[i]
    if want_pl:
        for i in range(n):
            for j in range(n):
                s = 0.0
                for k in range(r):
                    s += V[k, i] * V[k, j]
                P[i, j] = (1.0 if i == j else 0.0) - s
                L[i, j] = W[i, j] if j <= i else 0.0
    return OK, r, mu, 0.0


@njit(cache=True)
def solve_one(M, h, f, A, gam, params, out, P, L):
    """Single state (2-D ``M``, ``A``), with few arguments to keep the call overhead small.

    ``params = [has_f, mu, has_mu, rtol, spd_rtol, sym_rtol, want_pl]``; writes
    ``out = [qdd (n), f_c (n), rank, mu, pivot_ratio]`` (and ``P``, ``L`` if ``want_pl``; pass
    any 2-D arrays otherwise) and returns the status. One entry point for both uses: each
    compiled entry point costs seconds of compilation on first use.
    """
    n = M.shape[0]
    B, S, G, W, vec = scratch(n, A.shape[0])
    st, r, mu, ratio = solve_state(
        M, h, f, params[0] != 0.0, A, gam, params[1], params[2] != 0.0, params[3], params[4],
        params[5], out[:n], out[n : 2 * n], P, L, params[6] != 0.0, B, S, G, W, vec,
    )  # fmt: skip
    out[2 * n] = r
    out[2 * n + 1] = mu
    out[2 * n + 2] = ratio
    return st


@njit(cache=True)
def _run_range(lo, hi, M, h, f, has_f, A, gam, mu_in, has_mu, rtol, spd_rtol, sym_rtol,
               qdd, fc, P, L, want_pl, status, rank, mu_out, ratio):  # fmt: skip
    B, S, G, W, vec = scratch(M.shape[1], A.shape[1])
    nmu = mu_in.shape[0]
    for b in range(lo, hi):
        st, r, mu, rt = solve_state(
            M[b], h[b], f[b], has_f, A[b], gam[b], mu_in[b if nmu > 1 else 0], has_mu, rtol,
            spd_rtol, sym_rtol, qdd[b], fc[b], P[b if want_pl else 0], L[b if want_pl else 0],
            want_pl, B, S, G, W, vec,
        )  # fmt: skip
        status[b] = st
        rank[b] = r
        mu_out[b] = mu
        ratio[b] = rt


@njit(cache=True)
def solve_batch_serial(M, h, f, has_f, A, gam, mu_in, has_mu, rtol, spd_rtol, sym_rtol,
                       qdd, fc, P, L, want_pl, status, rank, mu_out, ratio):  # fmt: skip
    """Batch of states (leading axis), one after the other."""
    _run_range(0, M.shape[0], M, h, f, has_f, A, gam, mu_in, has_mu, rtol, spd_rtol, sym_rtol,
               qdd, fc, P, L, want_pl, status, rank, mu_out, ratio)  # fmt: skip


@njit(cache=True, parallel=True)
def solve_batch_parallel(M, h, f, has_f, A, gam, mu_in, has_mu, rtol, spd_rtol, sym_rtol,
                         qdd, fc, P, L, want_pl, status, rank, mu_out, ratio, nchunks):  # fmt: skip
    """Batch of states split into ``nchunks`` contiguous chunks evaluated in parallel threads."""
    N = M.shape[0]
    for c in prange(nchunks):
        lo = (c * N) // nchunks
        hi = ((c + 1) * N) // nchunks
        _run_range(lo, hi, M, h, f, has_f, A, gam, mu_in, has_mu, rtol, spd_rtol, sym_rtol,
                   qdd, fc, P, L, want_pl, status, rank, mu_out, ratio)  # fmt: skip


def num_threads() -> int:
    """Number of threads numba's parallel drivers use."""
    return int(numba.get_num_threads())
