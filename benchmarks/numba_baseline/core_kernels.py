"""Numba-compiled kernels of the projection dynamics (imported lazily by :mod:`._fast`).

One routine, :func:`solve_range`, does the whole evaluation of
:func:`nonmin.core.solve_dynamics` for the states ``lo … hi−1`` of batch arrays, one state after
the other in one set of scratch arrays (:func:`scratch`, allocated once per call); it indexes
the batch arrays directly, so there are no per-state array views (their reference counting cost
~0.2 µs per state). It is inlined (numba ``inline="always"``) into the single-call driver
:func:`solve_one` (arrays reshaped to a batch of one) and the batched drivers
:func:`solve_batch_serial` / :func:`solve_batch_parallel`, so a state gives bitwise the same
result whichever driver evaluates it (strict IEEE arithmetic, no fast-math).

Per state (``n`` coordinates, ``m`` constraint rows):

1. input checks: every entry finite (per-column sums of ``x·0``, which are 0 iff all entries
   are finite), ``max|M − Mᵀ| ≤ SYMMETRY_RTOL · max|M|`` (exactly the
   decision of :func:`nonmin._validation.symmetric`); a failure returns a status code and the
   caller re-runs the NumPy path, which raises the typed error (a caller that has validated a
   constant M once, or holds A's row pattern, says so with ``known``: those checks and scans
   are skipped, the results bitwise unchanged);
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
5. Cholesky of ``M̄`` (right-looking, element-wise trailing updates) with the SPD test of
   :func:`nonmin.core.linalg.cholesky` (fail if a pivot ``≤ 0``, or if a pivot
   ``L_ii² ≤ SPD_RTOL · max M̄_jj``);
6. ``w = −(DA)⁺ D γ``, ``rhs = P(g − Mw) + μw`` with ``g = h + f``, ``qdd = M̄⁻¹ rhs``,
   ``f_c = M qdd − g``.

Null-space form (certified full rank with few degrees of freedom, ``k = n − r ≤ r``): the LQ
factorization also gives an orthonormal basis ``Z`` (k × n) of N(A). In the basis ``[Q; Z]``,
``M̄ = diag(μ I, S)`` with ``S = Z M Zᵀ`` (k × k), so steps 4–6 become: ``μ = tr S / k``, the
Cholesky factor of ``S`` (same SPD test, pivots of ``S`` against ``max M̄_jj``) and
``qdd = w + Zᵀ S⁻¹ Z (g − M w)`` — O(k n² + k³) instead of the n × n M̄ and its O(n³)
factorization (formed only when ``P`` and ``L`` are asked for).

The certified LQ exploits the sparsity of A (constraint Jacobians in absolute coordinates: a
planar pin row has 3 nonzeros): every product with a Householder reflector runs over the
reflector's nonzero columns only, and zero entries of L are skipped in L⁻¹. Only exact zero
terms are skipped, so the results are those of the dense loops.

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
NO_FACTOR = 6  # solve_again without a reusable factorization (5 is the simulation loop's)

#: Bits of the ``known`` argument of :func:`solve_work` and :func:`solve_near`: what the caller
#: has established, so the kernel skips the corresponding checks and scans (a simulation loop
#: with a constant M validated once and the static row pattern of its A).
#: M is finite and symmetric within ``sym_rtol`` (input checks of step 1 skipped for M).
KNOWN_M_VALID = 1
#: M is diagonal (only with :data:`KNOWN_M_VALID`; otherwise M is treated as full).
KNOWN_M_DIAGONAL = 2
#: ``work[30]`` holds a superset of A's row pattern (many-row path only: :func:`_pattern` is
#: not called; the extra columns are zero entries, which every sum skips by value, so the
#: results are bitwise those of the scanned pattern).
KNOWN_PATTERN = 4

#: Maximum number of Jacobi sweeps (convergence is quadratic; m ≤ 30 needs < 10).
MAX_SWEEPS = 60

_NO_T = np.zeros((1, 1))
_EPS = float(np.finfo(np.float64).eps)
_TINY = float(np.finfo(np.float64).tiny)


#: Row norms whose sum of squares leaves [_NORM_SMALL, _NORM_BIG] are recomputed on the row
#: divided by its largest entry (no overflow above ~1e154, no underflow below ~1e-154); inside
#: that range the plain sum is kept, bitwise as before (the NumPy spec: core.linalg.row_norms).
_NORM_BIG = 1e300
_NORM_SMALL = 1e-290

@njit(cache=True, inline="always")
def _cut(buf, o, r, c):  # type: ignore[no-untyped-def]
    """The r × c view of ``buf`` at offset ``o`` and the offset after it."""
    return buf[o : o + r * c].reshape((r, c)), o + r * c


@njit(cache=True)
def scratch(n, m):
    """Scratch arrays of :func:`solve_range` for ``n`` coordinates and ``m`` rows.

    Everything a state needs is here, including the warm-start buffers and the status/μ slots of
    :func:`solve_work` and what :func:`solve_again` reuses, so a loop that owns one set
    allocates nothing per call. The float arrays are views of one buffer (two allocations in
    all: a single call that builds its scratch pays ~0.1 µs per allocation).
    """
    n1 = n + 1
    buf = np.empty(2 * m * n1 + 5 * m * n + 3 * m * m + n * n + 5 * n + 3 * m + 9)
    B, o = _cut(buf, 0, m, n1)
    V, o = _cut(buf, o, m, n)
    Kt, o = _cut(buf, o, m, n)
    Tt, o = _cut(buf, o, m, n)
    Et, o = _cut(buf, o, m, n)
    Ft, o = _cut(buf, o, m, n)
    G, o = _cut(buf, o, m, m)
    W, o = _cut(buf, o, n, n)
    Bw, o = _cut(buf, o, m, n1)
    Tn, o = _cut(buf, o, m, m)
    Li, o = _cut(buf, o, m, m)
    vn = buf[o : o + 5 * n].reshape((5, n))  # cw, g, wv, u, dinv
    vm = buf[o + 5 * n : o + 5 * n + 3 * m].reshape((3, m))  # sig, cv, dsc
    # μ, info (8): the factorization held — [0] valid, [1] null-space form, [2] rank,
    # [3] diagonal M, [4] μ, [5] certified LQ, [6] μ and [7] validity of solve_near's last result
    tail = buf[o + 5 * n + 3 * m :]
    cw, g, wv, u, dinv = vn[0], vn[1], vn[2], vn[3], vn[4]
    sig, cv, dsc = vm[0], vm[1], vm[2]
    mu1, info = tail[:1], tail[1:]
    for i in range(8):
        info[i] = 0.0  # no factorization held yet
    # status/rank slots; Hx, Lf, Ro, Pc and Lr of _lq_certified
    o = 2 + m * (n + 1)
    ints = np.empty(o + 2 * m + 2 * n, dtype=np.int64)
    Hx = ints[2:o].reshape((m, n + 1))
    Lf = ints[o : o + m]
    Ro = ints[o + m : o + 2 * m]
    Pc = ints[o + 2 * m : o + 2 * m + n]
    Lr = ints[o + 2 * m + n :]
    # _lq_sparse's zero-initialized work matrix, row column lists and marks (many rows only)
    # and the row patterns of A (Ap: of the last factorization, whose B is zero elsewhere;
    # An: solve_near's), all for many rows only (see _sparse_rows)
    ms = m if _sparse_rows(m) else 0
    Wz = np.zeros((ms, n))
    Rl = np.empty((ms, n + 1), dtype=np.int64)
    In = np.zeros((ms, n), dtype=np.uint8)
    Ap = np.zeros((ms, n + 1), dtype=np.int64)
    An = np.zeros((ms, n + 1), dtype=np.int64)
    if ms > 0:
        for i in range(m):
            for j in range(n1):
                B[i, j] = 0.0
    return (B, V, Kt, Tt, Et, Ft, G, W, cw, g, wv, u, sig, cv, dinv, Bw, Tn, ints[:2], mu1, Li,
            dsc, info, Hx, Lf, Ro, Pc, Lr, Wz, Rl, In, Ap, An)  # fmt: skip


#: Safety factor of the certified-QR rank decision (see :func:`_lq_certified`) for small
#: tolerances, where the computed ‖L⁻¹‖_F carries relative errors up to ~eps·cond ≈ 1e-6.
QR_MARGIN = 10.0

#: Tolerances above this use no safety factor: eps·cond ≤ eps/rtol ≈ 1e-10 there, far below
#: the bound's own slack (‖L‖_F ‖L⁻¹‖_F overestimates cond(D A) by 2–5× on the library
#: mechanisms). The projection's first Gauss–Newton steps cut at rtol = 1e-2
#: (:data:`nonmin.sim.POSITION_CUT_RTOL`): with the factor 10 they could never be certified
#: (‖L‖_F ‖L⁻¹‖_F ≥ m) and always took the Jacobi SVD.
QR_MARGIN_RTOL = 1e-6

#: Results of :func:`_lq_certified`: not certified; certified with the dense ``L⁻¹`` in the
#: scratch; certified with ``L`` and its row profile (:func:`_certify_profile`).
LQ_NONE = 0
LQ_INVERSE = 1
LQ_PROFILE = 2

#: Up to this many rows the certificate is ``‖L‖_F ‖L⁻¹‖_F`` with the dense ``L⁻¹`` (cheap and
#: sharp enough there); above, :func:`_certify_profile`.
DENSE_INVERSE_MAX_ROWS = 32

#: :func:`_certify_profile` certifies ``σ_min > CERT_SLACK · max(rtol, CERT_FLOOR) · ‖T‖∞^½``:
#: the floor keeps the shift τ ≥ 1e-10 ‖T‖∞, far above the round-off of T and its Cholesky
#: factorization (~m eps ‖T‖), and the slack absorbs what is left of it. Below the floor
#: (σ_min/σ_max < 1e-5, within ~1e-5 of a singular configuration) the SVD decides.
CERT_FLOOR = 1e-5
CERT_SLACK = 1.01

#: Above this many rows a state the certified LQ does not settle takes LAPACK's SVD
#: (:func:`_svd_lapack`) instead of the Jacobi sweeps (measured at m = 242: 12 ms against
#: 460 ms).
JACOBI_MAX_ROWS = 32

#: The certified LQ is tried from this many rows on; with fewer, the Jacobi SVD is as cheap
#: (a pair or three of rows converge in 2–3 sweeps) and a failed certification is pure cost.
QR_MIN_ROWS = 4


@njit(cache=True, inline="always")
def _sparse_rows(m):  # type: ignore[no-untyped-def]
    """Many rows (a large mechanism): A is handled through its row patterns (:func:`_pattern`),
    the LQ by :func:`_lq_sparse`, an uncertified state by LAPACK's SVD (never the Jacobi sweeps,
    which rotate ``B`` in place)."""
    return m > DENSE_INVERSE_MAX_ROWS and m > JACOBI_MAX_ROWS


@njit(cache=True, inline="always")
def _pattern(X, m, n, P):  # type: ignore[no-untyped-def]
    """``P[i] = [count, k …]``: the columns of row i of ``X`` (m × n) with a nonzero entry
    (a NaN counts), in increasing order."""
    for i in range(m):
        c = 0
        for k in range(n):
            if X[i, k] != 0.0:
                P[i, 1 + c] = k
                c += 1
        P[i, 0] = c


@njit(cache=True, inline="always")
def _pattern_norm(X, i, n, P):  # type: ignore[no-untyped-def]
    """:func:`_row_norm` over row i's pattern ``P[i]`` (the same partial sums, bitwise)."""
    n4 = n - n % 4
    s0 = 0.0
    s1 = 0.0
    s2 = 0.0
    s3 = 0.0
    for t in range(P[i, 0]):
        k = P[i, 1 + t]
        x = X[i, k]
        if k >= n4:
            s0 += x * x
        else:
            r = k % 4
            if r == 0:
                s0 += x * x
            elif r == 1:
                s1 += x * x
            elif r == 2:
                s2 += x * x
            else:
                s3 += x * x
    s = (s0 + s1) + (s2 + s3)
    if s > _NORM_BIG or s < _NORM_SMALL:  # overflowed or underflowed squares: rescale
        scale = 0.0
        for t in range(P[i, 0]):
            scale = max(scale, abs(X[i, P[i, 1 + t]]))
        if not scale > 0.0:
            return math.sqrt(s) if scale == 0.0 else scale
        s = 0.0
        for t in range(P[i, 0]):
            x = X[i, P[i, 1 + t]] / scale
            s += x * x
        return scale * math.sqrt(s)
    return math.sqrt(s)


