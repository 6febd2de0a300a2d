"""Andrews' squeezing mechanism (seven-body mechanism) as a hand-written model.

Source: E. Hairer, G. Wanner, *Solving Ordinary Differential Equations II*, 2nd ed., Springer
1996, §VII.7 (after Manning 1981 and Schiehlen's benchmark); F. Mazzia, C. Magherini, *Test Set
for IVP Solvers*, problem ``andrews`` (University of Bari). Data as in
``shared/benchmarks/README.md``.

Differences from the Test Set's index-3 formulation: no Lagrange multipliers (nonmin's
projection method); the velocity-dependent terms of the Test Set's ``f`` are represented by the
Christoffel matrix of the given ``M(q)`` (``C qd`` equals minus those terms, checked in the
tests); the spring and the constant motor torque are conservative: ``V = c0 (ℓ − l0)²/2 −
mom·β``, ``f_g = −∂V/∂q``.
"""

from __future__ import annotations

import json
import math
import weakref
from collections.abc import Iterable
from dataclasses import dataclass, fields
from importlib import resources
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from ..model import ConstraintSpec, ConstraintTerms, Model
from ..model._protocol import FloatArray, _as_vector
from ._registry import Mechanism, register

__all__ = ["ANDREWS_Q0", "ANDREWS_QDD0", "AndrewsModel", "a03_andrews"]

#: Consistent initial angles (Hairer–Wanner / Test Set), β Θ γ Φ δ Ω ε.
ANDREWS_Q0 = np.array([
    -0.0617138900142764496358948458001,
    0.0,
    0.455279819163070380255912382449,
    0.222668390165885884674473185609,
    0.487364979543842550225598953530,
    -0.222668390165885884674473185609,
    1.23054744454982119249735015568,
])
#: Initial accelerations of the Test Set (``y'(0)`` of the index-3 DAE).
ANDREWS_QDD0 = np.array([14222.4439199541138705911625887, -10666.8329399655854029433719415, 0, 0, 0, 0, 0])
#: Initial multipliers of the Test Set (``M q̈ = f − Gᵀλ``).
ANDREWS_LAMBDA0 = np.array([98.5668703962410896057654982170, -6.12268834425566265503114393122, 0, 0, 0, 0])

ANGLE_NAMES = ("beta", "Theta", "gamma", "Phi", "delta", "Omega", "epsilon")
LOOPS = (("loop_B", 0), ("loop_A1", 2), ("loop_A2", 4))
#: The three loop closures (built once: the engine's drivers ask for them at every call).
_CONSTRAINTS = (
    ConstraintSpec("loop_B", "holonomic", 2, "g1, g2: loop through B"),
    ConstraintSpec("loop_A1", "holonomic", 2, "g3, g4: loop through A (Φ, δ)"),
    ConstraintSpec("loop_A2", "holonomic", 2, "g5, g6: loop through A (Ω, ε)"),
)


