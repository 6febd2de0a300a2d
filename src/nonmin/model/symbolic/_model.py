"""Model source 3: SymPy expressions → a numeric :class:`~nonmin.model.Model`.

The user gives, in terms of coordinate symbols ``q``, velocity symbols ``qd``, an optional
time symbol ``t`` and parameter symbols with numeric values:

* either the kinetic energy ``T(q, qd)`` (a homogeneous quadratic form in ``qd``) or the
  inertia matrix ``M(q)``, and the potential energy ``V(q)``;
* named constraints (:class:`SymbolicConstraint`): holonomic ``φ(q)``, rheonomic ``φ(q, t)``,
  nonholonomic rows ``A(q)`` (``A qd = 0``), unilateral gaps ``g(q) ≥ 0``;
* optionally an input matrix ``B(q)``, passive forces ``f_p(t, q, qd)`` and output
  expressions.

Everything the protocol needs is derived symbolically and compiled once with
``sympy.lambdify(..., cse=True)`` (common-subexpression elimination)::

    M = ∂²T/∂qd²,   C_ij = Σ_k ½(∂M_ij/∂q_k + ∂M_ik/∂q_j − ∂M_jk/∂q_i) qd_k   (Christoffel),
    f_g = −∂V/∂q,   A = ∂φ/∂q,   φ_t = ∂φ/∂t,   Ȧ = Σ_k ∂A/∂q_k qd_k + ∂A/∂t,
    γ = ∂(A qd + φ_t)/∂q · qd + ∂(A qd + φ_t)/∂t  (= Ȧ qd + 2 φ_tq qd + φ_tt).

Parameters are arguments of the compiled functions, so :meth:`SymbolicModel.replace` with new
``params`` values costs nothing (no re-derivation, no re-compilation).

SymPy is imported only inside this package, on first use; without it a
:class:`~nonmin.errors.MissingDependencyError` names the extra ``sympy``.
"""

from __future__ import annotations

import weakref
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from ...errors import InputError, ModelError, UnknownNameError, missing_dependency
from .._protocol import (
    CONSTRAINT_KINDS,
    ConstraintKind,
    ConstraintSpec,
    ConstraintTerms,
    FloatArray,
    Model,
    _as_vector,
)

__all__ = ["SymbolicConstraint", "SymbolicModel"]

#: Tolerance of the numeric check that T is a homogeneous quadratic form in qd.
QUADRATIC_CHECK_RTOL = 1e-9


def _sympy() -> Any:
    try:
        import sympy
    except ImportError:
        raise missing_dependency("sympy", "sympy", "the symbolic model source") from None
    return sympy


@dataclass(frozen=True, eq=False)
class SymbolicConstraint:
    """A named constraint given by SymPy expressions. Build it with the named constructors.

    Attributes
    ----------
    name : str
    kind : {"holonomic", "rheonomic", "nonholonomic", "unilateral"}
    expr : sympy expression or sequence of expressions
        φ rows (holonomic, rheonomic, unilateral) or the rows of ``A(q)`` (nonholonomic,
        a sequence of length-n rows).
    description : str
    """

    name: str
    kind: ConstraintKind
    expr: Any
    description: str = ""

    @classmethod
    def holonomic(cls, name: str, phi: Any, *, description: str = "") -> SymbolicConstraint:
        """``φ(q) = 0`` (a scalar expression or a sequence of them)."""
        return cls(name, "holonomic", phi, description)

    @classmethod
    def rheonomic(cls, name: str, phi: Any, *, description: str = "") -> SymbolicConstraint:
        """``φ(q, t) = 0`` (driving constraint; uses the model's time symbol)."""
        return cls(name, "rheonomic", phi, description)

    @classmethod
    def nonholonomic(cls, name: str, rows: Any, *, description: str = "") -> SymbolicConstraint:
        """Pfaffian ``A(q) qd = 0``; ``rows`` is one length-n row or a sequence of rows."""
        return cls(name, "nonholonomic", rows, description)

    @classmethod
    def unilateral(cls, name: str, gap: Any, *, description: str = "") -> SymbolicConstraint:
        """``gap(q) ≥ 0`` (one scalar expression); an equality while active."""
        return cls(name, "unilateral", gap, description)