@njit(cache=True, inline="always")
def _pattern_dot(X, i, P, v, s):  # type: ignore[no-untyped-def]
    """``s + X[i] · v`` over row i's pattern (the terms of the dense sum that are not zero)."""
    for t in range(P[i, 0]):
        k = P[i, 1 + t]
        s += X[i, k] * v[k]
    return s


@njit(cache=True)
def _lq_certified(B, m, n, rtol, Wq, Hv, Li, cv, beta, Hx, Lf, Ro, Pc, Lr, Rl, In):  # type: ignore[no-untyped-def]
    """LQ factorization ``D A = L Q`` of ``B[:, :n]`` (m ≤ n, every row nonzero), if full rank
    is certain.

    Householder reflections from the right (row-oriented: contiguous rows); ``Wq`` (m, n) and
    ``Hv`` (m, n, the reflectors) are scratch. Certification: ``σ_max ≤ ‖L‖_F`` and
    ``σ_min ≥ 1/‖L⁻¹‖_F`` bound the condition number of ``D A``; if
    ``‖L‖_F ‖L⁻¹‖_F · QR_MARGIN · rtol < 1`` (factor 1 for ``rtol > QR_MARGIN_RTOL``) every
    singular value is above ``rtol · σ_max`` and
    the SVD's rule would keep all m rows. Then writes ``cv = L⁻¹ D γ`` (``D γ = B[:, n]``), so
    ``(D A)⁺ D γ = Qᵀ cv``, keeps the reflectors in ``Hv``/``beta`` (:func:`_lq_rows`,
    :func:`_lq_min_norm`) and returns :data:`LQ_INVERSE`. Returns :data:`LQ_NONE` when the
    bound fails. This is the variant for few rows (at most :data:`DENSE_INVERSE_MAX_ROWS`):
    rows in their order, the pivot of reflector j is column j (``Ro`` and ``Pc`` the
    identity); many rows take :func:`_lq_sparse`.

    Sparsity: constraint Jacobians in absolute coordinates are sparse (a planar pin row has
    3 nonzeros of ``n``), and so are the first reflectors. ``Hx[j] = [c, k_1 … k_c]`` lists
    the columns where reflector ``j`` is nonzero (``k_1`` is its pivot column, onto which it
    maps row j); every product with it runs over those only, and only over the rows that can
    be nonzero there (``Lr[k]``: the last row that may have a nonzero in column k). The sums
    skip exact zero terms only, so the results are those of the dense loops (up to the sign
    of a zero). ``Rl`` and ``In`` are :func:`_lq_sparse`'s (not used here).
    """
    for k in range(n):
        Pc[k] = 0  # 1 once pivoted
        Lr[k] = -1
    for i in range(m):
        Ro[i] = i
        for k in range(n):
            x = B[i, k]
            Wq[i, k] = x
            if x != 0.0:
                Lr[k] = i
    for j in range(m):
        p = j
        x0 = Wq[j, p]
        s = x0 * x0
        Hv[j, p] = x0
        Hx[j, 1] = p
        Pc[p] = 1
        cnt = 1
        imax = Lr[p]
        for k in range(p + 1, n):
            if Pc[k] != 0:
                continue
            x = Wq[j, k]
            Hv[j, k] = x
            if x != 0.0:
                s += x * x
                Hx[j, 1 + cnt] = k
                cnt += 1
                if Lr[k] > imax:
                    imax = Lr[k]
        Hx[j, 0] = cnt
        if not _reflect(Wq, Hv, Hx, beta, Lr, j, p, x0, s, imax, Rl, In, False):
            return LQ_NONE
    _pivot_order(Hx, Lr, Pc, m, n)
    fl = 0.0
    for i in range(m):
        for k in range(i + 1):
            fl += Wq[i, k] * Wq[i, k]
    for i in range(m):  # reciprocal pivots (cv is scratch until the end)
        cv[i] = 1.0 / Wq[i, i]
    # L⁻¹ (lower triangle of Li) row by row: row i = (e_i − Σ_{k<i} L_ik · row k) / L_ii, the
    # updates element-wise along the row (independent: no chain of dependent operations). Each
    # entry's sum runs over k in increasing order, as in a column-by-column forward substitution.
    f0 = 0.0
    f1 = 0.0
    for i in range(m):
        for c in range(i):
            Li[i, c] = 0.0
        Li[i, i] = 1.0
        for k in range(i):
            a = Wq[i, k]
            if a != 0.0:  # (L is sparse too)
                for c in range(k + 1):
                    Li[i, c] -= a * Li[k, c]
        r = cv[i]
        for c in range(i + 1):
            Li[i, c] *= r
        i2 = (i + 1) - (i + 1) % 2  # ‖L⁻¹‖_F²: two interleaved partial sums
        for c in range(0, i2, 2):
            f0 += Li[i, c] * Li[i, c]
            f1 += Li[i, c + 1] * Li[i, c + 1]
        if i2 <= i:
            f0 += Li[i, i] * Li[i, i]
    fi = f0 + f1
    margin = QR_MARGIN if rtol <= QR_MARGIN_RTOL else 1.0
    if not (math.sqrt(fl) * math.sqrt(fi) * margin * rtol < 1.0):
        return LQ_NONE
    _apply_linv(LQ_INVERSE, Li, Lf, Ro, m, B[:, n], cv)
    return LQ_INVERSE


@njit(cache=True, inline="always")
def _reflect_row(X, i, Hv, Hx, j, bj):  # type: ignore[no-untyped-def]
    """Row i of ``X`` times reflector j (``I − β_j v vᵀ``, ``v = Hv[j]`` over its columns
    ``Hx[j]``); returns whether the row changed (its product with ``v`` was not zero)."""
    cnt = Hx[j, 0]
    d = 0.0
    for t in range(1, cnt + 1):
        k = Hx[j, t]
        d += X[i, k] * Hv[j, k]
    if d == 0.0:
        return False
    d *= bj
    for t in range(1, cnt + 1):
        k = Hx[j, t]
        X[i, k] -= d * Hv[j, k]
    return True


@njit(cache=True, inline="always")
def _pivot_order(Hx, Lr, Pc, m, n):  # type: ignore[no-untyped-def]
    """``Pc``: the reflectors' pivot columns ``Hx[:, 1]`` in order, then the other columns
    (``Lr`` is scratch: -2 marks a pivot column)."""
    for i in range(m):
        Pc[i] = Hx[i, 1]
        Lr[Hx[i, 1]] = -2
    c = m
    for k in range(n):
        if Lr[k] != -2:
            Pc[c] = k
            c += 1