@dataclass(frozen=True, eq=False)
class AndrewsModel(Model):
    """Andrews' squeezing mechanism in 7 relative angles, 6 holonomic constraints (1 DOF).

    Constraints ``loop_B`` (g1, g2), ``loop_A1`` (g3, g4), ``loop_A2`` (g5, g6); no gravity;
    motor torque ``mom`` on β and the spring ``c0, l0`` between C and D are conservative.
    Each ``g_i`` is a sum of terms ``a·cos(w·q)`` / ``a·sin(w·q)`` plus a constant, which
    gives ``A``, ``Ȧ`` and ``γ = Ȧ qd`` in closed form.
    """

    name: str = "A03_andrews"
    m: tuple[float, ...] = (0.04325, 0.00365, 0.02373, 0.00706, 0.07050, 0.00706, 0.05498)
    I: tuple[float, ...] = (2.194e-6, 4.410e-7, 5.255e-6, 5.667e-7, 1.169e-5, 5.667e-7, 1.912e-5)
    xa: float = -0.06934
    ya: float = -0.00227
    xb: float = -0.03635
    yb: float = 0.03273
    xc: float = 0.014
    yc: float = 0.072
    c0: float = 4530.0
    l0: float = 0.07785
    mom: float = 0.033
    d: float = 0.028
    da: float = 0.0115
    e: float = 0.02
    ea: float = 0.01421
    rr: float = 0.007
    ra: float = 0.00092
    ss: float = 0.035
    sa: float = 0.01874
    sb: float = 0.01043
    sc: float = 0.018
    sd: float = 0.02
    ta: float = 0.02308
    tb: float = 0.00916
    u: float = 0.04
    ua: float = 0.01228
    ub: float = 0.00449
    zf: float = 0.02
    zt: float = 0.04
    fa: float = 0.01421

    has_outputs = True

    def engine_program(self) -> Any:
        """The model as the engine's ``TapeProgram``: its M, h, A, γ, φ and V run compiled.

        The expression tape ships with the package (``nonmin/data/tapes/A03_andrews.json``, no
        SymPy at run time): it is :meth:`symbolic`'s tape, with every field of the model as a
        parameter input, so a :func:`dataclasses.replace` variant only changes the parameter
        values. ``nonmin.library._andrews.write_tape()`` writes it again (needs SymPy);
        ``tests/library/test_andrews_engine.py`` checks it against this class's own formulas
        and against a fresh SymPy compilation.
        """
        prog = _PROGRAMS.get(self)
        if prog is None:
            from .. import _engine  # type: ignore[attr-defined]  # the compiled extension

            tape = _shipped_tape()
            pvals = [_param_value(self, name) for name in tape["params"]]
            cons = [(c.name, 0, c.dim) for c in self.constraints]
            i32 = np.int32
            prog = _engine.TapeProgram(
                7, 0, cons, np.asarray(tape["op"], i32), np.asarray(tape["a"], i32),
                np.asarray(tape["b"], i32), np.asarray(tape["c"], float),
                np.asarray(tape["out_target"], i32), np.asarray(tape["out_index"], i32),
                np.asarray(tape["out_reg"], i32), pvals,
            )  # fmt: skip
            _PROGRAMS[self] = prog
        return prog

    def symbolic(self) -> Any:
        """The same model as a :class:`~nonmin.model.symbolic.SymbolicModel` (needs SymPy).

        M(q) as in :meth:`mass_matrix`, ``V = c0 (ℓ − l0)²/2 − mom·β``, the six closure
        residuals g1 … g6 as holonomic constraints (``loop_B``, ``loop_A1``, ``loop_A2``). Every
        field is a parameter: the tuples ``m`` and ``I`` as ``m0`` … ``m6``, ``I0`` … ``I6``,
        the scalars by their field names; the values are this model's.
        """
        import sympy as sp

        from ..model.symbolic import SymbolicConstraint, SymbolicModel

        names = _param_names()
        P = {name: sp.Symbol(name) for name in names}
        q = sp.symbols(" ".join(ANGLE_NAMES))
        be, th, ga, ph, de, om, ep = q
        m = [P[f"m{i}"] for i in range(7)]
        Ii = [P[f"I{i}"] for i in range(7)]
        ee, zz = P["e"] - P["ea"], P["zf"] - P["fa"]
        rr, da, zt, u = P["rr"], P["da"], P["zt"], P["u"]
        M = sp.zeros(7, 7)
        M[0, 0] = m[0] * P["ra"] ** 2 + m[1] * (rr**2 - 2 * da * rr * sp.cos(th) + da**2) + Ii[0] + Ii[1]
        M[1, 0] = M[0, 1] = m[1] * (da**2 - da * rr * sp.cos(th)) + Ii[1]
        M[1, 1] = m[1] * da**2 + Ii[1]
        M[2, 2] = m[2] * (P["sa"] ** 2 + P["sb"] ** 2) + Ii[2]
        M[3, 3] = m[3] * ee**2 + Ii[3]
        M[4, 3] = M[3, 4] = m[3] * (ee**2 + zt * ee * sp.sin(ph)) + Ii[3]
        M[4, 4] = m[3] * (zt**2 + 2 * zt * ee * sp.sin(ph) + ee**2) + m[4] * (P["ta"] ** 2 + P["tb"] ** 2) + Ii[3] + Ii[4]
        M[5, 5] = m[5] * zz**2 + Ii[5]
        M[6, 5] = M[5, 6] = m[5] * (zz**2 - u * zz * sp.sin(om)) + Ii[5]
        M[6, 6] = m[5] * (zz**2 - 2 * u * zz * sp.sin(om) + u**2) + m[6] * (P["ua"] ** 2 + P["ub"] ** 2) + Ii[5] + Ii[6]
        xd = P["sd"] * sp.cos(ga) + P["sc"] * sp.sin(ga) + P["xb"]
        yd = P["sd"] * sp.sin(ga) - P["sc"] * sp.cos(ga) + P["yb"]
        V = P["c0"] * (sp.sqrt((xd - P["xc"]) ** 2 + (yd - P["yc"]) ** 2) - P["l0"]) ** 2 / 2 - P["mom"] * be
        d, ss, e, zf = P["d"], P["ss"], P["e"], P["zf"]
        ex, ey = rr * sp.cos(be) - d * sp.cos(be + th), rr * sp.sin(be) - d * sp.sin(be + th)
        g = [
            ex - ss * sp.sin(ga) - P["xb"], ey + ss * sp.cos(ga) - P["yb"],
            ex - e * sp.sin(ph + de) - zt * sp.cos(de) - P["xa"], ey + e * sp.cos(ph + de) - zt * sp.sin(de) - P["ya"],
            ex - zf * sp.cos(om + ep) - u * sp.sin(ep) - P["xa"], ey - zf * sp.sin(om + ep) + u * sp.cos(ep) - P["ya"],
        ]  # fmt: skip
        cons = [SymbolicConstraint.holonomic(name, g[r0 : r0 + 2]) for name, r0 in LOOPS]
        params = {P[name]: _param_value(self, name) for name in names}
        return SymbolicModel.from_mass_matrix(self.name, q=q, M=M, V=V, constraints=cons, params=params)

    @property
    def coordinate_names(self) -> tuple[str, ...]:  # type: ignore[override]
        return ANGLE_NAMES

    @property
    def constraints(self) -> tuple[ConstraintSpec, ...]:  # type: ignore[override]
        return _CONSTRAINTS

    @property
    def actuator_names(self) -> tuple[str, ...]:  # type: ignore[override]
        return ()

    @property
    def default_active(self) -> frozenset[str]:  # type: ignore[override]
        return frozenset(("loop_B", "loop_A1", "loop_A2"))

    # ------------------------------------------------------------------ inertia
    def mass_matrix(self, q: ArrayLike) -> FloatArray:
        q = _as_vector(q, "q", 7)
        m1, m2, m3, m4, m5, m6, m7 = self.m
        i1, i2, i3, i4, i5, i6, i7 = self.I
        rr, da, ra, ea, e, zt = self.rr, self.da, self.ra, self.ea, self.e, self.zt
        zf, fa, u = self.zf, self.fa, self.u
        cth, sph, som = math.cos(q[1]), math.sin(q[3]), math.sin(q[5])
        M = np.zeros((7, 7))
        M[0, 0] = m1 * ra**2 + m2 * (rr**2 - 2 * da * rr * cth + da**2) + i1 + i2
        M[1, 0] = M[0, 1] = m2 * (da**2 - da * rr * cth) + i2
        M[1, 1] = m2 * da**2 + i2
        M[2, 2] = m3 * (self.sa**2 + self.sb**2) + i3
        M[3, 3] = m4 * (e - ea) ** 2 + i4
        M[4, 3] = M[3, 4] = m4 * ((e - ea) ** 2 + zt * (e - ea) * sph) + i4
        M[4, 4] = m4 * (zt**2 + 2 * zt * (e - ea) * sph + (e - ea) ** 2) + m5 * (self.ta**2 + self.tb**2) + i4 + i5
        M[5, 5] = m6 * (zf - fa) ** 2 + i6
        M[6, 5] = M[5, 6] = m6 * ((zf - fa) ** 2 - u * (zf - fa) * som) + i6
        M[6, 6] = m6 * ((zf - fa) ** 2 - 2 * u * (zf - fa) * som + u**2) + m7 * (self.ua**2 + self.ub**2) + i6 + i7
        return M

    def mass_matrix_derivative(self, q: ArrayLike) -> FloatArray:
        """``T[k] = ∂M/∂q_k``, shape (7, 7, 7) (analytic)."""
        q = _as_vector(q, "q", 7)
        m2, m4, m6 = self.m[1], self.m[3], self.m[5]
        T = np.zeros((7, 7, 7))
        a = m2 * self.da * self.rr * math.sin(q[1])
        T[1, 0, 0] = 2 * a
        T[1, 0, 1] = T[1, 1, 0] = a
        b = m4 * self.zt * (self.e - self.ea) * math.cos(q[3])
        T[3, 3, 4] = T[3, 4, 3] = b
        T[3, 4, 4] = 2 * b
        c = -m6 * self.u * (self.zf - self.fa) * math.cos(q[5])
        T[5, 5, 6] = T[5, 6, 5] = c
        T[5, 6, 6] = 2 * c
        return T

    def coriolis_matrix(self, q: ArrayLike, qd: ArrayLike) -> FloatArray:
        """Christoffel matrix ``C_ij = ½ Σ_k (∂_k M_ij + ∂_j M_ik − ∂_i M_jk) qd_k``."""
        v = _as_vector(qd, "qd", 7)
        T = self.mass_matrix_derivative(q)
        t1 = np.einsum("kij,k->ij", T, v)
        t2 = np.einsum("jik,k->ij", T, v)
        t3 = np.einsum("ijk,k->ij", T, v)
        return 0.5 * (t1 + t2 - t3)

    # ------------------------------------------------------------------ forces
    def _spring(self, q: FloatArray) -> tuple[float, float, float]:
        """``(ℓ, ∂ℓ/∂γ, x_D, ...)``: spring length and its derivative in γ."""
        cg, sg = math.cos(q[2]), math.sin(q[2])
        xd = self.sd * cg + self.sc * sg + self.xb
        yd = self.sd * sg - self.sc * cg + self.yb
        dxd = -self.sd * sg + self.sc * cg
        dyd = self.sd * cg + self.sc * sg
        ell = math.hypot(xd - self.xc, yd - self.yc)
        dell = ((xd - self.xc) * dxd + (yd - self.yc) * dyd) / ell
        return ell, dell, 0.0

    def conservative_force(self, q: ArrayLike) -> FloatArray:
        qv = _as_vector(q, "q", 7)
        ell, dell, _ = self._spring(qv)
        f = np.zeros(7)
        f[0] = self.mom
        f[2] = -self.c0 * (ell - self.l0) * dell
        return f

    def potential_energy(self, q: ArrayLike) -> float:
        qv = _as_vector(q, "q", 7)
        ell, _, _ = self._spring(qv)
        return 0.5 * self.c0 * (ell - self.l0) ** 2 - self.mom * float(qv[0])

    # ------------------------------------------------------------------ constraints
    def _terms(self) -> list[tuple[int, float, str, tuple[int, ...]]]:
        """Rows as sums of ``coef·f(Σ q[idx])``: (row, coef, 'cos'|'sin', idx)."""
        rr, d, ss, e, zt, zf, u = self.rr, self.d, self.ss, self.e, self.zt, self.zf, self.u
        out: list[tuple[int, float, str, tuple[int, ...]]] = []
        for r in (0, 2, 4):  # x rows share the crank part
            out += [(r, rr, "cos", (0,)), (r, -d, "cos", (0, 1))]
        for r in (1, 3, 5):
            out += [(r, rr, "sin", (0,)), (r, -d, "sin", (0, 1))]
        out += [
            (0, -ss, "sin", (2,)),
            (1, ss, "cos", (2,)),
            (2, -e, "sin", (3, 4)),
            (2, -zt, "cos", (4,)),
            (3, e, "cos", (3, 4)),
            (3, -zt, "sin", (4,)),
            (4, -zf, "cos", (5, 6)),
            (4, -u, "sin", (6,)),
            (5, -zf, "sin", (5, 6)),
            (5, u, "cos", (6,)),
        ]
        return out

    def _constraint_all(self, q: FloatArray, qd: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """φ (6,), A (6, 7), Ȧ (6, 7), γ (6,) of all six rows."""
        phi = -np.array([self.xb, self.yb, self.xa, self.ya, self.xa, self.ya])
        A = np.zeros((6, 7))
        Ad = np.zeros((6, 7))
        gamma = np.zeros(6)
        for row, coef, fn, idx in self._terms():
            s = float(sum(q[i] for i in idx))
            sd = float(sum(qd[i] for i in idx))
            c, si = math.cos(s), math.sin(s)
            if fn == "cos":  # f = cos, f' = −sin, f'' = −cos
                val, d1, d2 = c, -si, -c
            else:  # f = sin, f' = cos, f'' = −sin
                val, d1, d2 = si, c, -si
            phi[row] += coef * val
            for i in idx:
                A[row, i] += coef * d1
                Ad[row, i] += coef * d2 * sd
            gamma[row] += coef * d2 * sd * sd
        return phi, A, Ad, gamma

    def _rows(self, active: Iterable[str] | None) -> list[int]:
        act = self.resolve_active(active)
        rows: list[int] = []
        for name, r0 in LOOPS:
            if name in act:
                rows += [r0, r0 + 1]
        return rows

    def constraint_terms(
        self, t: float, q: ArrayLike, qd: ArrayLike, active: Iterable[str] | None = None
    ) -> ConstraintTerms:
        qv = _as_vector(q, "q", 7)
        v = _as_vector(qd, "qd", 7)
        rows = self._rows(active)
        phi, A, _, gamma = self._constraint_all(qv, v)
        A = A[rows]
        return ConstraintTerms(A, gamma[rows], phi[rows], A @ v, np.ones(len(rows), dtype=bool))

    def constraint_jacobian_dot(
        self, t: float, q: ArrayLike, qd: ArrayLike, active: Iterable[str] | None = None
    ) -> FloatArray:
        qv = _as_vector(q, "q", 7)
        v = _as_vector(qd, "qd", 7)
        return self._constraint_all(qv, v)[2][self._rows(active)]

    # ------------------------------------------------------------------ Test Set form
    def testset_force(self, q: ArrayLike, qd: ArrayLike) -> FloatArray:
        """The Test Set's right-hand side ``f(q, qd)`` (velocity terms, spring, motor), shape (7,)."""
        qv = _as_vector(q, "q", 7)
        v = _as_vector(qd, "qd", 7)
        m2, m4, m6 = self.m[1], self.m[3], self.m[5]
        bep, thp, _, php, dep, omp, epp = v
        sth, cph, com = math.sin(qv[1]), math.cos(qv[3]), math.cos(qv[5])
        cg, sg = math.cos(qv[2]), math.sin(qv[2])
        xd = self.sd * cg + self.sc * sg + self.xb
        yd = self.sd * sg - self.sc * cg + self.yb
        ell = math.hypot(xd - self.xc, yd - self.yc)
        force = -self.c0 * (ell - self.l0) / ell
        fx, fy = force * (xd - self.xc), force * (yd - self.yc)
        ee, zz = self.e - self.ea, self.zf - self.fa
        return np.array([
            self.mom - m2 * self.da * self.rr * thp * (thp + 2 * bep) * sth,
            m2 * self.da * self.rr * bep**2 * sth,
            fx * (self.sc * cg - self.sd * sg) + fy * (self.sd * cg + self.sc * sg),
            m4 * self.zt * ee * dep**2 * cph,
            -m4 * self.zt * ee * php * (php + 2 * dep) * cph,
            -m6 * self.u * zz * epp**2 * com,
            m6 * self.u * zz * omp * (omp + 2 * epp) * com,
        ])

    def outputs(self, t: float, q: ArrayLike, qd: ArrayLike) -> dict[str, FloatArray]:
        qv = _as_vector(q, "q", 7)
        v = _as_vector(qd, "qd", 7)
        out = {name: np.array(qv[i]) for i, name in enumerate(ANGLE_NAMES)}
        out["angles"] = qv.copy()
        out["rates"] = v.copy()
        out["F.position"] = self.rr * np.array([math.cos(qv[0]), math.sin(qv[0])])
        return out


#: Engine programs of live models (built on first use; not part of a model's value or pickle).
_PROGRAMS: weakref.WeakKeyDictionary[AndrewsModel, Any] = weakref.WeakKeyDictionary()
_TAPE: list[dict[str, Any]] = []
TAPE_FILE = "A03_andrews.json"


def _param_names() -> list[str]:
    """The tape's parameter inputs: ``m0`` … ``m6``, ``I0`` … ``I6``, then the scalar fields."""
    out: list[str] = []
    for f in fields(AndrewsModel):
        if f.name == "name":
            continue
        if f.name in ("m", "I"):
            out += [f"{f.name}{i}" for i in range(7)]
        else:
            out.append(f.name)
    return out


def _param_value(model: AndrewsModel, name: str) -> float:
    if name[0] in "mI" and name[1:].isdigit():
        return float(getattr(model, name[0])[int(name[1:])])
    return float(getattr(model, name))


def _shipped_tape() -> dict[str, Any]:
    """The tape of :meth:`AndrewsModel.symbolic` as shipped (read once; plain JSON, no code)."""
    if not _TAPE:
        text = resources.files("nonmin").joinpath("data", "tapes", TAPE_FILE).read_text("utf-8")
        tape = json.loads(text)
        if sorted(tape.get("params", ())) != sorted(_param_names()):
            raise RuntimeError(
                f"nonmin/data/tapes/{TAPE_FILE} does not match AndrewsModel's fields: regenerate it "
                "with nonmin.library._andrews.write_tape()"
            )
        _TAPE.append(tape)
    return _TAPE[0]


def tape_record(model: AndrewsModel | None = None) -> dict[str, Any]:
    """:meth:`AndrewsModel.symbolic`'s expression tape as the JSON record that ships (needs SymPy)."""
    from ..model.symbolic._model import _tape_of

    sym = (model or AndrewsModel()).symbolic()
    tape = _tape_of(sym.compiled)
    if tape is None:  # pragma: no cover - every function of the model is on the tape
        raise RuntimeError("the Andrews model did not compile to a tape")
    return {
        "model": "A03_andrews",
        "generator": "nonmin.library._andrews.write_tape() (AndrewsModel.symbolic(), nonmin.model.symbolic._tape)",
        "n_inputs": int(tape.n_inputs),
        "params": [str(s) for s in sym.compiled.param_symbols],  # the tape's input order
        **{k: getattr(tape, k).tolist() for k in ("op", "a", "b", "c", "out_target", "out_index", "out_reg")},
    }


@register("A03_andrews")
def a03_andrews(*, t_final: float = 0.03) -> Mechanism:
    """Andrews' squeezing mechanism (IFToMM A03; Hairer–Wanner II §VII.7; Test Set ``andrews``).

    Sources: E. Hairer, G. Wanner, *Solving ODEs II* (Springer 1996), §VII.7; F. Mazzia,
    C. Magherini, *Test Set for IVP Solvers*, problem ``andrews``. Initial state: the Test
    Set's consistent ``q0`` at rest. Horizon 0.03 s (Test Set; the IFToMM variant uses 0.05 s
    and outputs ``F.position``). Outputs: the seven angles by name (``beta``, ``Theta``,
    ``gamma``, ``Phi``, ``delta``, ``Omega``, ``epsilon``), ``angles``, ``rates``,
    ``F.position``.
    """
    model = AndrewsModel()
    return Mechanism(
        model=model,
        state=model.state(ANDREWS_Q0, np.zeros(7)),
        t_final=float(t_final),
        description="Andrews' squeezing mechanism: 7 bodies, 7 relative angles, 6 holonomic constraints",
        reference=(
            "Hairer & Wanner, Solving ODEs II (1996) §VII.7; Mazzia & Magherini, Test Set for IVP "
            "Solvers, problem andrews; IFToMM benchmark A03"
        ),
    )



def write_tape(path: str | None = None) -> str:
    """Write :func:`tape_record` to the shipped file (or ``path``); returns the path (needs SymPy).

    Run after changing :meth:`AndrewsModel.symbolic` or the tape compiler:
    ``python -c "from nonmin.library._andrews import write_tape; print(write_tape())"``.
    """
    from pathlib import Path

    out = Path(path) if path is not None else Path(__file__).resolve().parents[1] / "data" / "tapes" / TAPE_FILE
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(tape_record(), separators=(",", ":")) + "\n", encoding="utf-8")
    return str(out)