@dataclass(frozen=True, eq=False)
class _Compiled:
    """Symbolic expressions and their compiled (lambdified) functions; shared by replace()."""

    q: tuple[Any, ...]
    qd: tuple[Any, ...]
    t: Any
    param_symbols: tuple[Any, ...]
    M: Any
    C: Any
    fg: Any
    V: Any
    B: Any
    specs: tuple[ConstraintSpec, ...]
    rows: tuple[slice, ...]
    A: Any
    phi: Any
    phi_t: Any
    Adot: Any
    gamma: Any
    passive: Any
    outputs: Mapping[str, Any]
    shapes: Mapping[str, tuple[int, ...]]
    fn: Mapping[str, Callable[..., Any]]
    exprs: Mapping[str, Any]

    # lambdified functions do not pickle: drop them and compile again on unpickling
    def __getstate__(self) -> dict[str, Any]:
        state = dict(self.__dict__)
        state["fn"] = None
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        args = [state["t"], list(state["q"]), list(state["qd"]), list(state["param_symbols"])]
        state["fn"] = _lambdify_all(args, state["exprs"])
        self.__dict__.update(state)


def _lambdify_all(args: list[Any], exprs: Mapping[str, Any]) -> dict[str, Callable[..., Any]]:
    """``sympy.lambdify(..., cse=True)`` of every non-empty expression."""
    sp = _sympy()
    return {
        key: sp.lambdify(args, e, modules="numpy", cse=True)
        for key, e in exprs.items()
        if 0 not in e.shape
    }


def _no_strings(x: Any, what: str, _depth: int = 0) -> None:
    """Refuse strings anywhere in a SymPy input: ``sympify`` of a string runs ``eval`` on it
    (``T="__import__('os').system(...)"`` would run a command). Build expressions from
    SymPy symbols instead (``sympy.symbols``, ``sympy.Matrix``)."""
    if isinstance(x, str | bytes):
        raise InputError(
            f"{what} must be a SymPy expression (or numbers), not the string {str(x)[:60]!r}: "
            "strings are parsed with eval by sympify, so nonmin does not accept them; build it "
            "from sympy.symbols"
        )
    if _depth > 8:
        return
    if isinstance(x, dict):
        for k, v in x.items():
            _no_strings(v, f"{what}[{k!r}]", _depth + 1)
    elif isinstance(x, list | tuple):
        for i, v in enumerate(x):
            _no_strings(v, f"{what}[{i}]", _depth + 1)


def _as_matrix(sp: Any, x: Any, what: str) -> Any:
    try:
        m = sp.Matrix(x)
    except (TypeError, ValueError, sp.SympifyError) as exc:
        raise ModelError(f"{what} must be a SymPy expression or matrix, got {x!r}: {exc}") from None
    return m


def _check_symbols(expr: Any, allowed: set[Any], what: str) -> None:
    extra = set(expr.free_symbols) - allowed
    if extra:
        raise ModelError(
            f"{what} depends on symbol(s) {sorted(map(str, extra))} that are neither coordinates, "
            f"velocities, time nor parameters with values (give them in params=)"
        )