@njit(cache=True, inline="always")
def _reflect(Wq, Hv, Hx, beta, Lr, j, p, x0, s, imax, Rl, In, track):  # type: ignore[no-untyped-def]
    """Finish reflector ``j`` of the LQ factorization and apply it to rows ``j+1 … imax``.

    On entry ``Hv[j]`` holds row j's entries at the reflector's columns ``Hx[j, 1 … c]``
    (pivot ``p = Hx[j, 1]`` first, ``x0`` its entry, ``s`` the sum of their squares in the
    order of ``Hx``) and ``imax`` is the last row that may be nonzero there. Writes
    ``Hv[j, p] = x0 − α``, ``β_j``, row j's ``α`` at the pivot and zeros at the other columns,
    and updates the rows below (``Lr``: those rows may now be nonzero in all its columns).
    With ``track`` every updated row's column list ``Rl[i] = [count, k …]`` (``In[i, k]`` its
    membership marks) gains the reflector's columns (see :func:`_lq_sparse`). Returns False for
    an all-zero row.
    """
    cnt = Hx[j, 0]
    if s == 0.0:
        return False
    nrm = math.sqrt(s)
    alpha = -nrm if x0 >= 0.0 else nrm
    v0 = x0 - alpha
    Hv[j, p] = v0
    bj = 2.0 / (s - x0 * x0 + v0 * v0)
    beta[j] = bj
    Wq[j, p] = alpha
    for t in range(2, cnt + 1):
        Wq[j, Hx[j, t]] = 0.0
    # rows below that can be nonzero in the reflector's columns: four at a time, so four
    # independent dot products are in flight (each still one sequential sum over k, so the
    # result is that of a row-by-row loop)
    i = j + 1
    while i + 3 <= imax:
        d0 = 0.0
        d1 = 0.0
        d2 = 0.0
        d3 = 0.0
        for t in range(1, cnt + 1):
            k = Hx[j, t]
            hk = Hv[j, k]
            d0 += Wq[i, k] * hk
            d1 += Wq[i + 1, k] * hk
            d2 += Wq[i + 2, k] * hk
            d3 += Wq[i + 3, k] * hk
        if d0 != 0.0 or d1 != 0.0 or d2 != 0.0 or d3 != 0.0:
            d0 *= bj
            d1 *= bj
            d2 *= bj
            d3 *= bj
            for t in range(1, cnt + 1):
                k = Hx[j, t]
                hk = Hv[j, k]
                Wq[i, k] -= d0 * hk
                Wq[i + 1, k] -= d1 * hk
                Wq[i + 2, k] -= d2 * hk
                Wq[i + 3, k] -= d3 * hk
            if track:  # (a row with d = 0 is unchanged: its zeros stay zeros)
                if d0 != 0.0:
                    _merge_columns(Rl, In, i, Hx, j, cnt)
                if d1 != 0.0:
                    _merge_columns(Rl, In, i + 1, Hx, j, cnt)
                if d2 != 0.0:
                    _merge_columns(Rl, In, i + 2, Hx, j, cnt)
                if d3 != 0.0:
                    _merge_columns(Rl, In, i + 3, Hx, j, cnt)
        i += 4
    while i <= imax:
        if _reflect_row(Wq, i, Hv, Hx, j, bj) and track:
            _merge_columns(Rl, In, i, Hx, j, cnt)
        i += 1
    for t in range(1, cnt + 1):  # those rows may now be nonzero in all its columns
        k = Hx[j, t]
        if imax > Lr[k]:
            Lr[k] = imax
    return True


@njit(cache=True, inline="always")
def _merge_columns(Rl, In, i, Hx, j, cnt):  # type: ignore[no-untyped-def]
    """Add reflector ``j``'s columns ``Hx[j, 1 … cnt]`` to row ``i``'s column list."""
    for t in range(1, cnt + 1):
        k = Hx[j, t]
        if In[i, k] == 0:
            In[i, k] = 1
            c = Rl[i, 0]
            Rl[i, 1 + c] = k
            Rl[i, 0] = c + 1


@njit(cache=True)
def _lq_sparse(B, m, n, rtol, Wz, Hv, Li, cv, beta, Hx, G, Lf, Ro, Pc, Lr, Rl, In, Ap):  # type: ignore[no-untyped-def]
    """:func:`_lq_certified` for many rows (more than :data:`DENSE_INVERSE_MAX_ROWS`), in time
    proportional to the nonzeros; certificate :func:`_certify_profile` (:data:`LQ_PROFILE`).

    A large mechanism's Jacobian is sparse and the dense row order would fill L and the
    reflectors (A02 N = 40 has a profile of 121 columns in the builder's order). So the rows
    are taken in the order of their first nonzero column (``Ro``, a stable sort), and the
    pivot of reflector j is the first column of row j not pivoted yet with a nonzero entry:
    the reflectors then stay within the bodies a constraint couples. ``Pc`` lists the pivot
    columns, then the others (row ``i`` of ``H_{m−1} ⋯ H_0`` is ``e_{Pc[i]}ᵀ H_{m−1} ⋯ H_0``);
    L is in that order.

    Nothing here is dense: ``B`` is read over the pattern ``Ap`` of A (``B = D A`` is zero
    elsewhere), and row i of the work matrix ``Wz`` (all zero
    on entry and on return: only listed entries are written, and cleared at the end) keeps
    the list of columns where it may be nonzero, ``Rl[i] = [count, k …]`` with membership
    marks ``In`` (zero on entry and return too); a reflector's update adds its columns to
    the list of each row it changes. Every sum runs over the same nonzero terms in the same
    order as the dense loops of the rows-in-order variant, so the factors are those of the
    dense factorization with this row order and these pivots (up to the sign of a zero).
    """
    for i in range(m):  # rows by their first nonzero column (a stable sort)
        f = n - 1
        for t in range(Ap[i, 0]):
            k = Ap[i, 1 + t]
            if B[i, k] != 0.0:
                f = k
                break
        cv[i] = f * float(m) + i
    order = np.argsort(cv[:m])
    for k in range(n):
        Pc[k] = 0  # 1 once pivoted
        Lr[k] = -1
    for i in range(m):  # the rows in that order, with their column lists
        src = order[i]
        Ro[i] = src
        c = 0
        for t in range(Ap[src, 0]):
            k = Ap[src, 1 + t]
            x = B[src, k]
            if x != 0.0:
                Wz[i, k] = x
                In[i, k] = 1
                Rl[i, 1 + c] = k
                c += 1
                Lr[k] = i
        Rl[i, 0] = c
    res = LQ_NONE
    ok = True
    for j in range(m):
        c = Rl[j, 0]
        p = -1
        for t in range(c):  # the pivot: first unpivoted nonzero column
            k = Rl[j, 1 + t]
            if Pc[k] == 0 and Wz[j, k] != 0.0 and (p < 0 or k < p):
                p = k
        if p < 0:
            ok = False
            break
        x0 = Wz[j, p]
        Hv[j, p] = x0
        Hx[j, 1] = p
        Pc[p] = 1
        cnt = 1
        for t in range(c):  # the other unpivoted nonzero columns, in increasing order
            k = Rl[j, 1 + t]
            if Pc[k] == 0:
                x = Wz[j, k]
                if x != 0.0:
                    Hv[j, k] = x
                    a = 1 + cnt
                    while a > 2 and Hx[j, a - 1] > k:
                        Hx[j, a] = Hx[j, a - 1]
                        a -= 1
                    Hx[j, a] = k
                    cnt += 1
        s = x0 * x0
        imax = Lr[p]
        for t in range(2, cnt + 1):
            k = Hx[j, t]
            x = Hv[j, k]
            s += x * x
            if Lr[k] > imax:
                imax = Lr[k]
        Hx[j, 0] = cnt
        if not _reflect(Wz, Hv, Hx, beta, Lr, j, p, x0, s, imax, Rl, In, True):
            ok = False
            break
    if ok:
        _pivot_order(Hx, Lr, Pc, m, n)
        for c in range(n):  # Lr: a column's position in that order
            Lr[Pc[c]] = c
        for i in range(m):  # L's row profile: its first nonzero column (L in the order Pc)
            f = i
            for t in range(Rl[i, 0]):
                k = Rl[i, 1 + t]
                if Lr[k] < f and Wz[i, k] != 0.0:
                    f = Lr[k]
            Lf[i] = f
        res = _certify_profile(B, m, n, rtol, Wz, Li, cv, G, Lf, Ro, Pc)
    for i in range(m):  # Wz and In back to zero
        for t in range(Rl[i, 0]):
            k = Rl[i, 1 + t]
            Wz[i, k] = 0.0
            In[i, k] = 0
    return res


