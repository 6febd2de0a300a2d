"""Vectorized evaluation of a planar model: index arrays built once, NumPy inside.

Every joint is decomposed at build time into *row primitives* of four kinds:

* ``pin``   — two rows ``φ = p_a − p_b`` (revolute; the first two rows of a weld),
* ``line``  — one row ``φ = n·(p_b − p_a)``, ``n = R_a u^⊥`` (point-on-line; prismatic row 2),
* ``rod``   — one row ``φ = s (dᵀd − L²)/(2L)``, ``d = p_b − p_a``, ``s = ±1``,
* ``angle`` — one row linear in the angles, ``φ = g·q − c − f(t)`` (weld row 3, prismatic row 1,
  gear, angle driver with the profile ``f``); its ``A`` row ``g`` is constant.

Joints of a user-defined :class:`~nonmin.model.planar.Joint` subclass (not one of the above) keep
their own :meth:`Joint.terms`. For an active set, a :class:`Layout` (cached per frozenset by the
model) holds the row of every primitive, the constant entries of ``A`` (a template) and the flat
indices of its variable entries. One evaluation then computes the kinematics of every primitive's
points with a few vectorized operations and scatters them into ``A``, ``γ`` and ``φ``; the
formulas are those of :mod:`._elements` (the per-joint reference implementation).

This is the Python side's evaluation (``PlanarModel.evaluate``, ``constraint_terms``, the
general driver); the engine evaluates the same primitives in C++ (``engine/src/planar_program.cpp``,
described by :mod:`._program`), and the two agree to round-off (tests/model/test_planar_program.py).

Coordinates are addressed in ``q_ext = (q, 0)``: the ground's ``x, y, θ`` and a point mass's
``θ`` point at the extra zero entry ``n``. Entries of ``A`` in that column are discarded by
sending them to a dump slot after the ``m·n`` entries of the flat buffer.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ...errors import ModelError
from .._protocol import ConstraintTerms, FloatArray
from ._elements import (
    GROUND,
    AngleDriver,
    Gear,
    Joint,
    Point,
    PointOnLine,
    Prismatic,
    Revolute,
    Rod,
    RotationalSpring,
    Spring,
    Weld,
    _Indexed,
    _Kin,
)

IntArray = NDArray[np.intp]
_ZERO1 = np.zeros(1)


@dataclass(frozen=True)
class _Side:
    """One point of a primitive: ``(ix, iy, ith)`` in q_ext and local coordinates."""

    ix: int
    iy: int
    ith: int
    sx: float
    sy: float


@dataclass(frozen=True)
class _Prim:
    """A row primitive of a joint (``offset``: its first row within the joint)."""

    kind: str  # "pin" | "line" | "rod" | "angle"
    offset: int
    a: _Side | None = None
    b: _Side | None = None
    ux: float = 0.0  # line: unit axis (body a)
    uy: float = 0.0
    coef: float = 0.0  # rod: s / L
    length: float = 0.0  # rod: L
    sign: float = 1.0  # rod: s
    angles: tuple[tuple[int, float], ...] = ()  # angle: (column, coefficient)
    const: float = 0.0  # angle: c
    profile: Callable[[float], tuple[float, float, float]] | None = None  # angle: driver f(t)


class Plan:
    """Row primitives of every joint of a model (built once, in the model's ``__post_init__``)."""

    def __init__(self, joints: tuple[Joint, ...], index: dict[str, tuple[int, int, int]], n: int) -> None:
        self.n = n
        self.joints = joints
        self.dims = tuple(j.dim for j in joints)

        def side(p: Point) -> _Side:
            if p.body == GROUND:
                return _Side(n, n, n, p.local[0], p.local[1])
            ix, iy, ith = index[p.body]
            return _Side(ix, iy, ith if ith >= 0 else n, p.local[0], p.local[1])

        def theta(body: str) -> int:
            return n if body == GROUND else index[body][2]

        def angle_row(offset: int, terms: Iterable[tuple[str, float]], const: float, profile: object = None) -> _Prim:
            cols = tuple((theta(b), float(c)) for b, c in terms if b != GROUND)
            return _Prim("angle", offset, angles=cols, const=const, profile=profile)  # type: ignore[arg-type]

        prims: list[tuple[_Prim, ...] | None] = []
        for j in joints:
            tj = type(j)
            if tj is Revolute:
                assert isinstance(j, Revolute)
                prims.append((_Prim("pin", 0, side(j.a), side(j.b)),))
            elif tj is Weld:
                assert isinstance(j, Weld)
                prims.append(
                    (
                        _Prim("pin", 0, side(j.a), side(j.b)),
                        angle_row(2, ((j.b.body, 1.0), (j.a.body, -1.0)), j.angle),
                    )
                )
            elif tj is PointOnLine:
                assert isinstance(j, PointOnLine)
                prims.append((_Prim("line", 0, side(j.a), side(j.b), ux=j.axis[0], uy=j.axis[1]),))
            elif tj is Prismatic:
                assert isinstance(j, Prismatic)
                prims.append(
                    (
                        angle_row(0, ((j.b.body, 1.0), (j.a.body, -1.0)), j.angle),
                        _Prim("line", 1, side(j.a), side(j.b), ux=j.axis[0], uy=j.axis[1]),
                    )
                )
            elif tj is Rod:
                assert isinstance(j, Rod)
                s = -1.0 if j.unilateral else 1.0
                prims.append(
                    (_Prim("rod", 0, side(j.a), side(j.b), coef=s / j.length, length=j.length, sign=s),)
                )
            elif tj is Gear:
                assert isinstance(j, Gear)
                prims.append(
                    (
                        angle_row(
                            0,
                            ((j.body_b, 1.0), (j.carrier, -1.0 + j.ratio), (j.body_a, -j.ratio)),
                            j.offset,
                        ),
                    )
                )
            elif tj is AngleDriver:
                assert isinstance(j, AngleDriver)
                prims.append((angle_row(0, ((j.body_b, 1.0), (j.body_a, -1.0)), 0.0, j.profile),))
            else:
                prims.append(None)  # a user-defined joint: its own terms()
        self.prims = tuple(prims)

    def layout(self, active: frozenset[str]) -> Layout:
        """The :class:`Layout` of an active set (names already validated)."""
        return Layout(self, active)


def _known(s: _Side | None) -> _Side:
    assert s is not None
    return s


def _flat(row: IntArray, col: IntArray, m: int, n: int) -> IntArray:
    """Flat index ``row·n + col`` into the (m·n + 1) buffer; column n goes to the dump slot."""
    return np.where(col < n, row * n + col, m * n).astype(np.intp)


def _pair_flat(
    row: IntArray, cols: tuple[IntArray, IntArray, IntArray], a_: slice, b_: slice, m: int, n: int
) -> list[IntArray]:
    """The six flat indices of a two-point row, in value order x_b, y_b, θ_b, x_a, y_a, θ_a
    (``cols`` = the point columns of x, y and θ)."""
    return [_flat(row, c[s], m, n) for s in (b_, a_) for c in cols]


class Layout:
    """Row layout and index arrays of one active set (immutable once built)."""

    def __init__(self, plan: Plan, active: frozenset[str]) -> None:
        n = plan.n
        self.n = n
        pins: list[tuple[int, _Side, _Side]] = []
        lines: list[tuple[int, _Prim]] = []
        rods: list[tuple[int, _Prim]] = []
        angles: list[tuple[int, _Prim]] = []
        generic: list[tuple[int, Joint]] = []
        r = 0
        for j, dim, pr in zip(plan.joints, plan.dims, plan.prims, strict=True):
            if j.name not in active:
                continue
            if pr is None:
                generic.append((r, j))
            else:
                for p in pr:
                    row = r + p.offset
                    if p.kind == "pin":
                        assert p.a is not None and p.b is not None
                        pins.append((row, p.a, p.b))
                    elif p.kind == "line":
                        lines.append((row, p))
                    elif p.kind == "rod":
                        rods.append((row, p))
                    else:
                        angles.append((row, p))
            r += dim
        m = r
        self.m = m
        self.generic = tuple(generic)
        P, NL, NR = len(pins), len(lines), len(rods)
        self.P, self.NL, self.NR = P, NL, NR
        # sides, in the order pin a, pin b, line a, line b, rod a, rod b
        sides: list[_Side] = (
            [a for _, a, _ in pins]
            + [b for _, _, b in pins]
            + [_known(p.a) for _, p in lines]
            + [_known(p.b) for _, p in lines]
            + [_known(p.a) for _, p in rods]
            + [_known(p.b) for _, p in rods]
        )
        S = len(sides)
        self.S = S
        self.I3: IntArray = np.array(
            [[s.ix for s in sides], [s.iy for s in sides], [s.ith for s in sides]], dtype=np.intp
        ).reshape(3, S)
        sx: FloatArray = np.array([s.sx for s in sides], dtype=np.float64)
        sy: FloatArray = np.array([s.sy for s in sides], dtype=np.float64)
        self.SL = np.stack([sx, sy]).reshape(2, S)
        self.SLp = np.stack([-sy, sx]).reshape(2, S)
        #: q_ext ⊕ qd_ext indices (6, S): x, y, θ, ẋ, ẏ, θ̇ of each side's body
        self.I6 = np.concatenate([self.I3, self.I3 + (n + 1)]).astype(np.intp)
        #: ``c·K1 + s·K2 = [R s; (R s)^⊥; −R s]`` (6, S)
        self.K1 = np.concatenate([self.SL, self.SLp, -self.SL])
        self.K2 = np.concatenate([self.SLp, -self.SL, -self.SLp])

        const_idx: list[IntArray] = []
        const_val: list[FloatArray] = []
        var_idx: list[IntArray] = []
        ix, iy, ith = self.I3
        # ---------------------------------------------------------------- pins
        prow = np.array([row for row, _, _ in pins], dtype=np.intp)
        self.pin_rows = np.concatenate([prow, prow + 1])  # x rows, then y rows
        if P:
            sgn = np.concatenate([np.ones(P), -np.ones(P)])
            r2 = np.concatenate([prow, prow])
            const_idx += [_flat(r2, ix[: 2 * P], m, n), _flat(r2 + 1, iy[: 2 * P], m, n)]
            const_val += [sgn, sgn]
            # θ entries: sign·(R s)^⊥ — x row gets sign·rsp_x, y row sign·rsp_y
            var_idx += [_flat(r2, ith[: 2 * P], m, n), _flat(r2 + 1, ith[: 2 * P], m, n)]
            self.pin_sign2 = np.stack([sgn, sgn])
        # ---------------------------------------------------------------- lines
        self.line_rows = np.array([row for row, _ in lines], dtype=np.intp)
        if NL:
            o = 2 * P
            a_, b_ = slice(o, o + NL), slice(o + NL, o + 2 * NL)
            rl = self.line_rows
            # u^⊥ = (−u_y, u_x) and its perpendicular (−u_x, −u_y), for n = c·UP + s·UPp
            ux = np.array([p.ux for _, p in lines])
            uy = np.array([p.uy for _, p in lines])
            self.UP = np.stack([-uy, ux])
            self.UPp = np.stack([-ux, -uy])
            # value order: n_x (x_b), n_y (y_b), n·rsp_b (θ_b), −n_x (x_a), −n_y (y_a), θ_a
            var_idx += _pair_flat(rl, (ix, iy, ith), a_, b_, m, n)
        # ---------------------------------------------------------------- rods
        self.rod_rows = np.array([row for row, _ in rods], dtype=np.intp)
        if NR:
            o = 2 * P + 2 * NL
            a_, b_ = slice(o, o + NR), slice(o + NR, o + 2 * NR)
            rr = self.rod_rows
            self.rod_coef = np.array([p.coef for _, p in rods])
            self.rod_len = np.array([p.length for _, p in rods])
            self.rod_sign = np.array([p.sign for _, p in rods])
            var_idx += _pair_flat(rr, (ix, iy, ith), a_, b_, m, n)
        # ---------------------------------------------------------------- angle rows
        self.angle_rows = np.array([row for row, _ in angles], dtype=np.intp)
        G = np.zeros((len(angles), n + 1))
        for k, (row, p) in enumerate(angles):
            for col, c in p.angles:
                G[k, col] += c
                if col < n:
                    const_idx.append(np.array([row * n + col], dtype=np.intp))
                    const_val.append(np.array([c]))
        self.G = np.ascontiguousarray(G[:, :n])
        self.angle_const = np.array([p.const for _, p in angles])
        self.drivers = tuple(
            (k, int(row), p.profile) for k, (row, p) in enumerate(angles) if p.profile is not None
        )
        # ---------------------------------------------------------------- A template
        buf = np.zeros(m * n + 1)
        if const_idx:
            np.add.at(buf, np.concatenate(const_idx), np.concatenate(const_val))
        buf[m * n] = 0.0
        self.A0 = buf
        #: ``[M.ravel(), A0]`` for :func:`constraint_terms_and_mass` (set on first use)
        self.MA0: FloatArray | None = None
        # packed pin/line/rod inputs, read by the frozen numba loop (benchmarks/numba_baseline)
        self.k_rows = np.concatenate([prow, self.line_rows, self.rod_rows]).astype(np.intp)
        self.k_prm = np.array(
            [v for _, p in lines for v in (p.ux, p.uy)]
            + [v for _, p in rods for v in (p.coef, p.length, p.sign)],
            dtype=np.float64,
        )
        self.var_idx = np.concatenate(var_idx) if var_idx else np.zeros(0, dtype=np.intp)
        real = self.var_idx[self.var_idx < m * n]
        #: variable entries may share a position (e.g. a joint between two points of one body)
        self.var_unique = bool(np.unique(real).size == real.size)
        self.holonomic = np.ones(m, dtype=bool)
        self.has_rheo = bool(self.drivers) or bool(generic)


def constraint_terms(
    model: _Indexed, lay: Layout, t: float, q: FloatArray, qd: FloatArray, adot: bool = False
) -> tuple[ConstraintTerms, FloatArray | None]:
    """Stacked ``(A, γ, φ, A qd + φ_t, holonomic)`` of the layout's active set, and ``Ȧ``
    (shape (m, n)) when ``adot`` is true (else None)."""
    return _constraints(model, lay, t, q, qd, lay.A0.copy(), adot)


def constraint_terms_and_mass(
    model: _Indexed, lay: Layout, t: float, q: FloatArray, qd: FloatArray, M: FloatArray
) -> tuple[ConstraintTerms, FloatArray]:
    """:func:`constraint_terms` and a fresh copy of the constant mass matrix ``M``.

    Both are views of one new buffer (a copy of ``[M, A template]``): one allocation instead of
    two, which for large n also spares the allocator returning and re-faulting pages between
    calls.
    """
    big = lay.MA0
    if big is None or big.size != M.size + lay.A0.size:
        big = np.concatenate((M.ravel(), lay.A0))
        lay.MA0 = big
    nn = M.size
    buf = big.copy()
    return _constraints(model, lay, t, q, qd, buf[nn:], False)[0], buf[:nn].reshape(M.shape)


def _constraints(
    model: _Indexed, lay: Layout, t: float, q: FloatArray, qd: FloatArray, buf: FloatArray, adot: bool
) -> tuple[ConstraintTerms, FloatArray | None]:
    """Fill ``buf`` (a copy of the A template, length m·n + 1) and return the terms."""
    n, m = lay.n, lay.m
    if m == 0:
        e = np.zeros(0)
        Ad0 = np.zeros((0, n)) if adot else None
        return ConstraintTerms(np.zeros((0, n)), e, e.copy(), e.copy(), np.zeros(0, dtype=bool)), Ad0
    dvals: list[FloatArray] = []
    PG = np.zeros((2, m))  # rows: φ, γ
    phi, gamma = PG[0], PG[1]
    P, NL, NR = lay.P, lay.NL, lay.NR
    if lay.S:
        X = np.concatenate((q, _ZERO1, qd, _ZERO1))[lay.I6]  # (6, S): x, y, θ, ẋ, ẏ, θ̇
        c = np.cos(X[2])
        s = np.sin(X[2])
        RR = c * lay.K1 + s * lay.K2
        rs, rsp, nrs = RR[:2], RR[2:4], RR[4:]  # R s, (R s)^⊥, −R s
        p = X[:2] + rs  # point positions
        om = X[5]
        om2nrs = (om * om) * nrs  # −θ̇² R s (the acceleration of the point at zero q̈)
        vals: list[FloatArray] = []
        if P:
            P2 = 2 * P
            # φ = p_a − p_b and γ = −θ̇_a² R_a s_a + θ̇_b² R_b s_b in one subtraction
            W = np.concatenate((p, om2nrs))
            PG[:, lay.pin_rows] = (W[:, :P] - W[:, P:P2]).reshape(2, P2)
            vals.append((rsp[:, :P2] * lay.pin_sign2).ravel())
            if adot:  # d/dt of sign·(R s)^⊥ is −sign·θ̇ R s
                dvals.append((om[:P2] * nrs[:, :P2] * lay.pin_sign2).ravel())
        if NL or NR:
            v = X[3:5] + om * rsp  # point velocities
        if NL:
            o = 2 * P
            a_, b_ = slice(o, o + NL), slice(o + NL, o + 2 * NL)
            ca, sa, oma = c[a_], s[a_], om[a_]
            nrm = ca * lay.UP + sa * lay.UPp  # n = R_a u^⊥
            nperp = ca * lay.UPp - sa * lay.UP  # n^⊥
            d = p[:, b_] - p[:, a_]
            dd = v[:, b_] - v[:, a_]
            dn = (nrm * d).sum(axis=0)
            phi[lay.line_rows] = dn
            gamma[lay.line_rows] = (
                2.0 * oma * (nperp * dd).sum(axis=0)
                + (nrm * (om2nrs[:, b_] - om2nrs[:, a_])).sum(axis=0)
                - oma * oma * dn
            )
            nb = (nrm * rsp[:, b_]).sum(axis=0)
            na = (d * nperp).sum(axis=0) - (nrm * rsp[:, a_]).sum(axis=0)
            vals.append(np.concatenate([nrm[0], nrm[1], nb, -nrm[0], -nrm[1], na]))
            if adot:  # Ȧ = ṅᵀD + nᵀḊ + (ḋ·n^⊥ − θ̇_a d·n) e_θa,  ṅ = θ̇_a n^⊥
                ndot = oma * nperp
                omb = om[b_]
                dnb = (ndot * rsp[:, b_]).sum(axis=0) - omb * (nrm * rs[:, b_]).sum(axis=0)
                dna = (
                    -(ndot * rsp[:, a_]).sum(axis=0)
                    + oma * (nrm * rs[:, a_]).sum(axis=0)
                    + (dd * nperp).sum(axis=0)
                    - oma * dn
                )
                dvals.append(np.concatenate([ndot[0], ndot[1], dnb, -ndot[0], -ndot[1], dna]))
        if NR:
            o = 2 * P + 2 * NL
            a_, b_ = slice(o, o + NR), slice(o + NR, o + 2 * NR)
            d = p[:, b_] - p[:, a_]
            dd = v[:, b_] - v[:, a_]
            k = lay.rod_coef
            L = lay.rod_len
            phi[lay.rod_rows] = lay.rod_sign * ((d * d).sum(axis=0) - L * L) / (2.0 * L)
            gamma[lay.rod_rows] = k * ((dd * dd).sum(axis=0) + (d * (om2nrs[:, b_] - om2nrs[:, a_])).sum(axis=0))
            kd = k * d
            tb = (kd * rsp[:, b_]).sum(axis=0)
            ta = (kd * rsp[:, a_]).sum(axis=0)
            vals.append(np.concatenate([kd[0], kd[1], tb, -kd[0], -kd[1], -ta]))
            if adot:  # Ȧ = (s/L)(ḋᵀD + dᵀḊ)
                kdd = k * dd
                dtb = (kdd * rsp[:, b_]).sum(axis=0) - om[b_] * (kd * rs[:, b_]).sum(axis=0)
                dta = -(kdd * rsp[:, a_]).sum(axis=0) + om[a_] * (kd * rs[:, a_]).sum(axis=0)
                dvals.append(np.concatenate([kdd[0], kdd[1], dtb, -kdd[0], -kdd[1], dta]))
        allv = vals[0] if len(vals) == 1 else np.concatenate(vals)
        if lay.var_unique:
            buf[lay.var_idx] += allv
        else:
            np.add.at(buf, lay.var_idx, allv)
    A = buf[: m * n].reshape(m, n)
    Ad: FloatArray | None = None
    if adot:
        dbuf = np.zeros(m * n + 1)
        if dvals:
            np.add.at(dbuf, lay.var_idx, np.concatenate(dvals))
        Ad = dbuf[: m * n].reshape(m, n)
    phit: FloatArray | None = None
    if lay.angle_rows.size:
        pa = lay.G @ q - lay.angle_const
        if lay.drivers:
            phit = np.zeros(m)
            for k_, row, prof in lay.drivers:
                f, fd, fdd = (float(x) for x in prof(float(t)))
                pa[k_] -= f
                gamma[row] = -fdd
                phit[row] = -fd
        phi[lay.angle_rows] = pa
    if lay.generic:
        kin = _Kin(model, q, qd)
        if phit is None:
            phit = np.zeros(m)
        for r, j in lay.generic:
            ph, Aj, Adj, gj, ptj = j.terms(kin, float(t))
            A[r : r + j.dim] = Aj
            if Ad is not None:
                Ad[r : r + j.dim] = Adj
            phi[r : r + j.dim] = ph
            gamma[r : r + j.dim] = gj
            phit[r : r + j.dim] = ptj
    vel = A @ qd
    if phit is not None:
        vel += phit
    return ConstraintTerms(A, gamma, phi, vel, lay.holonomic.copy()), Ad


# ----------------------------------------------------------------------------- forces and B
def _side_arrays(sides: list[_Side]) -> tuple[IntArray, FloatArray, FloatArray]:
    """``(I3, SL, SLp)``: q_ext indices (3, S), local vectors ``s`` and ``s^⊥`` (2, S)."""
    S = len(sides)
    I3 = np.array([[s.ix for s in sides], [s.iy for s in sides], [s.ith for s in sides]], dtype=np.intp)
    sx = np.array([s.sx for s in sides], dtype=np.float64)
    sy = np.array([s.sy for s in sides], dtype=np.float64)
    return I3.reshape(3, S), np.stack([sx, sy]).reshape(2, S), np.stack([-sy, sx]).reshape(2, S)


class Forces:
    """Springs, rotational springs, dampers and the q-dependent columns of B, vectorized.

    Contributions to a force vector are accumulated with ``np.bincount`` over q_ext indices
    (the extra entry n collects the terms of the ground and of point-mass rotations).
    """

    def __init__(
        self,
        springs: list[Spring],
        rsprings: list[RotationalSpring],
        index: dict[str, tuple[int, int, int]],
        n: int,
    ) -> None:
        self.n = n

        def side(p: Point) -> _Side:
            if p.body == GROUND:
                return _Side(n, n, n, p.local[0], p.local[1])
            ix, iy, ith = index[p.body]
            return _Side(ix, iy, ith if ith >= 0 else n, p.local[0], p.local[1])

        def theta(body: str) -> int:
            if body == GROUND:
                return n
            ith = index[body][2]
            return ith if ith >= 0 else n

        self.NS = len(springs)
        sides = [side(sp.a) for sp in springs] + [side(sp.b) for sp in springs]
        self.I3, self.SL, self.SLp = _side_arrays(sides)
        ns = self.NS
        # force index order: x_b, y_b, θ_b, x_a, y_a, θ_a
        self.sp_idx = np.concatenate(
            [self.I3[0, ns:], self.I3[1, ns:], self.I3[2, ns:], self.I3[0, :ns], self.I3[1, :ns], self.I3[2, :ns]]
        ).astype(np.intp)
        self.sp_k = np.array([sp.stiffness for sp in springs], dtype=np.float64)
        self.sp_L0 = np.array([sp.rest_length for sp in springs], dtype=np.float64)
        self.sp_c = np.array([sp.damping for sp in springs], dtype=np.float64)
        self.sp_names = tuple(sp.name for sp in springs)
        self.NR = len(rsprings)
        self.rs_a = np.array([theta(r.body_a) for r in rsprings], dtype=np.intp)
        self.rs_b = np.array([theta(r.body_b) for r in rsprings], dtype=np.intp)
        self.rs_idx = np.concatenate([self.rs_b, self.rs_a]).astype(np.intp)
        self.rs_k = np.array([r.stiffness for r in rsprings], dtype=np.float64)
        self.rs_th0 = np.array([r.rest_angle for r in rsprings], dtype=np.float64)
        self.rs_c = np.array([r.damping for r in rsprings], dtype=np.float64)

    def _spring_kin(self, q: FloatArray, qd: FloatArray | None) -> tuple[FloatArray, ...]:
        """``(d, ḋ, rsp_a, rsp_b)`` of every spring (``ḋ`` zero when qd is None)."""
        ns = self.NS
        qe = np.concatenate((q, _ZERO1))
        Q = qe[self.I3]
        c = np.cos(Q[2])
        s = np.sin(Q[2])
        rs = c * self.SL + s * self.SLp
        rsp = c * self.SLp - s * self.SL
        p = Q[:2] + rs
        d = p[:, ns:] - p[:, :ns]
        if qd is None:
            dd = np.zeros_like(d)
        else:
            V = np.concatenate((qd, _ZERO1))[self.I3]
            v = V[:2] + V[2] * rsp
            dd = v[:, ns:] - v[:, :ns]
        return d, dd, rsp[:, :ns], rsp[:, ns:]

    def _scatter(self, coef: FloatArray, d: FloatArray, rspa: FloatArray, rspb: FloatArray) -> FloatArray:
        """``Σ coef_i · D_iᵀ d_i`` as a vector over q_ext (length n + 1)."""
        cd = coef * d
        w = np.concatenate([cd[0], cd[1], (cd * rspb).sum(axis=0), -cd[0], -cd[1], -(cd * rspa).sum(axis=0)])
        f: FloatArray = np.bincount(self.sp_idx, weights=w, minlength=self.n + 1)  # type: ignore[assignment]
        return f

    def conservative(self, fg: FloatArray, q: FloatArray) -> FloatArray:
        """``f_g`` = gravity ``fg`` plus the spring forces ``−k(ℓ − ℓ0) Dᵀe``."""
        f = np.zeros(self.n + 1)
        if self.NS:
            d, _, rspa, rspb = self._spring_kin(q, None)
            ell = np.hypot(d[0], d[1])
            pos = ell > 0.0
            bad = ~pos & (self.sp_k != 0.0) & (self.sp_L0 != 0.0)
            if bad.any():
                name = self.sp_names[int(np.flatnonzero(bad)[0])]
                raise ModelError(f"spring {name!r}: zero length, force direction undefined")
            coef = -self.sp_k * (1.0 - self.sp_L0 / np.where(pos, ell, 1.0)) * pos
            f += self._scatter(coef, d, rspa, rspb)
        if self.NR:
            qe = np.concatenate((q, _ZERO1))
            tau = -self.rs_k * (qe[self.rs_b] - qe[self.rs_a] - self.rs_th0)
            f += np.bincount(self.rs_idx, weights=np.concatenate([tau, -tau]), minlength=self.n + 1)
        return fg + f[: self.n]

    def potential(self, q: FloatArray) -> float:
        """Elastic energy of the springs."""
        V = 0.0
        if self.NS:
            d, _, _, _ = self._spring_kin(q, None)
            ell = np.hypot(d[0], d[1])
            V += float(np.sum(0.5 * self.sp_k * (ell - self.sp_L0) ** 2))
        if self.NR:
            qe = np.concatenate((q, _ZERO1))
            V += float(np.sum(0.5 * self.rs_k * (qe[self.rs_b] - qe[self.rs_a] - self.rs_th0) ** 2))
        return V

    def passive(self, q: FloatArray, qd: FloatArray) -> FloatArray:
        """Damper forces ``−c ℓ̇ Dᵀe`` and ``−c(θ̇_b − θ̇_a)``."""
        f = np.zeros(self.n + 1)
        if self.NS:
            d, dd, rspa, rspb = self._spring_kin(q, qd)
            ell2 = (d * d).sum(axis=0)
            pos = ell2 > 0.0
            coef = -self.sp_c * (d * dd).sum(axis=0) / np.where(pos, ell2, 1.0) * pos
            f += self._scatter(coef, d, rspa, rspb)
        if self.NR:
            ve = np.concatenate((qd, _ZERO1))
            tau = -self.rs_c * (ve[self.rs_b] - ve[self.rs_a])
            f += np.bincount(self.rs_idx, weights=np.concatenate([tau, -tau]), minlength=self.n + 1)
        return f[: self.n]


class Inputs:
    """The input matrix B: constant entries in a template, q-dependent ones computed vectorized.

    q-dependent columns: a point force on a rotating body off its origin (θ entry
    ``dirᵀ(R s)^⊥``) and a prismatic joint actuator (force along ``u = R_a axis`` on body b at
    ``p_b``, reaction on body a at the same point: θ_b entry ``u·(R_b s_b)^⊥``, θ_a entry
    ``−u·(p_b − r_a)^⊥``, x/y entries ``±u``).
    """

    def __init__(
        self,
        const: list[tuple[int, int, float]],
        forces: list[tuple[int, Point, tuple[float, float]]],
        prismatic: list[tuple[int, Point, Point, tuple[float, float]]],
        index: dict[str, tuple[int, int, int]],
        n: int,
        k: int,
    ) -> None:
        self.n, self.k = n, k

        def side(p: Point) -> _Side:
            if p.body == GROUND:
                return _Side(n, n, n, p.local[0], p.local[1])
            ix, iy, ith = index[p.body]
            return _Side(ix, iy, ith if ith >= 0 else n, p.local[0], p.local[1])

        def flat(i: int | IntArray, col: int | IntArray) -> IntArray:
            i_ = np.asarray(i, dtype=np.intp)
            return np.where(i_ < n, i_ * k + np.asarray(col, dtype=np.intp), n * k).astype(np.intp)

        buf = np.zeros(n * k + 1)
        for i, col, val in const:
            if i < n:
                buf[i * k + col] += val
        self.NF, self.NP = len(forces), len(prismatic)
        sides = [side(p) for _, p, _ in forces] + [side(a) for _, a, _, _ in prismatic]
        sides += [side(b) for _, _, b, _ in prismatic]
        self.I3, self.SL, self.SLp = _side_arrays(sides)
        fcol = np.array([c for c, _, _ in forces], dtype=np.intp)
        self.fdir = np.ascontiguousarray(np.array([d for _, _, d in forces], dtype=np.float64).reshape(-1, 2).T)
        nf, npr = self.NF, self.NP
        if nf:
            # constant x, y entries of the point forces
            for c_, sd, dr in zip(fcol, sides[:nf], self.fdir.T, strict=True):
                for i, val in ((sd.ix, dr[0]), (sd.iy, dr[1])):
                    if i < n:
                        buf[i * k + c_] += val
        pcol = np.array([c for c, _, _, _ in prismatic], dtype=np.intp)
        ax = np.ascontiguousarray(np.array([u for _, _, _, u in prismatic], dtype=np.float64).reshape(-1, 2).T)
        self.AX, self.AXp = ax, np.stack([-ax[1], ax[0]]).reshape(2, npr)
        ia, ib = self.I3[:, nf : nf + npr], self.I3[:, nf + npr :]
        parts = [flat(self.I3[2, :nf], fcol)]
        if npr:
            parts += [flat(ib[0], pcol), flat(ib[1], pcol), flat(ib[2], pcol)]
            parts += [flat(ia[0], pcol), flat(ia[1], pcol), flat(ia[2], pcol)]
        self.var_idx = np.concatenate(parts).astype(np.intp)
        real = self.var_idx[self.var_idx < n * k]
        self.var_unique = bool(np.unique(real).size == real.size)
        self.B0 = buf
        self.varies = bool(nf or npr)

    def matrix(self, q: FloatArray) -> FloatArray:
        """``B(q)``, shape (n, k)."""
        n, k = self.n, self.k
        buf = self.B0.copy()
        if self.varies:
            nf, npr = self.NF, self.NP
            qe = np.concatenate((q, _ZERO1))
            Q = qe[self.I3]
            c = np.cos(Q[2])
            s = np.sin(Q[2])
            rsp = c * self.SLp - s * self.SL
            vals = [(self.fdir * rsp[:, :nf]).sum(axis=0)]
            if npr:
                a_, b_ = slice(nf, nf + npr), slice(nf + npr, nf + 2 * npr)
                ca, sa = c[a_], s[a_]
                u = ca * self.AX + sa * self.AXp  # R_a axis
                rsb = c[b_] * self.SL[:, b_] + s[b_] * self.SLp[:, b_]
                lever = Q[:2, b_] + rsb - Q[:2, a_]  # p_b − r_a
                tb = (u * rsp[:, b_]).sum(axis=0)
                ta = -(u[0] * -lever[1] + u[1] * lever[0])
                vals.append(np.concatenate([u[0], u[1], tb, -u[0], -u[1], ta]))
            allv = np.concatenate(vals)
            if self.var_unique:
                buf[self.var_idx] += allv
            else:
                np.add.at(buf, self.var_idx, allv)
        return buf[: n * k].reshape(n, k)