def _compile(
    *,
    q: Sequence[Any],
    qd: Sequence[Any],
    t: Any,
    params: Mapping[Any, float],
    M: Any,
    V: Any,
    constraints: Sequence[SymbolicConstraint],
    B: Any,
    passive: Any,
    outputs: Mapping[str, Any],
) -> tuple[_Compiled, FloatArray]:
    sp = _sympy()
    n = len(q)
    q_t = tuple(q)
    qd_t = tuple(qd)
    psyms = tuple(sorted(params, key=str))
    pvals = np.array([float(params[s]) for s in psyms], dtype=float)
    base = set(q_t) | set(psyms)
    allowed_q = base
    allowed_all = base | set(qd_t) | {t}
    _check_symbols(M, allowed_q, "M(q)")
    Vm = _as_matrix(sp, [V], "V")
    _check_symbols(Vm, allowed_q, "V(q)")
    fg = -Vm.jacobian(q_t).T
    dM = [M.diff(qk) for qk in q_t]
    C = sp.zeros(n, n)
    for i in range(n):
        for j in range(n):
            C[i, j] = sum(
                sp.Rational(1, 2) * (dM[k][i, j] + dM[j][i, k] - dM[i][j, k]) * qd_t[k]
                for k in range(n)
            )
    qdv = sp.Matrix(qd_t)
    # constraints, stacked
    specs: list[ConstraintSpec] = []
    rows: list[slice] = []
    A_rows: list[Any] = []
    phi_rows: list[Any] = []
    phit_rows: list[Any] = []
    r = 0
    names = set()
    for c in constraints:
        if not isinstance(c, SymbolicConstraint):
            raise InputError(f"constraints must be SymbolicConstraint values, got {type(c).__name__}")
        if c.kind not in CONSTRAINT_KINDS:
            raise InputError(f"constraint {c.name!r}: unknown kind {c.kind!r}")
        if c.name in names:
            raise ModelError(f"duplicate constraint name {c.name!r}")
        names.add(c.name)
        what = f"constraint {c.name!r}"
        if c.kind == "nonholonomic":
            Ac = _as_matrix(sp, c.expr, what)
            if Ac.shape[1] != n and Ac.shape == (n, 1):
                Ac = Ac.T
            if Ac.shape[1] != n:
                raise ModelError(f"{what}: rows must have length n = {n}, got shape {Ac.shape}")
            _check_symbols(Ac, base | {t}, what)
            phic = sp.zeros(Ac.shape[0], 1)
            phitc = sp.zeros(Ac.shape[0], 1)
        else:
            expr = c.expr if isinstance(c.expr, list | tuple) else [c.expr]
            phic = _as_matrix(sp, list(expr), what)
            if phic.shape[1] != 1:
                phic = phic.reshape(phic.shape[0] * phic.shape[1], 1)
            if c.kind == "unilateral" and phic.shape[0] != 1:
                raise ModelError(f"{what}: a unilateral constraint has one row, got {phic.shape[0]}")
            _check_symbols(phic, base | ({t} if c.kind == "rheonomic" else set()), what)
            Ac = phic.jacobian(q_t)
            phitc = phic.diff(t)
        d = Ac.shape[0]
        specs.append(ConstraintSpec(c.name, c.kind, d, c.description))
        rows.append(slice(r, r + d))
        r += d
        A_rows.append(Ac)
        phi_rows.append(phic)
        phit_rows.append(phitc)
    m = r
    A = sp.Matrix.vstack(*A_rows) if A_rows else sp.zeros(0, n)
    phi = sp.Matrix.vstack(*phi_rows) if phi_rows else sp.zeros(0, 1)
    phi_t = sp.Matrix.vstack(*phit_rows) if phit_rows else sp.zeros(0, 1)
    Adot = sp.zeros(m, n)
    gamma = sp.zeros(m, 1)
    if m:
        Adot = sum((A.diff(qk) * qdk for qk, qdk in zip(q_t, qd_t)), sp.zeros(m, n)) + A.diff(t)
        vel = A * qdv + phi_t
        gamma = vel.jacobian(q_t) * qdv + vel.diff(t)
    if B is not None:
        Bm = _as_matrix(sp, B, "B")
        if Bm.shape[0] != n:
            raise ModelError(f"B must have n = {n} rows, got shape {Bm.shape}")
        _check_symbols(Bm, allowed_q, "B(q)")
    else:
        Bm = sp.zeros(n, 0)
    if passive is not None:
        Pm = _as_matrix(sp, passive, "passive")
        if Pm.shape != (n, 1):
            raise ModelError(f"passive must be a length-{n} vector, got shape {Pm.shape}")
        _check_symbols(Pm, allowed_all, "passive(t, q, qd)")
    else:
        Pm = sp.zeros(n, 1)
    out_exprs: dict[str, Any] = {}
    for name, e in outputs.items():
        om = _as_matrix(sp, e if isinstance(e, list | tuple) else [e], f"output {name!r}")
        _check_symbols(om, allowed_all, f"output {name!r}")
        out_exprs[str(name)] = om
    args = [t, list(q_t), list(qd_t), list(psyms)]
    exprs: dict[str, Any] = {
        "M": M,
        "C": C,
        "fg": fg,
        "V": Vm,
        "B": Bm,
        "A": A,
        "phi": phi,
        "phi_t": phi_t,
        "Adot": Adot,
        "gamma": gamma,
        "passive": Pm,
    }
    exprs.update({f"out:{k}": v for k, v in out_exprs.items()})
    shapes = {key: tuple(e.shape) for key, e in exprs.items()}
    fn = _lambdify_all(args, exprs)
    comp = _Compiled(
        q=q_t,
        qd=qd_t,
        t=t,
        param_symbols=psyms,
        M=M,
        C=C,
        fg=fg,
        V=Vm[0, 0],
        B=Bm,
        specs=tuple(specs),
        rows=tuple(rows),
        A=A,
        phi=phi,
        phi_t=phi_t,
        Adot=Adot,
        gamma=gamma,
        passive=Pm,
        outputs=out_exprs,
        shapes=shapes,
        fn=fn,
        exprs=exprs,
    )
    return comp, pvals