@njit(cache=True)
def _certify_profile(B, m, n, rtol, Wq, Li, cv, G, Lf, Ro, Pc):  # type: ignore[no-untyped-def]
    """The certification of :func:`_lq_sparse` (many rows), in O(m b²) (b: L's bandwidth).

    ``‖L‖_F ‖L⁻¹‖_F ≥ m`` cannot certify a cutoff ``rtol ≥ 1/m`` (the projection's 1e-2 with
    over 100 rows), and the dense ``L⁻¹`` costs O(m³). Instead: ``T = L Lᵀ = (D A)(D A)ᵀ`` has
    the eigenvalues ``σ_i²`` and at most ``‖T‖∞ ≥ σ_max²``; a Cholesky factorization of
    ``T − τ I`` with ``τ = (CERT_SLACK · max(rtol, CERT_FLOOR))² ‖T‖∞`` succeeds iff every
    ``σ_i² > τ`` (to round-off ~m·eps·‖T‖, which the floor keeps ≥ 1e3 times below τ), so every
    σ_i is above ``rtol · σ_max`` and the SVD's rule would keep all m rows. L keeps the row
    profile of ``D A`` (a constraint row touches a few bodies), and ``T`` and its factor keep
    L's, so both are formed over the profile only: row i of L starts at column ``Lf[i]``
    (given; ``Wq`` holds L's rows in the columns' own order).

    On success ``Li`` holds ``L`` itself (rows in the order ``Ro``, columns in the pivot order
    ``Pc``; lower triangle over the profile, the rest is not read), ``cv = L⁻¹ (D γ)[Ro]`` by
    forward substitution, and it returns :data:`LQ_PROFILE`; else
    :data:`LQ_NONE`. Scratch: ``G`` (m × m, the factor of ``T − τI``), ``cv``.
    """
    for i in range(m):  # L (in the pivot order Pc) over its row profile
        for c in range(Lf[i], i + 1):
            Li[i, c] = Wq[i, Pc[c]]
    for i in range(m):  # T = L Lᵀ over the profile: T_ij = 0 for j < Lf[i]
        cv[i] = 0.0
    for i in range(m):
        fi = Lf[i]
        for j in range(fi, i + 1):
            s = 0.0
            for k in range(max(fi, Lf[j]), j + 1):
                s += Li[i, k] * Li[j, k]
            G[i, j] = s
            a = abs(s)
            cv[i] += a  # |T| row sums (T symmetric: row i's entries left and below the diagonal)
            if j < i:
                cv[j] += a
    tnorm = 0.0
    for i in range(m):
        tnorm = max(tnorm, cv[i])
    rt = CERT_SLACK * max(rtol, CERT_FLOOR)
    tau = rt * rt * tnorm
    for i in range(m):  # Cholesky of T − τI, row by row over the profile
        fi = Lf[i]
        for j in range(fi, i):
            s = G[i, j]
            for k in range(max(fi, Lf[j]), j):
                s -= G[i, k] * G[j, k]
            G[i, j] = s / G[j, j]
        s = G[i, i] - tau
        for k in range(fi, i):
            s -= G[i, k] * G[i, k]
        if not s > 0.0:
            return LQ_NONE
        G[i, i] = math.sqrt(s)
    _apply_linv(LQ_PROFILE, Li, Lf, Ro, m, B[:, n], cv)
    return LQ_PROFILE


@njit(cache=True)
def _svd_lapack(B, m, n, rtol, V, Kt, Li, cv):  # type: ignore[no-untyped-def]
    """Step 3 for many rows: LAPACK's SVD of ``D A = U Σ Vᵀ`` (``B[:, :n]``) instead of the
    Jacobi sweeps, with the same rank rule (keep ``σ_i > rtol · σ_max``).

    Writes the kept right singular vectors into the rows of ``V``, ``cv_k = (u_kᵀ D γ)/σ_k``,
    the rows ``u_kᵀ/σ_k`` of ``Σ⁻¹Uᵀ`` into ``Li`` (for :func:`solve_again`) and, when the
    null-space form applies (``n − r ≤ r``), the other right singular vectors (an orthonormal
    basis of N(D A) at that rank) into the rows of ``Kt``. Returns ``(r, null-space form)``.
    """
    U, s, Vt = np.linalg.svd(B[:, :n])  # (numba copies it for LAPACK); full: Vt is n × n
    p = s.shape[0]
    smax = s[0] if p > 0 else 0.0
    r = 0
    for a in range(p):
        if s[a] > rtol * smax:
            r += 1
    for a in range(r):
        inv = 1.0 / s[a]
        for k in range(n):
            V[a, k] = Vt[a, k]
        t = 0.0
        for c in range(m):
            t += U[c, a] * B[c, n]
        cv[a] = t * inv
        for c in range(m):
            Li[a, c] = U[c, a] * inv
    zmode = n - r <= r
    if zmode:
        for a in range(n - r):
            for k in range(n):
                Kt[a, k] = Vt[r + a, k]
    return r, zmode


@njit(cache=True, inline="always")
def _profile_solve(Lp, Lf, m, cv):  # type: ignore[no-untyped-def]
    """``cv ← L⁻¹ cv`` by forward substitution over L's row profile (``Lp`` holds L, row i from
    column ``Lf[i]``)."""
    for i in range(m):
        s = cv[i]
        for k in range(Lf[i], i):
            s -= Lp[i, k] * cv[k]
        cv[i] = s / Lp[i, i]


@njit(cache=True, inline="always")
def _apply_linv(mode, Li, Lf, Ro, m, y, cv):  # type: ignore[no-untyped-def]
    """``cv = L⁻¹ y`` with the certified LQ's factor (``y`` of length m in A's row order):
    :data:`LQ_INVERSE` — ``Li`` holds ``L⁻¹`` (rows in their order); :data:`LQ_PROFILE` —
    ``Li`` holds ``L`` over its row profile (rows in the order ``Ro``, :func:`_profile_solve`)."""
    if mode == LQ_PROFILE:
        for i in range(m):
            cv[i] = y[Ro[i]]
        _profile_solve(Li, Lf, m, cv)
    else:
        for i in range(m):
            s = 0.0
            for k in range(i + 1):
                s += Li[i, k] * y[k]
            cv[i] = s


@njit(cache=True)
def _lq_rows(Hv, beta, m, n, first, count, E, Hx, Pc):  # type: ignore[no-untyped-def]
    """Rows ``first … first+count−1`` of the orthogonal ``H_{m−1} ⋯ H_0`` into ``E[:count]``.

    Rows ``0 … m−1`` are ``Q`` (an orthonormal basis of R(Aᵀ)), rows ``m … n−1`` an orthonormal
    basis ``Z`` of N(A) (the reflectors are symmetric: ``E ← E H_j`` for j = m−1 … 0).
    Products with reflector ``j`` run over its nonzero columns ``Hx[j]`` (see
    :func:`_lq_certified`).
    """
    for i in range(count):
        for k in range(n):
            E[i, k] = 0.0
        E[i, Pc[first + i]] = 1.0
    for j in range(m - 1, -1, -1):
        for i in range(count):
            _reflect_row(E, i, Hv, Hx, j, beta[j])


@njit(cache=True)
def _lq_min_norm(Hv, beta, m, n, cv, w, Hx, Pc):  # type: ignore[no-untyped-def]
    """``w = −Qᵀ cv = −H_0 ⋯ H_{m−1} [cv; 0]`` (= ``−(DA)⁺ D γ`` with ``cv = L⁻¹ D γ``);
    reflector ``j`` over its nonzero columns ``Hx[j]``."""
    for i in range(n):
        w[i] = 0.0
    for i in range(m):
        w[Pc[i]] = cv[i]
    for j in range(m - 1, -1, -1):
        cnt = Hx[j, 0]
        d = 0.0
        for t in range(1, cnt + 1):
            k = Hx[j, t]
            d += Hv[j, k] * w[k]
        d *= beta[j]
        for t in range(1, cnt + 1):
            k = Hx[j, t]
            w[k] -= d * Hv[j, k]
    for i in range(n):
        w[i] = -w[i]


@njit(cache=True, inline="always")
def _row_norm(X, i, n):  # type: ignore[no-untyped-def]
    """‖X[i, :n]‖₂ with four interleaved partial sums in a fixed order."""
    n4 = n - n % 4
    s0 = 0.0
    s1 = 0.0
    s2 = 0.0
    s3 = 0.0
    for k in range(0, n4, 4):
        s0 += X[i, k] * X[i, k]
        s1 += X[i, k + 1] * X[i, k + 1]
        s2 += X[i, k + 2] * X[i, k + 2]
        s3 += X[i, k + 3] * X[i, k + 3]
    for k in range(n4, n):
        s0 += X[i, k] * X[i, k]
    s = (s0 + s1) + (s2 + s3)
    if s > _NORM_BIG or s < _NORM_SMALL:  # overflowed or underflowed squares: rescale
        scale = 0.0
        for k in range(n):
            scale = max(scale, abs(X[i, k]))
        if not scale > 0.0:
            return math.sqrt(s) if scale == 0.0 else scale
        s = 0.0
        for k in range(n):
            x = X[i, k] / scale
            s += x * x
        return scale * math.sqrt(s)
    return math.sqrt(s)


@njit(cache=True, inline="always")
def _add_m_times(M, b, diag, x, sign, out):  # type: ignore[no-untyped-def]
    """``out += sign · M[b] x`` (M symmetric: element-wise column updates; diagonal M without
    the zero terms)."""
    n = x.shape[0]
    if diag:
        for i in range(n):
            out[i] += sign * (M[b, i, i] * x[i])
        return
    for j in range(n):
        c = sign * x[j]
        for i in range(n):
            out[i] += M[b, j, i] * c


@njit(cache=True, inline="always")
def _null_space_qdd(Z, Ls, k, u, w, cv, out):  # type: ignore[no-untyped-def]
    """``out = w + Zᵀ S⁻¹ Z u`` with ``S = Ls Lsᵀ`` (k × k, lower ``Ls``): the null-space form's
    solve (:func:`solve_range` step 6, :func:`solve_near`); ``cv`` (≥ k) is scratch."""
    n = u.shape[0]
    for a in range(k):
        s = 0.0
        for j in range(n):
            s += Z[a, j] * u[j]
        for c in range(a):  # forward substitution with Ls
            s -= Ls[a, c] * cv[c]
        cv[a] = s / Ls[a, a]
    for a in range(k - 1, -1, -1):  # back substitution with Lsᵀ
        s = cv[a]
        for c in range(a + 1, k):
            s -= Ls[c, a] * cv[c]
        cv[a] = s / Ls[a, a]
    for i in range(n):
        out[i] = w[i]
    for a in range(k):
        c = cv[a]
        for i in range(n):
            out[i] += Z[a, i] * c


