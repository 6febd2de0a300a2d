"""Compiled (numba) kernel of the pin/line/rod block of the planar constraint evaluation.

Optional (extra ``fast``): imported only by :mod:`._compiled` when numba is importable and the
backend chosen with :func:`nonmin.core.set_backend` (or ``NONMIN_BACKEND``) is not ``"numpy"``.
It computes exactly what the NumPy block of :func:`._compiled._constraints` computes — the
same formulas (see that module and ``_elements.py``), in one pass over the primitives —
and writes the variable entries of A in the same order (``var_idx``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True)
def pin_line_rod(x, I6, SL, prm, rows, var_idx, P, NL, NR, buf, PG):  # type: ignore[no-untyped-def]
    """Fill ``PG = [φ; γ]`` (rows of the primitives) and add the variable entries of A to ``buf``.

    Allocates its scratch; loops call :func:`pin_line_rod_work` with their own.
    """
    pin_line_rod_work(x, I6, SL, prm, rows, var_idx, P, NL, NR, buf, PG,
                      np.empty((9, I6.shape[1])), np.empty(var_idx.shape[0]), False)  # fmt: skip


@njit(cache=True)
def pin_line_rod_work(x, I6, SL, prm, rows, var_idx, P, NL, NR, buf, PG, wk, vals, vel_only):  # type: ignore[no-untyped-def]
    """:func:`pin_line_rod` with caller-owned scratch ``wk`` (9, S) and ``vals`` (len(var_idx),).

    With ``vel_only`` only γ (``PG[1]``) is computed, for new velocities at the ``q`` of the
    previous call with this ``wk`` (whose rotated vectors, points and angles it reuses); φ and
    A are left as they are.

    Parameters
    ----------
    x : (2n + 2,) ``(q, 0, qd, 0)``
    I6 : (6, S) int, indices into x of ``(x, y, θ, ẋ, ẏ, θ̇)`` of every side (point)
    SL : (2, S) local vectors ``s``
    prm : (2 NL + 3 NR,) line axes ``(u_x, u_y)`` then rod ``(s/L, L, s)``
    rows : (P + NL + NR,) first row of each pin, then line rows, then rod rows
    var_idx : flat indices (into buf) of the variable entries of A, in the NumPy order
    """
    S = I6.shape[1]
    rsx = wk[0]
    rsy = wk[1]
    px = wk[2]
    py = wk[3]
    vx = wk[4]
    vy = wk[5]
    om = wk[6]
    cs = wk[7]
    sn = wk[8]
    for k in range(S):
        if vel_only:
            rx = rsx[k]
            ry = rsy[k]
        else:
            th = x[I6[2, k]]
            c = math.cos(th)
            s = math.sin(th)
            sx = SL[0, k]
            sy = SL[1, k]
            rx = c * sx + s * (-sy)
            ry = c * sy + s * sx
            rsx[k] = rx
            rsy[k] = ry
            px[k] = x[I6[0, k]] + rx
            py[k] = x[I6[1, k]] + ry
            cs[k] = c
            sn[k] = s
        w = x[I6[5, k]]
        om[k] = w
        # ṗ = ṙ + θ̇ (R s)^⊥ with (R s)^⊥ = (−r_y, r_x)
        vx[k] = x[I6[3, k]] + w * -ry
        vy[k] = x[I6[4, k]] + w * rx
    phi = PG[0]
    gamma = PG[1]
    m = phi.shape[0]
    n_var = var_idx.shape[0]
    j = 0
    # ------------------------------------------------------------------ pins
    P2 = 2 * P
    for i in range(P):
        a = i
        b = P + i
        r = rows[i]
        if not vel_only:
            phi[r] = px[a] - px[b]
            phi[r + 1] = py[a] - py[b]
        wa = om[a] * om[a]
        wb = om[b] * om[b]
        gamma[r] = wa * -rsx[a] - wb * -rsx[b]
        gamma[r + 1] = wa * -rsy[a] - wb * -rsy[b]
    # θ entries sign·(R s)^⊥: x rows of all 2P sides, then y rows
    for k in range(P2):
        sg = 1.0 if k < P else -1.0
        vals[j + k] = -rsy[k] * sg
        vals[j + P2 + k] = rsx[k] * sg
    j += 2 * P2
    # ------------------------------------------------------------------ lines
    o = P2
    for i in range(NL):
        a = o + i
        b = o + NL + i
        r = rows[P + i]
        ux = prm[2 * i]
        uy = prm[2 * i + 1]
        ca = cs[a]
        sa = sn[a]
        oma = om[a]
        # n = R_a u^⊥, u^⊥ = (−u_y, u_x); n^⊥ = R_a (−u)
        nx = ca * -uy + sa * -ux
        ny = ca * ux + sa * -uy
        npx = ca * -ux - sa * -uy
        npy = ca * -uy - sa * ux
        dx = px[b] - px[a]
        dy = py[b] - py[a]
        ddx = vx[b] - vx[a]
        ddy = vy[b] - vy[a]
        dn = nx * dx + ny * dy
        if not vel_only:
            phi[r] = dn
        wa = oma * oma
        wb = om[b] * om[b]
        gx = wb * -rsx[b] - wa * -rsx[a]
        gy = wb * -rsy[b] - wa * -rsy[a]
        gamma[r] = 2.0 * oma * (npx * ddx + npy * ddy) + (nx * gx + ny * gy) - oma * oma * dn
        # rsp = (−r_y, r_x)
        nb = nx * -rsy[b] + ny * rsx[b]
        na = (dx * npx + dy * npy) - (nx * -rsy[a] + ny * rsx[a])
        vals[j + i] = nx
        vals[j + NL + i] = ny
        vals[j + 2 * NL + i] = nb
        vals[j + 3 * NL + i] = -nx
        vals[j + 4 * NL + i] = -ny
        vals[j + 5 * NL + i] = na
    j += 6 * NL
    # ------------------------------------------------------------------ rods
    o = P2 + 2 * NL
    q0 = 2 * NL
    for i in range(NR):
        a = o + i
        b = o + NR + i
        r = rows[P + NL + i]
        kc = prm[q0 + 3 * i]
        L = prm[q0 + 3 * i + 1]
        sg = prm[q0 + 3 * i + 2]
        dx = px[b] - px[a]
        dy = py[b] - py[a]
        ddx = vx[b] - vx[a]
        ddy = vy[b] - vy[a]
        if not vel_only:
            phi[r] = sg * ((dx * dx + dy * dy) - L * L) / (2.0 * L)
        wa = om[a] * om[a]
        wb = om[b] * om[b]
        gx = wb * -rsx[b] - wa * -rsx[a]
        gy = wb * -rsy[b] - wa * -rsy[a]
        gamma[r] = kc * ((ddx * ddx + ddy * ddy) + (dx * gx + dy * gy))
        kdx = kc * dx
        kdy = kc * dy
        vals[j + i] = kdx
        vals[j + NR + i] = kdy
        vals[j + 2 * NR + i] = kdx * -rsy[b] + kdy * rsx[b]
        vals[j + 3 * NR + i] = -kdx
        vals[j + 4 * NR + i] = -kdy
        vals[j + 5 * NR + i] = -(kdx * -rsy[a] + kdy * rsx[a])
    j += 6 * NR
    if not vel_only:  # (vals is scratch: computed either way)
        for k in range(n_var):
            buf[var_idx[k]] += vals[k]
    return m


@njit(cache=True)
def inputs(x, I3, SL, fdir, AX, nf, npr, var_idx, buf):  # type: ignore[no-untyped-def]
    """Add the q-dependent entries of B to ``buf`` (same order and formulas as ``Inputs.matrix``).

    ``x = (q, 0)``; sides: the ``nf`` point forces, then the ``npr`` prismatic a sides, then
    their b sides; ``fdir`` (2, nf) force directions, ``AX`` (2, npr) prismatic axes.
    """
    n_var = var_idx.shape[0]
    vals = np.empty(n_var)
    for k in range(nf):
        th = x[I3[2, k]]
        c = math.cos(th)
        s = math.sin(th)
        sx = SL[0, k]
        sy = SL[1, k]
        vals[k] = fdir[0, k] * (c * -sy - s * sx) + fdir[1, k] * (c * sx - s * sy)
    j = nf
    for i in range(npr):
        a = nf + i
        b = nf + npr + i
        tha = x[I3[2, a]]
        ca = math.cos(tha)
        sa = math.sin(tha)
        ax = AX[0, i]
        ay = AX[1, i]
        ux = ca * ax + sa * -ay  # R_a axis
        uy = ca * ay + sa * ax
        thb = x[I3[2, b]]
        cb = math.cos(thb)
        sb = math.sin(thb)
        sx = SL[0, b]
        sy = SL[1, b]
        lx = (x[I3[0, b]] + (cb * sx + sb * -sy)) - x[I3[0, a]]  # p_b − r_a
        ly = (x[I3[1, b]] + (cb * sy + sb * sx)) - x[I3[1, a]]
        tb = ux * (cb * -sy - sb * sx) + uy * (cb * sx - sb * sy)
        vals[j + i] = ux
        vals[j + npr + i] = uy
        vals[j + 2 * npr + i] = tb
        vals[j + 3 * npr + i] = -ux
        vals[j + 4 * npr + i] = -uy
        vals[j + 5 * npr + i] = -(ux * -ly + uy * lx)
    for k in range(n_var):
        buf[var_idx[k]] += vals[k]
    return n_var