@dataclass(frozen=True, eq=False)
class SymbolicModel(Model):
    """A numeric model compiled from SymPy expressions (build it with the named constructors).

    Use :meth:`from_energy` (``T`` and ``V``) or :meth:`from_mass_matrix` (``M`` and ``V``).
    ``replace(params={...})`` changes parameter values without recompiling.

    Attributes
    ----------
    name : str
    coordinate_names : tuple of str
    actuator_names : tuple of str
    params : dict of str to float
        Parameter values by symbol name.
    default_active_names : frozenset of str or None
        None: every non-unilateral constraint.
    compiled : _Compiled
        Symbolic expressions (``compiled.M``, ``compiled.C``, ...) and compiled functions.

    Examples
    --------
    A pendulum of length ``l`` in Cartesian coordinates:

    >>> import sympy as sp
    >>> from nonmin.model.symbolic import SymbolicConstraint, SymbolicModel
    >>> x, y, xd, yd, m, g, l = sp.symbols("x y xd yd m g l")
    >>> model = SymbolicModel.from_energy(
    ...     "pendulum", q=[x, y], qd=[xd, yd], T=m * (xd**2 + yd**2) / 2, V=m * g * y,
    ...     constraints=[SymbolicConstraint.holonomic("rod", (x**2 + y**2 - l**2) / 2)],
    ...     params={m: 1.0, g: 9.81, l: 1.0})
    >>> model.constraint_terms(0.0, [1.0, 0.0], [0.0, 2.0]).gamma
    array([4.])
    """

    name: str
    coordinate_names: tuple[str, ...]
    compiled: _Compiled
    params: dict[str, float]
    actuator_names: tuple[str, ...] = ()
    default_active_names: frozenset[str] | None = None
    _pvals: FloatArray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        names = [str(s) for s in self.compiled.param_symbols]
        if set(self.params) != set(names):
            missing = sorted(set(names) - set(self.params))
            unknown = sorted(set(self.params) - set(names))
            raise UnknownNameError(
                f"params: missing {missing}, unknown {unknown}; parameters of model "
                f"{self.name!r}: {names}"
            )
        vals = np.array([float(self.params[s]) for s in names], dtype=float)
        if not np.isfinite(vals).all():
            raise ModelError(f"parameter values must be finite, got {self.params}")
        object.__setattr__(self, "_pvals", vals)
        if len(self.actuator_names) != self.compiled.shapes["B"][1]:
            raise ModelError(
                f"actuator_names has {len(self.actuator_names)} names but B has "
                f"{self.compiled.shapes['B'][1]} columns"
            )
        if self.default_active_names is not None:
            self.resolve_active(self.default_active_names)

    # ------------------------------------------------------------------ constructors
    @classmethod
    def from_energy(
        cls,
        name: str,
        *,
        q: Sequence[Any],
        qd: Sequence[Any],
        T: Any,
        V: Any,
        constraints: Iterable[SymbolicConstraint] = (),
        params: Mapping[Any, float] | None = None,
        t: Any = None,
        B: Any = None,
        actuator_names: Iterable[str] = (),
        passive: Any = None,
        outputs: Mapping[str, Any] | None = None,
        default_active: Iterable[str] | None = None,
    ) -> SymbolicModel:
        """Model from the kinetic energy ``T(q, qd)`` and potential energy ``V(q)``.

        Parameters
        ----------
        name : str
        q, qd : sequence of sympy.Symbol, length n
            Coordinate and velocity symbols (coordinate names are ``str(q_i)``).
        T : sympy expression
            Kinetic energy, a homogeneous quadratic form in ``qd``: ``M = ∂²T/∂qd²``.
        V : sympy expression
            Potential energy ``V(q)`` (gravity, springs): ``f_g = −∂V/∂q``.
        constraints : iterable of SymbolicConstraint
        params : mapping of sympy.Symbol (or name) to float
            Values of every other free symbol.
        t : sympy.Symbol, optional
            Time symbol of rheonomic constraints/passive forces (default ``Symbol("t")``).
        B : sympy matrix, shape (n, k), optional
            Input matrix ``B(q)``; ``actuator_names`` names its columns.
        passive : sequence of n expressions, optional
            Passive non-conservative forces ``f_p(t, q, qd)`` (dampers).
        outputs : mapping of str to expression(s), optional
            Named outputs in ``t, q, qd``.
        default_active : iterable of str, optional
            Default: every non-unilateral constraint.

        Raises
        ------
        ModelError
            T not quadratic in qd, unknown free symbols, wrong shapes.
        MissingDependencyError
            SymPy is not installed.
        """
        sp = _sympy()
        for arg, val in (("T", T), ("V", V), ("B", B), ("passive", passive), ("outputs", outputs),
                         ("q", q), ("qd", qd), ("t", t)):
            _no_strings(val, f"from_energy: {arg}")
        qd_t = tuple(qd)
        if len(qd_t) != len(tuple(q)):
            raise ModelError(f"q and qd must have the same length, got {len(tuple(q))} and {len(qd_t)}")
        Texpr = sp.sympify(T)
        M = sp.hessian(Texpr, qd_t)
        if set(M.free_symbols) & set(qd_t):
            raise ModelError("T must be a homogeneous quadratic form in qd (M depends on qd)")
        model = cls._build(name, q, qd_t, M, V, constraints, params, t, B, actuator_names,
                           passive, outputs, default_active)
        # T − ½ qdᵀ M qd must vanish (no terms linear in qd or independent of qd)
        rest = Texpr - (sp.Matrix(qd_t).T * M * sp.Matrix(qd_t))[0, 0] / 2
        psyms = model.compiled.param_symbols
        f = sp.lambdify([list(q), list(qd_t), list(psyms)], [rest, Texpr], modules="numpy")
        rng = np.random.default_rng(0)
        for _ in range(3):
            qv = rng.normal(size=len(qd_t))
            vv = rng.normal(size=len(qd_t))
            r, tv = (float(x) for x in f(qv, vv, model._pvals))
            if abs(r) > QUADRATIC_CHECK_RTOL * max(1.0, abs(tv)):
                raise ModelError(
                    "T must be a homogeneous quadratic form in qd: T − ½ qdᵀ M qd = "
                    f"{r:.3g} ≠ 0 at a random state"
                )
        return model

    @classmethod
    def from_mass_matrix(
        cls,
        name: str,
        *,
        q: Sequence[Any],
        M: Any,
        V: Any,
        qd: Sequence[Any] | None = None,
        constraints: Iterable[SymbolicConstraint] = (),
        params: Mapping[Any, float] | None = None,
        t: Any = None,
        B: Any = None,
        actuator_names: Iterable[str] = (),
        passive: Any = None,
        outputs: Mapping[str, Any] | None = None,
        default_active: Iterable[str] | None = None,
    ) -> SymbolicModel:
        """Model from the inertia matrix ``M(q)`` (symmetric, n × n) and ``V(q)``.

        ``qd`` symbols are created (``<q>_dot``) when not given; the other parameters are as
        in :meth:`from_energy`.
        """
        sp = _sympy()
        for arg, val in (("M", M), ("V", V), ("B", B), ("passive", passive), ("outputs", outputs),
                         ("q", q), ("qd", qd), ("t", t)):
            _no_strings(val, f"from_mass_matrix: {arg}")
        q_t = tuple(q)
        n = len(q_t)
        Mm = _as_matrix(sp, M, "M")
        if Mm.shape != (n, n):
            raise ModelError(f"M must have shape ({n}, {n}), got {Mm.shape}")
        if (Mm - Mm.T).applyfunc(sp.expand) != sp.zeros(n, n):
            raise ModelError("M must be symmetric")
        qd_t = tuple(qd) if qd is not None else tuple(sp.Symbol(f"{s}_dot") for s in q_t)
        if len(qd_t) != n:
            raise ModelError(f"qd must have length {n}, got {len(qd_t)}")
        return cls._build(name, q_t, qd_t, Mm, V, constraints, params, t, B, actuator_names,
                          passive, outputs, default_active)

    @classmethod
    def _build(
        cls,
        name: str,
        q: Sequence[Any],
        qd: Sequence[Any],
        M: Any,
        V: Any,
        constraints: Iterable[SymbolicConstraint],
        params: Mapping[Any, float] | None,
        t: Any,
        B: Any,
        actuator_names: Iterable[str],
        passive: Any,
        outputs: Mapping[str, Any] | None,
        default_active: Iterable[str] | None,
    ) -> SymbolicModel:
        sp = _sympy()
        q_t = tuple(q)
        if not q_t:
            raise ModelError("q must name at least one coordinate symbol")
        for s in (*q_t, *qd):
            if not isinstance(s, sp.Symbol):
                raise ModelError(f"q and qd must be sympy Symbols, got {s!r}")
        if len(set(q_t) | set(qd)) != 2 * len(q_t):
            raise ModelError("q and qd symbols must be distinct")
        tsym = sp.Symbol("t") if t is None else t
        # parameters: keys may be symbols or names; match names against free symbols
        pmap: dict[Any, float] = {}
        free: set[Any] = set(M.free_symbols) | set(sp.sympify(V).free_symbols)
        cons = tuple(constraints)
        for c in cons:
            if isinstance(c, SymbolicConstraint):
                _no_strings(c.expr, f"constraint {c.name!r}")
                free |= set(_as_matrix(sp, c.expr if isinstance(c.expr, list | tuple) else [c.expr],
                                       f"constraint {c.name!r}").free_symbols)
        for extra in (B, passive):
            if extra is not None:
                free |= set(_as_matrix(sp, extra, "B/passive").free_symbols)
        for e in (outputs or {}).values():
            free |= set(_as_matrix(sp, e if isinstance(e, list | tuple) else [e], "outputs").free_symbols)
        by_name = {str(s): s for s in free}
        for key, val in (params or {}).items():
            sym = key if isinstance(key, sp.Symbol) else by_name.get(str(key), sp.Symbol(str(key)))
            if sym in set(q_t) | set(qd) or sym == tsym:
                raise ModelError(f"params: {key!s} is a coordinate, velocity or time symbol")
            pmap[sym] = float(val)
        comp, _ = _compile(
            q=q_t, qd=tuple(qd), t=tsym, params=pmap, M=M, V=V, constraints=cons, B=B,
            passive=passive, outputs=dict(outputs or {}),
        )
        dflt = (
            frozenset(s.name for s in comp.specs if s.kind != "unilateral")
            if default_active is None
            else frozenset(default_active)
        )
        return cls(
            name=str(name),
            coordinate_names=tuple(str(s) for s in q_t),
            compiled=comp,
            params={str(s): v for s, v in pmap.items()},
            actuator_names=tuple(actuator_names),
            default_active_names=dflt,
        )

    # ------------------------------------------------------------------ protocol
    @property
    def constraints(self) -> tuple[ConstraintSpec, ...]:  # type: ignore[override]
        return self.compiled.specs

    @property
    def default_active(self) -> frozenset[str]:  # type: ignore[override]
        if self.default_active_names is None:
            return frozenset(s.name for s in self.compiled.specs if s.kind != "unilateral")
        return frozenset(self.default_active_names)

    @property
    def has_outputs(self) -> bool:  # type: ignore[override]
        return bool(self.compiled.outputs)

    def _eval(self, key: str, t: float, q: FloatArray, qd: FloatArray) -> FloatArray:
        shape = self.compiled.shapes[key]
        fn = self.compiled.fn.get(key)
        if fn is None:
            return np.zeros(shape)
        out = np.asarray(fn(float(t), q, qd, self._pvals), dtype=float)
        return out.reshape(shape)

    def mass_matrix(self, q: ArrayLike) -> FloatArray:
        qv = _as_vector(q, "q", self.n)
        return self._eval("M", 0.0, qv, np.zeros(self.n))

    def coriolis_matrix(self, q: ArrayLike, qd: ArrayLike) -> FloatArray:
        qv = _as_vector(q, "q", self.n)
        return self._eval("C", 0.0, qv, _as_vector(qd, "qd", self.n))

    def conservative_force(self, q: ArrayLike) -> FloatArray:
        qv = _as_vector(q, "q", self.n)
        return self._eval("fg", 0.0, qv, np.zeros(self.n)).reshape(self.n)

    def potential_energy(self, q: ArrayLike) -> float:
        qv = _as_vector(q, "q", self.n)
        return float(self._eval("V", 0.0, qv, np.zeros(self.n))[0, 0])

    def passive_force(self, t: float, q: ArrayLike, qd: ArrayLike) -> FloatArray:
        qv = _as_vector(q, "q", self.n)
        return self._eval("passive", t, qv, _as_vector(qd, "qd", self.n)).reshape(self.n)

    def input_matrix(self, q: ArrayLike) -> FloatArray:
        qv = _as_vector(q, "q", self.n)
        return self._eval("B", 0.0, qv, np.zeros(self.n))

    def _rows(self, act: frozenset[str]) -> FloatArray:
        idx = [
            np.arange(sl.start, sl.stop)
            for spec, sl in zip(self.compiled.specs, self.compiled.rows)
            if spec.name in act
        ]
        return np.concatenate(idx) if idx else np.zeros(0, dtype=int)

    def constraint_terms(
        self,
        t: float,
        q: ArrayLike,
        qd: ArrayLike,
        active: Iterable[str] | None = None,
    ) -> ConstraintTerms:
        act = self.resolve_active(active)
        qv = _as_vector(q, "q", self.n)
        v = _as_vector(qd, "qd", self.n)
        r = self._rows(act)
        A = self._eval("A", t, qv, v)[r]
        gamma = self._eval("gamma", t, qv, v).reshape(-1)[r]
        phi = self._eval("phi", t, qv, v).reshape(-1)[r]
        phi_t = self._eval("phi_t", t, qv, v).reshape(-1)[r]
        hol = np.concatenate(
            [
                np.full(s.dim, s.has_position_level)
                for s in self.compiled.specs
                if s.name in act
            ]
            or [np.zeros(0, dtype=bool)]
        )
        return ConstraintTerms(A=A, gamma=gamma, phi=phi, velocity=A @ v + phi_t, holonomic=hol)

    def constraint_jacobian_dot(
        self, t: float, q: ArrayLike, qd: ArrayLike, active: Iterable[str] | None = None
    ) -> FloatArray:
        """The exact ``Ȧ = Σ_k ∂A/∂q_k qd_k + ∂A/∂t`` (compiled), shape (m, n)."""
        act = self.resolve_active(active)
        qv = _as_vector(q, "q", self.n)
        v = _as_vector(qd, "qd", self.n)
        return self._eval("Adot", t, qv, v)[self._rows(act)]

    def engine_program(self) -> Any | None:
        """The model as the engine's ``TapeProgram`` (see :meth:`nonmin.model.Model.engine_program`).

        The SymPy expressions of M, ``h = f_g − C qd``, f_passive, B, A, γ, φ, the velocity
        residual and V are compiled once to an expression tape (:mod:`._tape`; shared by
        :meth:`replace` variants, whose parameter values are inputs of the tape); the program
        is built once per model. None when an expression uses a function the tape does not
        have (the engine then calls :meth:`evaluate` back).
        """
        prog = _PROGRAMS.get(self, _MISSING)
        if prog is _MISSING:
            tape = _tape_of(self.compiled)
            prog = None if tape is None else _tape_program(self, tape)
            _PROGRAMS[self] = prog
        return prog

    def outputs(self, t: float, q: ArrayLike, qd: ArrayLike) -> dict[str, FloatArray]:
        qv = _as_vector(q, "q", self.n)
        v = _as_vector(qd, "qd", self.n)
        out = {}
        for name in self.compiled.outputs:
            val = self._eval(f"out:{name}", t, qv, v).reshape(-1)
            out[name] = val[0] if val.size == 1 else val
        return {k: np.asarray(x, dtype=float) for k, x in out.items()}

    def replace(self, **changes: Any) -> SymbolicModel:
        """A copy with fields replaced; ``params`` may be a partial mapping (merged, by name or
        symbol) and is applied without recompiling."""
        import dataclasses

        known = {"name", "params", "actuator_names", "default_active_names"}
        unknown = set(changes) - known
        if unknown:
            raise InputError(f"replace(): unknown field(s) {sorted(unknown)}; known: {sorted(known)}")
        if "params" in changes:
            new = dict(self.params)
            for key, val in dict(changes["params"]).items():
                k = str(key)
                if k not in new:
                    raise UnknownNameError(
                        f"params: unknown parameter {k!r}; parameters of model {self.name!r}: "
                        f"{sorted(new)}"
                    )
                new[k] = float(val)
            changes["params"] = new
        return dataclasses.replace(self, **changes)