@njit(cache=True, inline="always")
def _rows_times_m(X, k, M, b, diag, out):  # type: ignore[no-untyped-def]
    """``out[:k] = X[:k] M[b]`` (M symmetric; element-wise updates, which LLVM vectorizes; for a
    diagonal M the same sums without the zero terms)."""
    n = M.shape[1]
    for a in range(k):
        if diag:
            for j in range(n):
                out[a, j] = 0.0 + X[a, j] * M[b, j, j]
            continue
        for j in range(n):
            out[a, j] = 0.0
        for i in range(n):
            c = X[a, i]
            for j in range(n):
                out[a, j] += c * M[b, i, j]


@njit(cache=True)
def _mbar_from_s(Z, k, S, mu, Y, W):  # type: ignore[no-untyped-def]
    """``M̄ = μI + Zᵀ(S − μI)Z`` (lower triangle of ``W``) from the null-space basis ``Z``
    (k × n, orthonormal rows spanning N(A)) and ``S = Z M Zᵀ`` (:func:`_null_factor`); only
    for the ``L`` output of the null-space form. Scratch: ``Y`` (≥ k × n)."""
    n = Z.shape[1]
    for a in range(k):  # Y = (S − μI) Z
        for j in range(n):
            s = -mu * Z[a, j]
            for c in range(k):
                s += S[a, c] * Z[c, j]
            Y[a, j] = s
    dmax = -np.inf
    for i in range(n):
        for j in range(i + 1):
            s = mu if i == j else 0.0
            for a in range(k):
                s += Z[a, i] * Y[a, j]
            W[i, j] = s
        if W[i, i] > dmax:
            dmax = W[i, i]
    return dmax


@njit(cache=True)
def _null_factor(M, b, Z, k, diag, has_mu, mu_in, nmu, spd_rtol, ZM, S, Ls):  # type: ignore[no-untyped-def]
    """The null-space form's factorization: ``S = Z M Zᵀ`` (k × k, into ``S``), μ, and the
    Cholesky factor of ``S`` (lower triangle of ``Ls``).

    ``M̄ = μQ + ZᵀSZ`` is ``diag(μ I, S)`` in the orthonormal basis ``[Q; Z]``, so it is SPD iff
    ``S`` is, and ``M̄⁻¹ x = Q x / μ + Zᵀ S⁻¹ Z x``: the n × n M̄ is never needed (see
    :func:`solve_range`, step 6). The SPD test is the one of the n × n factorization with the
    pivots of ``S``: fail if a pivot is ``≤ 0`` or ``≤ spd_rtol · max_i M̄_ii``. Returns
    ``(status, smallest pivot ratio, μ)``. Scratch: ``ZM`` (≥ k × n).
    """
    n = M.shape[1]
    _rows_times_m(Z, k, M, b, diag, ZM)  # ZM = Z M
    trs = 0.0
    for a in range(k):
        for c in range(k):
            s = 0.0
            for j in range(n):
                s += ZM[a, j] * Z[c, j]
            S[a, c] = s
        trs += S[a, a]
    if has_mu:
        mu = mu_in[b] if nmu > 1 else mu_in[0]
    else:
        if k > 0:
            mu = trs / k
        else:  # r = n: μ = tr(M)/n, as the V form
            mu = 0.0
            for i in range(n):
                mu += M[b, i, i]
            mu /= n
        if not mu > 0.0:
            mu = 1.0
    dmax = -np.inf  # max_i M̄_ii = μ (1 − ‖Z e_i‖²) + (Zᵀ S Z)_ii
    for i in range(n):
        p = 0.0
        t = 0.0
        for a in range(k):
            za = Z[a, i]
            p += za * za
            s = 0.0
            for c in range(k):
                s += S[a, c] * Z[c, i]
            t += za * s
        d = mu * (1.0 - p) + t
        if d > dmax:
            dmax = d
    st = OK
    rt = np.inf
    for j in range(k):  # Cholesky of S (lower triangle of Ls)
        s = S[j, j]
        for c in range(j):
            s -= Ls[j, c] * Ls[j, c]
        if not s > 0.0:
            return CHOL_FAIL, rt, mu
        piv = s
        if piv <= spd_rtol * dmax:
            st = SMALL_PIVOT
            if piv / dmax < rt:
                rt = piv / dmax
        ljj = math.sqrt(s)
        Ls[j, j] = ljj
        for i in range(j + 1, k):
            s = S[i, j]
            for c in range(j):
                s -= Ls[i, c] * Ls[j, c]
            Ls[i, j] = s / ljj
    return st, rt, mu


@njit(cache=True, inline="always")
def _cholesky_lower(W, n, spd_rtol, dmax, dinv, cw):  # type: ignore[no-untyped-def]
    """In-place Cholesky factor of the lower triangle of ``W`` (n × n) with the SPD test of
    :func:`nonmin.core.linalg.cholesky` (a pivot ``≤ 0``: CHOL_FAIL; ``L_jj² ≤ spd_rtol ·
    dmax``: SMALL_PIVOT, factorization continued); reciprocal pivots into ``dinv``. Returns
    ``(status, smallest pivot ratio)``. Right-looking (outer-product) form: after column j the
    trailing rows are updated element-wise with a contiguous copy ``cw`` of the column."""
    st = OK
    rt = np.inf
    for j in range(n):
        s = W[j, j]
        if not s > 0.0:
            return CHOL_FAIL, rt
        ljj = math.sqrt(s)
        piv = ljj * ljj
        if piv <= spd_rtol * dmax:
            st = SMALL_PIVOT
            if piv / dmax < rt:
                rt = piv / dmax
        W[j, j] = ljj
        rj = 1.0 / ljj  # one division per column, as LAPACK's dpotf2
        dinv[j] = rj
        for i in range(j + 1, n):
            x = W[i, j] * rj
            W[i, j] = x
            cw[i] = x
        for i in range(j + 1, n):
            a = cw[i]
            for k in range(j + 1, i + 1):
                W[i, k] -= a * cw[k]
    return st, rt


#: No fast-math flags: strict IEEE arithmetic, so the compiled per-state routine gives bitwise the
#: same result whichever driver (single, serial batch, parallel batch) inlines it. (With
#: ``reassoc`` the vectorizer may order sums differently per call site: measured mismatches.)
#: Speed without reassociation comes from the loop forms instead: element-wise updates
#: ("axpy": every output entry has its own sequential sum, which LLVM vectorizes as is) and
#: reductions split into four interleaved partial sums in a fixed order.
_FM: set[str] = set()


@njit(cache=True, fastmath=_FM, inline="always")  # numba-level inlining: no call, no refcounts
def solve_range(lo, hi, M, h, f, has_f, A, gam, mu_in, has_mu, rtol, spd_rtol, sym_rtol,
                qdd, fc, P, L, want_pl, status, rank, mu_out, ratio, work, T, warm,
                again, known):  # fmt: skip
    """Evaluate states ``lo … hi−1`` of the batch arrays, one after the other.

    Inputs ``M`` (N, n, n), ``h``, ``f`` (N, n) (``f`` read only if ``has_f``), ``A``
    (N, m, n), ``gam`` (N, m), ``mu_in`` (N or 1; used if ``has_mu``). Outputs per state ``b``:
    ``qdd[b]``, ``fc[b]`` (only if ``fc`` is not empty: pass shape (0, n) when only q̈ is
    wanted), ``P[b]``, ``L[b]`` (only if ``want_pl``), ``status[b]`` (a status
    code), ``rank[b]``, ``mu_out[b]``, ``ratio[b]`` (smallest pivot ratio if
    :data:`SMALL_PIVOT`). The loop indexes the batch arrays directly (no per-state views, whose
    reference counting cost ~0.2 µs per state) and reuses one set of scratch arrays. See the
    module docstring for the steps. With ``again`` (single state, see :func:`solve_again`) steps
    1–5 are skipped: ``w`` comes from the factorization the last call left in ``work``.
    ``known`` (bits, see :data:`KNOWN_M_VALID`) states what the caller has established about
    every state of the range, so its checks are skipped (0: nothing, check everything).
    """
    n = M.shape[1]
    m = A.shape[1]
    nmu = mu_in.shape[0]
    (B, V, Kt, Tt, Et, Ft, G, W, cw, g, wv, u, sig, cv, dinv, Bw, Tn, _ist, _mu1, Li, dsc, info, Hx,
     Lf, Ro, Pc, Lr, Wz, Rl, In, Ap, _An) = work
    sparse = _sparse_rows(m)
    for b in range(lo, hi):
        if again:  # solve_again: the factorization left by the last call; new h, f, γ
            if info[0] == 0.0:
                status[b] = NO_FACTOR
                rank[b] = 0
                mu_out[b] = 0.0
                ratio[b] = 0.0
                continue
            zmode = info[1] != 0.0
            r = int(info[2])
            diag = info[3] != 0.0
            mu = info[4]
            for i in range(m):
                Bw[i, 0] = dsc[i] * gam[b, i]  # D γ
            if info[5] != LQ_NONE:  # certified LQ: cv = L⁻¹ D γ
                _apply_linv(int(info[5]), Li, Lf, Ro, m, Bw[:, 0], cv)
            else:  # Jacobi or LAPACK SVD: cv = Σ⁻¹Uᵀ D γ (kept rows)
                for k in range(r):
                    s = 0.0
                    for c in range(m):
                        s += Li[k, c] * Bw[c, 0]
                    cv[k] = s
            if zmode and want_pl:  # M̄ and its factor were not formed (null-space form)
                # S afresh: G may hold the S of a solve_near since (Tn: the same Ls again)
                _null_factor(M, b, Kt, n - r, diag, True, info[4:5], 1, spd_rtol, Et, G, Tn)
                info[7] = 0.0  # solve_near's S and Ls are gone
                dm = _mbar_from_s(Kt, n - r, G, mu, Tt, W)
                _cholesky_lower(W, n, 0.0, dm, dinv, cw)
            status[b] = OK
            rank[b] = r
            mu_out[b] = mu
            ratio[b] = 0.0
        else:
            # ---------------------------------------------------------------- 1. input checks
            # Finiteness: x·0 is 0 for finite x and NaN for ±inf/NaN; the per-column sums cw[j] (each
            # sequential, element-wise across j) are 0 iff every entry is finite.
            for j in range(n):
                cw[j] = h[b, j] * 0.0
            if has_f:
                for j in range(n):
                    cw[j] += f[b, j] * 0.0
            m_valid = (known & KNOWN_M_VALID) != 0
            if not m_valid:
                for i in range(n):
                    for j in range(n):
                        cw[j] += M[b, i, j] * 0.0
            if sparse:  # B back to zero (it was nonzero on the last pattern only), A's pattern
                for i in range(m):
                    for ip in range(Ap[i, 0]):
                        B[i, Ap[i, 1 + ip]] = 0.0
                if (known & KNOWN_PATTERN) == 0:  # (else the caller's, a superset: same sums)
                    _pattern(A[b], m, n, Ap)  # (A's finiteness: from its row norms, step 2)
            else:
                for i in range(m):
                    for j in range(n):
                        cw[j] += A[b, i, j] * 0.0
            bad = False
            for j in range(n):
                bad |= cw[j] != 0.0
            for i in range(m):
                bad |= gam[b, i] - gam[b, i] != 0.0
            code = NONFINITE if bad else OK
            asym = 0.0
            offd = 0.0  # largest off-diagonal |M_ij|: 0 for a diagonal M (planar bodies, point masses)
            if m_valid:
                offd = 0.0 if (known & KNOWN_M_DIAGONAL) != 0 else 1.0
            elif code == OK:
                for i in range(n):
                    for j in range(i):
                        d = abs(M[b, i, j] - M[b, j, i])
                        if d > asym:
                            asym = d
                        a = abs(M[b, i, j]) + abs(M[b, j, i])
                        if a > offd:
                            offd = a
            diag = offd == 0.0
            if asym > 0.0:  # same decision as _validation.symmetric (max|M| only needed now)
                scale = 0.0
                for i in range(n):
                    for j in range(n):
                        a = abs(M[b, i, j])
                        if a > scale:
                            scale = a
                if asym > sym_rtol * max(scale, _TINY):
                    code = ASYMMETRIC
            if code != OK:  # invalid input: the caller re-runs the NumPy path, which raises
                status[b] = code
                rank[b] = 0
                mu_out[b] = 0.0
                ratio[b] = 0.0
                continue
            # ---------------------------------------------------------------- 2. equilibration
            big = 0.0
            Ab = A[b]
            finite = True
            for i in range(m):
                nrm = _pattern_norm(Ab, i, n, Ap) if sparse else _row_norm(Ab, i, n)
                finite &= math.isfinite(nrm)
                sig[i] = nrm
                if nrm > big:
                    big = nrm
            if sparse and not finite:  # a non-finite entry, or only an overflowing square?
                for j in range(n):
                    cw[j] = 0.0
                for i in range(m):
                    for j in range(n):
                        cw[j] += A[b, i, j] * 0.0
                for j in range(n):
                    if cw[j] != 0.0:
                        code = NONFINITE
                if code != OK:
                    status[b] = code
                    rank[b] = 0
                    mu_out[b] = 0.0
                    ratio[b] = 0.0
                    continue
            thr = rtol * big
            for i in range(m):
                nrm = sig[i]
                if nrm > thr:
                    di = 1.0 / nrm
                    if sparse:  # (B is zero off the pattern)
                        for ip in range(Ap[i, 0]):
                            k = Ap[i, 1 + ip]
                            B[i, k] = A[b, i, k] * di
                    else:
                        for j in range(n):
                            B[i, j] = A[b, i, j] * di
                    B[i, n] = di * gam[b, i]
                    dsc[i] = di
                elif sparse:
                    B[i, n] = 0.0
                    dsc[i] = 0.0
                else:
                    for j in range(n + 1):
                        B[i, j] = 0.0
                    dsc[i] = 0.0
            # ---------------------------------------------------------------- 2b. certified QR
            # When every row is live (m ≤ n), an LQ factorization D A = L Q (Householder reflections
            # from the right on the rows; Q has orthonormal rows) decides the rank without the SVD if
            # it is certainly full: σ_min/σ_max ≥ 1/(‖L‖_F ‖L⁻¹‖_F) > QR_MARGIN · rtol means every
            # σ_i is kept by the SVD's rule too. Then V = Q and (D A)⁺ D γ = Qᵀ L⁻¹ D γ. Otherwise
            # (near a singular configuration, redundant rows) the Jacobi SVD below decides.
            lq = LQ_NONE
            zmode = False
            r = 0
            if QR_MIN_ROWS <= m <= n:
                live = 0
                for i in range(m):
                    if sig[i] > thr:
                        live += 1
                if live == m:
                    if sparse:
                        lq = _lq_sparse(B, m, n, rtol, Wz, Ft, Li, cv, sig, Hx, G, Lf, Ro, Pc, Lr,
                                        Rl, In, Ap)  # fmt: skip
                    else:
                        lq = _lq_certified(B, m, n, rtol, Et, Ft, Li, cv, sig, Hx, Lf, Ro, Pc, Lr,
                                           Rl, In)  # fmt: skip
                    if lq != LQ_NONE:
                        r = m
                        # few degrees of freedom (n − m ≤ m): work with the null-space basis Z
                        # (rows of Kt) — M̄ = μI + Zᵀ(S − μI)Z, S = Z M Zᵀ, P = ZᵀZ — instead of V
                        zmode = n - m <= m
                        if zmode:
                            _lq_rows(Ft, sig, m, n, m, n - m, Kt, Hx, Pc)
                        else:
                            _lq_rows(Ft, sig, m, n, 0, m, V, Hx, Pc)
            qr_ok = lq != LQ_NONE
            lapack = not qr_ok and sparse
            if lapack:  # many rows: LAPACK's SVD (the Jacobi sweeps cost O(m² n) each)
                r, zmode = _svd_lapack(B, m, n, rtol, V, Kt, Li, cv)
            elif not qr_ok:
                if warm:  # start from the previous state's rotation: B ← T B (T orthogonal, m × m)
                    for i in range(m):
                        for k in range(n + 1):
                            Bw[i, k] = 0.0
                        for j in range(m):
                            c = T[i, j]
                            if c != 0.0:
                                for k in range(n + 1):
                                    Bw[i, k] += c * B[j, k]
                    for i in range(m):
                        for k in range(n + 1):
                            B[i, k] = Bw[i, k]
                        for j in range(m):
                            Tn[i, j] = T[i, j]
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
                            a0 = 0.0
                            a1 = 0.0
                            b0 = 0.0
                            b1 = 0.0
                            c0 = 0.0
                            c1 = 0.0
                            for k in range(0, n - n % 2, 2):
                                x = B[i, k]
                                y = B[j, k]
                                x1 = B[i, k + 1]
                                y1 = B[j, k + 1]
                                a0 += x * x
                                b0 += y * y
                                c0 += x * y
                                a1 += x1 * x1
                                b1 += y1 * y1
                                c1 += x1 * y1
                            if n % 2:
                                x = B[i, n - 1]
                                y = B[j, n - 1]
                                a0 += x * x
                                b0 += y * y
                                c0 += x * y
                            aa = a0 + a1
                            bb = b0 + b1
                            cc = c0 + c1
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
                            if warm:
                                for k in range(m):
                                    x = Tn[i, k]
                                    y = Tn[j, k]
                                    Tn[i, k] = cs * x - sn * y
                                    Tn[j, k] = sn * x + cs * y
                    if not rotated:
                        break
                if warm:
                    for i in range(m):
                        for j in range(m):
                            T[i, j] = Tn[i, j]
                smax = 0.0
                for i in range(m):
                    sig[i] = _row_norm(B, i, n)
                    if sig[i] > smax:
                        smax = sig[i]
                r = 0
                for i in range(m):
                    if sig[i] > rtol * smax:
                        inv = 1.0 / sig[i]
                        for k in range(n):
                            V[r, k] = B[i, k] * inv
                        cv[r] = B[i, n] * inv  # (Uᵀ D γ)_i / σ_i
                        if warm:  # row r of (Σ⁻¹Uᵀ) for solve_again: B = Tn · (D A | D γ)
                            for k in range(m):
                                Li[r, k] = Tn[i, k] * inv
                        r += 1
            # ---------------------------------------------------------------- 4. PMP, μ, M̄
            dmax = 1.0
            stz = OK
            rtz = np.inf
            if zmode:  # S = Z M Zᵀ and its Cholesky factor (in Tn); M̄ itself only for want_pl
                stz, rtz, mu = _null_factor(M, b, Kt, n - r, diag, has_mu, mu_in, nmu, spd_rtol,
                                            Et, G, Tn)  # fmt: skip
                if want_pl:
                    dmax = _mbar_from_s(Kt, n - r, G, mu, Tt, W)
            if not zmode:
                _rows_times_m(V, r, M, b, diag, Kt)  # Kt = V M
            if not zmode:
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
                    tr_pmp += M[b, i, i] - s
                    tr_m += M[b, i, i]
                if has_mu:
                    mu = mu_in[b] if nmu > 1 else mu_in[0]
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
                        W[i, j] = M[b, i, j]
                    for k in range(r):
                        a = V[k, i]
                        c = Ft[k, i]
                        for j in range(i + 1):
                            W[i, j] -= a * Et[k, j] + c * V[k, j]
                    if W[i, i] > dmax:
                        dmax = W[i, i]
            # ---------------------------------------------------------------- 5. Cholesky
            # (null-space form: only for the L output; the status is that of S)
            st = OK
            rt = np.inf
            if not zmode or want_pl:
                st, rt = _cholesky_lower(W, n, spd_rtol, dmax, dinv, cw)
            if zmode:
                st = stz
                rt = rtz
            status[b] = st
            rank[b] = r
            mu_out[b] = mu
            ratio[b] = rt if st == SMALL_PIVOT else 0.0
            # what solve_again needs to reuse this factorization (the last state's)
            info[0] = 1.0 if (st == OK and (qr_ok or warm or lapack)) else 0.0
            info[1] = 1.0 if zmode else 0.0
            info[2] = r
            info[3] = 1.0 if diag else 0.0
            info[4] = mu
            info[5] = lq
            info[7] = 0.0  # no solve_near result on this factorization yet
            if st != OK:
                continue
        # ---------------------------------------------------------------- 6. right-hand side, solve
        # w = −(DA)⁺ D γ from cv (both branches leave it: certified LQ cv = L⁻¹ D γ, Jacobi
        # cv_k = (u_kᵀ D γ)/σ_k)
        if zmode and info[5] != LQ_NONE:  # −Qᵀ cv through the reflectors
            _lq_min_norm(Ft, sig, m, n, cv, wv, Hx, Pc)
        else:  # −Σ_k v_k cv_k
            for j in range(n):
                wv[j] = 0.0
            for k in range(r):
                c = cv[k]
                for j in range(n):
                    wv[j] -= V[k, j] * c
        want_fc = fc.shape[0] > 0
        for i in range(n):
            gi = h[b, i]
            if has_f:
                gi += f[b, i]
            g[i] = gi
            u[i] = gi
        _add_m_times(M, b, diag, wv, -1.0, u)  # u = g − M w
        if zmode:  # qdd = M̄⁻¹(Zᵀ Z u + μ w) = w + Zᵀ S⁻¹ Z u   (S = Ls Lsᵀ, Ls in Tn)
            _null_space_qdd(Kt, Tn, n - r, u, wv, cv, qdd[b])
        else:
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
        for k in range(0 if zmode else n):  # L y = rhs, column-oriented (independent updates)
            y = u[k] * dinv[k]
            u[k] = y
            for i in range(k + 1, n):
                u[i] -= W[i, k] * y
        for i in range(-1 if zmode else n - 1, -1, -1):  # Lᵀ x = y (contiguous rows of L)
            xi = u[i] * dinv[i]
            qdd[b, i] = xi
            for k in range(i):
                u[k] -= W[i, k] * xi
        if want_fc:
            for i in range(n):  # f_c = M qdd − g
                cw[i] = 0.0
            _add_m_times(M, b, diag, qdd[b], 1.0, cw)
            for i in range(n):
                fc[b, i] = cw[i] - g[i]
        if want_pl:
            for i in range(n):
                for j in range(n):
                    s = 0.0
                    if zmode:  # P = ZᵀZ
                        for k in range(n - r):
                            s += Kt[k, i] * Kt[k, j]
                        P[b, i, j] = s
                    else:  # P = I − VᵀV
                        for k in range(r):
                            s += V[k, i] * V[k, j]
                        P[b, i, j] = (1.0 if i == j else 0.0) - s
                    L[b, i, j] = W[i, j] if j <= i else 0.0