#: Tapes of compiled expression sets and programs of live models (built on first use; not part
#: of a model's value or pickle). A tape is None when an expression cannot be compiled.
_TAPES: weakref.WeakKeyDictionary[_Compiled, Any] = weakref.WeakKeyDictionary()
_PROGRAMS: weakref.WeakKeyDictionary[SymbolicModel, Any] = weakref.WeakKeyDictionary()
_MISSING = object()
_KIND_CODES = {"holonomic": 0, "rheonomic": 1, "nonholonomic": 2, "unilateral": 3}


def _tape_of(comp: _Compiled) -> Any | None:
    """The expression tape of ``comp`` (compiled once), or None if it cannot be compiled."""
    tape = _TAPES.get(comp, _MISSING)
    if tape is _MISSING:
        from ._tape import compile_tape

        sp = _sympy()
        qdv = sp.Matrix(comp.qd)
        outputs = {
            "M": comp.M,
            "h": comp.fg - comp.C * qdv,
            "f_passive": comp.passive,
            "B": comp.B,
            "A": comp.A,
            "gamma": comp.gamma,
            "phi": comp.phi,
            "velocity": comp.A * qdv + comp.phi_t,
            "V": comp.V,
        }
        inputs = [comp.t, *comp.q, *comp.qd, *comp.param_symbols]
        try:
            tape = compile_tape(sp, inputs, outputs)
        except ModelError:
            tape = None
        _TAPES[comp] = tape
    return tape


def _tape_program(model: SymbolicModel, tape: Any) -> Any:
    from ... import _engine  # type: ignore[attr-defined]  # the compiled extension (no stubs)

    cons = [(s.name, _KIND_CODES[s.kind], s.dim) for s in model.compiled.specs]
    return _engine.TapeProgram(
        model.n, model.k, cons, tape.op, tape.a, tape.b, tape.c, tape.out_target,
        tape.out_index, tape.out_reg, [float(v) for v in model._pvals],
    )  # fmt: skip