@njit(cache=True)
def solve_one(M, h, f, A, gam, params, out):  # type: ignore[no-untyped-def]
    """Single state (2-D ``M``, ``A``), with few arguments to keep the call overhead small.

    ``params = [has_f, mu, has_mu, rtol, spd_rtol, sym_rtol, want_pl]``; writes
    ``out = [qdd (n), f_c (n), rank, mu, pivot_ratio]``, followed by ``P`` and ``L`` (n × n
    each, row-major) if ``want_pl`` (then ``out`` has ``2n + 3 + 2n²`` entries), and returns the
    status. It inlines :func:`solve_range` itself (rather than calling :func:`solve_work`, which
    would pass the scratch tuple: ~0.5 µs per call, measured at n = 3); the compiled simulation
    loop uses :func:`solve_work`. Every array argument costs the call ~0.1 µs of unboxing,
    hence ``P`` and ``L`` inside ``out``.
    """
    n = M.shape[0]
    m = A.shape[0]
    res = out[: 2 * n].reshape((2, n))
    k = n if params[6] != 0.0 else 0
    o = 2 * n + 3
    P = out[o : o + k * k].reshape((k, k))
    L = out[o + k * k : o + 2 * k * k].reshape((k, k))
    work = scratch(n, m)
    ist = work[17]
    mu_in = params[1:2]
    solve_range(
        0, 1, M.reshape((1, n, n)), h.reshape((1, n)), f.reshape((1, f.shape[0])),
        params[0] != 0.0, A.reshape((1, m, n)), gam.reshape((1, m)), mu_in,
        params[2] != 0.0, params[3], params[4], params[5], res[0:1], res[1:2],
        P.reshape((1, P.shape[0], P.shape[1])), L.reshape((1, L.shape[0], L.shape[1])),
        params[6] != 0.0, ist[0:1], ist[1:2], out[2 * n + 1 : 2 * n + 2],
        out[2 * n + 2 : 2 * n + 3], work, _NO_T, False, False, 0,
    )  # fmt: skip
    out[2 * n] = ist[1]
    return ist[0]


@njit(cache=True)
def solve_work(M, h, f, has_f, A, gam, mu, has_mu, rtol, spd_rtol, sym_rtol, want_pl, out, P, L,
               work, T, warm, again=False, known=0):  # type: ignore[no-untyped-def]  # fmt: skip
    """Single state with caller-owned scratch (``work = scratch(n, m)``) and a warm start.

    For integration loops: no allocation per call, and with ``warm`` true the Jacobi SVD
    starts from ``T`` (m × m orthogonal, the accumulated rotation of the previous call, updated
    in place; start with the identity), so a state close to the previous one converges in
    fewer sweeps. Same result as a cold start up to round-off (same rank policy). ``f`` is read
    only if ``has_f``, ``mu`` only if ``has_mu``. Writes ``out = [qdd (n), f_c (n), rank, mu,
    pivot_ratio]`` (``P`` and ``L`` if ``want_pl``); returns the status. ``known``: what the
    caller has established (bits :data:`KNOWN_M_VALID`, :data:`KNOWN_M_DIAGONAL`,
    :data:`KNOWN_PATTERN`; e.g. a simulation loop with a constant, validated M and the static
    pattern of its A in ``work[30]``); those checks and scans are skipped.
    """
    n = M.shape[0]
    ist = work[17]
    mu_in = work[18]
    mu_in[0] = mu
    # batches of one as x[None] views (a reshape calls a C helper: ~0.02 µs each)
    solve_range(
        0, 1, M[None], h[None], f[None], has_f, A[None], gam[None], mu_in, has_mu, rtol,
        spd_rtol, sym_rtol, out[:n][None], out[n : 2 * n][None], P[None], L[None], want_pl,
        ist[0:1], ist[1:2], out[2 * n + 1 : 2 * n + 2], out[2 * n + 2 : 2 * n + 3], work, T,
        warm, again, known,
    )  # fmt: skip
    out[2 * n] = ist[1]
    return ist[0]


@njit(cache=True)
def solve_again(M, h, f, has_f, gam, want_pl, out, P, L, work):  # type: ignore[no-untyped-def]
    """Solve again with the factorization the last :func:`solve_work` call left in ``work``.

    Same ``A``, ``M``, rank tolerance and μ as that call (the caller guarantees it); new
    ``h``, ``f`` and ``γ``. The result is linear in ``(h + f, γ)``: ``w = −(DA)⁺ D γ`` comes from
    the kept factors (certified LQ: ``L⁻¹`` and the reflectors or ``V``; Jacobi SVD:
    ``Σ⁻¹Uᵀ`` of the kept rows, recorded when the call was warm-started), then step 6 of
    :func:`solve_range` (``solve_work`` with ``again``). Costs O(m² + mn + n²) instead of a
    factorization; used by the simulation loop for the velocity projection and ``F(t, y)`` at
    the same projected ``q``, and for the simplified Gauss–Newton steps of the projection.
    Writes ``out`` as :func:`solve_work`; returns :data:`OK`, or :data:`NO_FACTOR` when
    ``work`` holds no reusable factorization (a failed or cold-started Jacobi call).
    """
    # A, T, μ and the tolerances are not read in this mode: any arrays of the right shape
    return solve_work(M, h, f, has_f, work[1], gam, 1.0, False, 1.0, 1.0, 1.0, want_pl, out, P, L,
                      work, work[16], False, True)  # fmt: skip


@njit(cache=True, inline="always")
def orthonormalize_row(X, i, passes):  # type: ignore[no-untyped-def]
    """Row ``i`` of ``X`` made orthogonal to rows ``0 … i−1`` (orthonormal already; Gram–Schmidt,
    ``passes`` times: 2 reorthogonalizes) and of unit length."""
    n = X.shape[1]
    for _ in range(passes):
        for c in range(i):
            d = 0.0
            for j in range(n):
                d += X[c, j] * X[i, j]
            for j in range(n):
                X[i, j] -= d * X[c, j]
    d = 0.0
    for j in range(n):
        d += X[i, j] * X[i, j]
    d = 1.0 / math.sqrt(d)
    for j in range(n):
        X[i, j] *= d


#: Largest number of refinement passes of :func:`solve_near` (each multiplies the residual by
#: about ‖A − A_h‖ ‖A_h⁺‖; two suffice for the projection's corrections of ~1e-6).
NEAR_PASSES = 3


@njit(cache=True, inline="always")
def _apply_pinv(Hv, beta, Li, dsc, m, n, t, cv, x, Hx, mode, Lf, Ro, Pc):  # type: ignore[no-untyped-def]
    """``x = A_h⁺ t = (D A_h)⁺ D t = Qᵀ L⁻¹ D t`` with the certified LQ held (``cv``: scratch;
    ``mode``: :data:`LQ_INVERSE` or :data:`LQ_PROFILE`, what ``Li`` holds). ``t`` is scratch:
    it is scaled to ``D t`` in place."""
    for i in range(m):
        t[i] *= dsc[i]
    _apply_linv(mode, Li, Lf, Ro, m, t, cv)
    _lq_min_norm(Hv, beta, m, n, cv, x, Hx, Pc)  # −Qᵀ cv
    for j in range(n):
        x[j] = -x[j]


@njit(cache=True, inline="always")
def _scaled_residual(A, x, b, dsc, m, n, res, sp, P):  # type: ignore[no-untyped-def]
    """``res = A x + b`` and ``max_i |D (A x + b)|_i`` (with ``sp`` over A's pattern ``P``)."""
    big = 0.0
    for i in range(m):
        s = b[i]
        if sp:
            s = _pattern_dot(A, i, P, x, s)
        else:
            for j in range(n):
                s += A[i, j] * x[j]
        res[i] = s
        a = abs(s) * dsc[i]
        if a > big:
            big = a
    return big


@njit(cache=True)
def solve_near(M, h, f, has_f, A, gam, spd_rtol, out, work, same, known=0):  # type: ignore[no-untyped-def]
    """Solve at a constraint matrix ``A`` close to the ``A_h`` of the factorization held in
    ``work`` (a certified LQ in the null-space form), without factorizing ``A``.

    The held factors give ``A_h⁺`` (:func:`_apply_pinv`) and an orthonormal basis ``Z_h`` of
    N(A_h). With ``A = A_h + E``: ``z' = z − A_h⁺(A z)`` has ``A z' = −E A_h⁺ E z``, so each
    pass turns the basis' residual from O(‖E‖) into O(‖E‖²) (then Gram–Schmidt); likewise the
    minimum-norm solution ``w`` of ``A w = −γ`` by ``w ← w − A_h⁺(A w + γ)``, then ``w`` minus
    its part in the refined span. With ``Z`` and ``w`` exact for ``A``, the null-space form
    (:func:`solve_range`) gives ``qdd = w + Zᵀ S⁻¹ Z (g − M w)``, ``S = Z M Zᵀ`` and μ = tr S / k:
    the same solution as a factorization of ``A`` (to round-off), at the cost of a few
    products with A and the held factors. Passes continue (at most :data:`NEAR_PASSES`) until
    the equilibrated residuals ``D A Z'ᵀ`` and ``D (A w + γ)`` are at round-off (64 eps). The
    rank is the held one: ``A`` must be within the held factorization's certified margin (the
    caller's concern: the same configuration up to a projection's correction).

    With ``same`` the caller states that ``A`` is (bitwise) the ``A`` of the last call: if that
    call succeeded on the factorization still held, its refined basis ``Z'``, ``S``, the
    Cholesky factor of ``S`` and μ are reused and only ``w`` is computed for the new ``γ``
    (the velocity projection and the evaluation at the projected state share one ``A``).

    ``known``: as for :func:`solve_work` (only :data:`KNOWN_PATTERN` is used: M is not checked
    here in any case, the held factorization's call did).

    Writes ``out`` as :func:`solve_work` (``S`` in the scratch, for cond(M̄)); returns
    :data:`OK`, the SPD status of ``S``, or :data:`NO_FACTOR` when nothing suitable is held or
    the passes do not reach round-off (then factorize ``A``).
    """
    n = M.shape[0]
    m = A.shape[0]
    Kt, Tt, Et, Ft, G = work[2], work[3], work[4], work[5], work[6]
    g, wv, u, sig, cv, Bw, Li, dsc, info, Hx = (work[9], work[10], work[11], work[12], work[13],
                                               work[15], work[19], work[20], work[21], work[22])  # fmt: skip
    Lf, Ro, Pc = work[23], work[24], work[25]
    if info[0] == 0.0 or info[1] == 0.0 or info[5] == LQ_NONE or int(info[2]) != m:
        return NO_FACTOR
    mode = int(info[5])
    k = n - m
    tol = 64.0 * _EPS
    given = (known & KNOWN_PATTERN) != 0
    An = work[30] if given else work[31]
    sp = _sparse_rows(m)
    res = Bw[0]  # scratch (n + 1 ≥ m entries)
    reuse = same and info[7] != 0.0  # Z', S, Ls and μ of the last call are this A's
    if sp and not reuse and not given:  # products with A over its row pattern (reuse: the last call's)
        _pattern(A, m, n, An)
    info[7] = 0.0
    # the refined basis Z' (rows of Tt), from Z_h (rows of Kt)
    if not reuse:
        for a in range(k):
            for j in range(n):
                Tt[a, j] = Kt[a, j]
    ok = reuse
    for _ in range(0 if reuse else NEAR_PASSES):
        big = 0.0
        for a in range(k):
            zr = Tt[a]
            for i in range(m):
                if sp:
                    res[i] = _pattern_dot(A, i, An, zr, 0.0)
                else:
                    s = 0.0
                    for j in range(n):
                        s += A[i, j] * zr[j]
                    res[i] = s
            _apply_pinv(Ft, sig, Li, dsc, m, n, res, cv, u, Hx, mode, Lf, Ro, Pc)
            for j in range(n):
                zr[j] -= u[j]
        for a in range(k):
            orthonormalize_row(Tt, a, 1)
        for a in range(k):
            for i in range(m):
                cv[i] = 0.0
            e = _scaled_residual(A, Tt[a], cv, dsc, m, n, res, sp, An)
            if e > big:
                big = e
        if big <= tol:
            ok = True
            break
    if not ok:
        return NO_FACTOR
    # w: minimum-norm solution of A w = −γ
    for i in range(m):
        res[i] = gam[i]
    _apply_pinv(Ft, sig, Li, dsc, m, n, res, cv, wv, Hx, mode, Lf, Ro, Pc)
    for j in range(n):
        wv[j] = -wv[j]
    gs = 0.0
    for i in range(m):
        gs = max(gs, abs(gam[i]) * dsc[i])
    ok = False
    for _ in range(NEAR_PASSES):
        e = _scaled_residual(A, wv, gam, dsc, m, n, res, sp, An)
        wmax = 0.0
        for j in range(n):
            wmax = max(wmax, abs(wv[j]))
        if e <= tol * (gs + wmax):
            ok = True
            break
        _apply_pinv(Ft, sig, Li, dsc, m, n, res, cv, u, Hx, mode, Lf, Ro, Pc)
        for j in range(n):
            wv[j] -= u[j]
    if not ok:
        return NO_FACTOR
    for a in range(k):  # w ⟂ N(A)
        d = 0.0
        for j in range(n):
            d += Tt[a, j] * wv[j]
        for j in range(n):
            wv[j] -= d * Tt[a, j]
    # the null-space form with Z'
    M3 = M[None]
    diag = info[3] != 0.0
    if reuse:
        mu = info[6]
    else:
        st, _rt, mu = _null_factor(M3, 0, Tt, k, diag, False, info[4:5], 1, spd_rtol, Et, G, Et)
        if st != OK:
            return st
    for i in range(n):
        gi = h[i]
        if has_f:
            gi += f[i]
        g[i] = gi
        u[i] = gi
    _add_m_times(M3, 0, diag, wv, -1.0, u)  # u = g − M w
    qv = out[:n]
    _null_space_qdd(Tt, Et, k, u, wv, cv, qv)  # Ls in Et
    fcv = out[n : 2 * n]  # f_c = M qdd − g
    for i in range(n):
        fcv[i] = -g[i]
    _add_m_times(M3, 0, diag, qv, 1.0, fcv)
    out[2 * n] = m
    out[2 * n + 1] = mu
    out[2 * n + 2] = 0.0
    info[6] = mu
    info[7] = 1.0
    return OK


@njit(cache=True)
def solve_batch_serial(M, h, f, has_f, A, gam, mu_in, has_mu, rtol, spd_rtol, sym_rtol,
                       qdd, fc, P, L, want_pl, status, rank, mu_out, ratio):  # fmt: skip
    """Batch of states (leading axis), one after the other."""
    solve_range(0, M.shape[0], M, h, f, has_f, A, gam, mu_in, has_mu, rtol, spd_rtol, sym_rtol,
                qdd, fc, P, L, want_pl, status, rank, mu_out, ratio,
                scratch(M.shape[1], A.shape[1]), _NO_T, False, False, 0)  # fmt: skip


@njit(cache=True, parallel=True)
def solve_batch_parallel(M, h, f, has_f, A, gam, mu_in, has_mu, rtol, spd_rtol, sym_rtol,
                         qdd, fc, P, L, want_pl, status, rank, mu_out, ratio, nchunks):  # fmt: skip
    """Batch of states split into ``nchunks`` contiguous chunks evaluated in parallel threads."""
    N = M.shape[0]
    for c in prange(nchunks):
        lo = (c * N) // nchunks
        hi = ((c + 1) * N) // nchunks
        solve_range(lo, hi, M, h, f, has_f, A, gam, mu_in, has_mu, rtol, spd_rtol, sym_rtol,
                    qdd, fc, P, L, want_pl, status, rank, mu_out, ratio,
                    scratch(M.shape[1], A.shape[1]), _NO_T, False, False, 0)  # fmt: skip


def num_threads() -> int:
    """Number of threads numba's parallel drivers use."""
    return int(numba.get_num_threads())
