"""Prescribed motions f(t) as values: what drivers (rheonomic constraints) follow.

Every time function returns ``(f, ḟ, f̈)`` at ``t`` and compiles to the engine's
``TimeFunction`` (``engine/include/nonmin/timefn.hpp``), so a driven model simulates without
calling Python:

:class:`Polynomial`
    ``f = Σ c_k t^k`` (constant speed is ``Polynomial([start, speed])``).
:class:`Spline`
    A C² cubic spline through knots ``(t_i, y_i)`` (``scipy.interpolate.CubicSpline``, boundary
    condition ``bc_type``). Outside the knots the end pieces extrapolate (default) or the end
    values are held.
:class:`Sampled`
    A sampled array (times ``t`` or a step ``dt``) through the same spline, end values held.
:class:`Expression`
    A closed-form expression of ``t`` (a string or a SymPy expression; needs the ``symbolic``
    extra): SymPy differentiates it twice, once, and the three are compiled to an expression
    tape.
:class:`PiecewisePolynomial`
    Polynomial pieces ``Σ c_ik (t − t_i)^k`` on ``[t_i, t_{i+1})`` (what the others compile to).

:func:`as_time_function` turns what a builder's driver accepts (a number, a time function, a
callable ``t -> (f, ḟ, f̈)``) into a time function; a plain callable stays a Python callback
(the escape hatch: correct, but the engine then calls Python at every evaluation).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from ..errors import InputError, ModelError, NonminError
from ._protocol import FloatArray

__all__ = [
    "Callback",
    "Expression",
    "PiecewisePolynomial",
    "Polynomial",
    "Sampled",
    "Spline",
    "TimeFunction",
    "as_time_function",
]


class TimeFunction:
    """Base of prescribed motions: ``fn(t) -> (f, ḟ, f̈)``; :meth:`engine` compiles it."""

    def __call__(self, t: float) -> tuple[float, float, float]:  # pragma: no cover - abstract
        raise NotImplementedError

    def engine(self) -> Any:
        """The engine's ``TimeFunction`` of this value."""
        raise NotImplementedError  # pragma: no cover - abstract


def _finite_array(x: ArrayLike, what: str, ndim: int) -> FloatArray:
    try:
        a = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(f"{what} must be an array of numbers, got {x!r}") from None
    if a.ndim != ndim:
        raise InputError(f"{what} must have {ndim} dimension(s), got shape {a.shape}")
    if not np.isfinite(a).all():
        raise InputError(f"{what} must be finite")
    return a


@dataclass(frozen=True, eq=False)
class PiecewisePolynomial(TimeFunction):
    """Pieces ``f(t) = Σ_k coefs[i, k] (t − breaks[i])^k`` on ``[breaks[i], breaks[i+1])``.

    Parameters
    ----------
    breaks : array_like, shape (s + 1,)
        Strictly increasing break points.
    coefs : array_like, shape (s, degree + 1)
        Ascending powers per piece.
    hold : bool
        Outside ``[breaks[0], breaks[-1]]`` hold the end values (rates 0) instead of
        extrapolating the end pieces.
    """

    breaks: FloatArray
    coefs: FloatArray
    hold: bool = False
    _engine: Any = field(default=None, repr=False, compare=False)

    def __post_init__(self) -> None:
        br = _finite_array(self.breaks, "breaks", 1)
        co = _finite_array(self.coefs, "coefs", 2)
        if br.shape[0] < 2 or co.shape[0] != br.shape[0] - 1:
            raise InputError(
                f"breaks of shape (s + 1,) and coefs of shape (s, degree + 1) needed, got {br.shape} and {co.shape}"
            )
        if co.shape[0] > 1 and not np.all(np.diff(br) > 0):
            raise InputError("breaks must be strictly increasing")
        object.__setattr__(self, "breaks", br)
        object.__setattr__(self, "coefs", co)

    def __getstate__(self) -> dict[str, Any]:  # the engine twin is rebuilt on demand
        return {"breaks": self.breaks, "coefs": self.coefs, "hold": self.hold}

    def __setstate__(self, state: dict[str, Any]) -> None:
        for k, v in state.items():
            object.__setattr__(self, k, v)
        object.__setattr__(self, "_engine", None)

    def __call__(self, t: float) -> tuple[float, float, float]:
        br, co = self.breaks, self.coefs
        tt = float(t)
        outside = False
        if self.hold and br[-1] > br[0] and (tt <= br[0] or tt >= br[-1]):
            tt = min(max(tt, float(br[0])), float(br[-1]))
            outside = True
        i = (
            0
            if co.shape[0] == 1
            else int(np.clip(np.searchsorted(br, tt, side="right") - 1, 0, co.shape[0] - 1))
        )
        tau = tt - br[i]
        c = co[i]
        f = np.polynomial.polynomial.polyval(tau, c)
        c1 = np.polynomial.polynomial.polyder(c) if c.size > 1 else np.zeros(1)
        c2 = np.polynomial.polynomial.polyder(c1) if c1.size > 1 else np.zeros(1)
        fd = np.polynomial.polynomial.polyval(tau, c1)
        fdd = np.polynomial.polynomial.polyval(tau, c2)
        if outside:
            return float(f), 0.0, 0.0
        return float(f), float(fd), float(fdd)

    def engine(self) -> Any:
        if self._engine is None:
            from .. import _engine  # type: ignore[attr-defined]

            fn = _engine.TimeFunction.pieces(
                self.breaks.tolist(),
                self.coefs.ravel().tolist(),
                int(self.coefs.shape[1] - 1),
                bool(self.hold),
            )
            object.__setattr__(self, "_engine", fn)
        return self._engine


def Polynomial(coefs: ArrayLike) -> PiecewisePolynomial:
    """``f(t) = Σ_k coefs[k] t^k`` everywhere (``Polynomial([θ0, ω])`` turns at constant speed)."""
    c = _finite_array(coefs, "coefs", 1)
    if c.size == 0:
        raise InputError("coefs must hold at least one coefficient")
    return PiecewisePolynomial(np.array([0.0, 0.0]), c[None, :])


def Spline(
    t: ArrayLike, y: ArrayLike, *, bc_type: Any = "not-a-knot", hold: bool = False
) -> PiecewisePolynomial:
    """The C² cubic spline through ``(t_i, y_i)`` (SciPy's ``CubicSpline``; ``bc_type`` as there:
    ``"not-a-knot"``, ``"natural"``, ``"clamped"`` (zero end slopes), ``"periodic"`` or end
    derivatives). ``hold=True`` holds the end values outside ``[t_0, t_N]``."""
    from scipy.interpolate import CubicSpline

    ta = _finite_array(t, "t", 1)
    ya = _finite_array(y, "y", 1)
    if ta.shape != ya.shape or ta.shape[0] < 2:
        raise InputError(
            f"t and y must have the same shape (N,), N ≥ 2, got {ta.shape} and {ya.shape}"
        )
    if not np.all(np.diff(ta) > 0):
        raise InputError("spline knots t must be strictly increasing")
    try:
        cs = CubicSpline(ta, ya, bc_type=bc_type)
    except ValueError as exc:
        raise InputError(f"spline: {exc}") from None
    # SciPy's c[k, i] multiplies (t − x_i)^(3 − k): reverse to ascending powers
    return PiecewisePolynomial(ta, cs.c[::-1].T.copy(), hold=hold)


def Sampled(
    values: ArrayLike,
    *,
    dt: float | None = None,
    t: ArrayLike | None = None,
    t0: float = 0.0,
    hold: bool = True,
) -> PiecewisePolynomial:
    """A sampled array ``values`` at times ``t`` (or ``t0 + i·dt``), interpolated by the C² cubic
    spline through the samples (not-a-knot ends). Outside the samples the end values are held
    (default; ``hold=False`` extrapolates the end pieces)."""
    ya = _finite_array(values, "values", 1)
    if (dt is None) == (t is None):
        raise InputError("Sampled needs exactly one of dt= (uniform samples) or t= (sample times)")
    if dt is not None:
        step = float(dt)
        if not (math.isfinite(step) and step > 0.0):
            raise InputError(f"dt must be a finite number > 0, got {dt!r}")
        ta = float(t0) + step * np.arange(ya.shape[0])
    else:
        ta = _finite_array(t, "t", 1)  # type: ignore[arg-type]
    return Spline(ta, ya, hold=hold)


@dataclass(frozen=True, eq=False)
class Expression(TimeFunction):
    """A closed-form ``f(t)``: a string such as ``"0.3*sin(2*pi*t)"`` or a SymPy expression in
    the symbol ``t`` (extra ``symbolic``). Its derivatives are SymPy's, compiled once to an
    expression tape that the engine evaluates."""

    expr: Any
    _fns: Any = field(default=None, repr=False, compare=False)
    _engine: Any = field(default=None, repr=False, compare=False)

    def __post_init__(self) -> None:
        try:
            import sympy as sp
        except ImportError:
            from ..errors import missing_dependency

            raise missing_dependency("sympy", "symbolic", "Expression time functions") from None
        t = sp.Symbol("t", real=True)
        try:
            e = (
                sp.sympify(self.expr, locals={"t": t})
                if isinstance(self.expr, str)
                else sp.sympify(self.expr)
            )
        except (sp.SympifyError, TypeError, SyntaxError) as exc:
            raise InputError(
                f"expression {self.expr!r} is not a valid expression of t: {exc}"
            ) from None
        e = e.subs({s: t for s in e.free_symbols if s.name == "t"})
        extra = [s for s in e.free_symbols if s != t]
        if extra:
            raise InputError(
                f"expression {self.expr!r} may use only the symbol t, got also {sorted(map(str, extra))}"
            )
        d1 = sp.diff(e, t)
        d2 = sp.diff(d1, t)
        object.__setattr__(self, "_fns", (sp, t, (e, d1, d2)))

    def __getstate__(self) -> dict[str, Any]:  # SymPy objects and the engine twin are rebuilt
        return {"expr": self.expr if isinstance(self.expr, str) else str(self.expr)}

    def __setstate__(self, state: dict[str, Any]) -> None:
        object.__setattr__(self, "expr", state["expr"])
        object.__setattr__(self, "_engine", None)
        self.__post_init__()

    def __call__(self, t: float) -> tuple[float, float, float]:
        # the compiled tape of the three SymPy expressions (SymPy's evalf costs ~1 ms a call);
        # tests check it against the closed forms
        f, fd, fdd = self.engine()(float(t))
        return float(f), float(fd), float(fdd)

    def engine(self) -> Any:
        if self._engine is None:
            from .. import _engine  # type: ignore[attr-defined]
            from .symbolic._tape import compile_tape

            sp, ts, exprs = self._fns
            try:
                tape = compile_tape(sp, [ts], {"phi": sp.Matrix(list(exprs))})
            except ModelError as exc:
                raise ModelError(f"expression {self.expr!r}: {exc}") from None
            out = [-1, -1, -1]
            for idx, reg in zip(tape.out_index.tolist(), tape.out_reg.tolist(), strict=True):
                out[idx] = reg
            fn = _engine.TimeFunction.tape(
                tape.op.tolist(), tape.a.tolist(), tape.b.tolist(), tape.c.tolist(), out
            )
            object.__setattr__(self, "_engine", fn)
        return self._engine


@dataclass(frozen=True, eq=False)
class Callback(TimeFunction):
    """A Python callable ``t -> (f, ḟ, f̈)`` (the escape hatch: the engine calls back into
    Python, so the program is not thread safe). Failures are typed: an exception or a result
    that is not three finite numbers is a :class:`~nonmin.errors.ModelError` naming ``what``
    and the time."""

    fn: Callable[[float], Any]
    what: str = "time function"

    def __call__(self, t: float) -> tuple[float, float, float]:
        try:
            out = self.fn(t)
        except NonminError:
            raise
        except Exception as exc:
            raise ModelError(
                f"{self.what}: profile raised {type(exc).__name__}: {exc} (at t = {t:.12g})"
            ) from exc
        try:
            vals = tuple(float(v) for v in out)
        except (TypeError, ValueError):
            vals = ()
        if len(vals) != 3 or not all(math.isfinite(v) for v in vals):
            raise ModelError(
                f"{self.what}: profile must return three finite numbers (f, ḟ, f̈), got {out!r} at t = {t:.12g}"
            )
        return vals  # type: ignore[return-value]

    def engine(self) -> Any:
        from .. import _engine  # type: ignore[attr-defined]

        return _engine.TimeFunction.callback(self)


def as_time_function(value: Any, what: str) -> TimeFunction:
    """A :class:`TimeFunction` from what a driver accepts.

    A number is a constant; a sequence of numbers is a polynomial's coefficients; a
    :class:`TimeFunction` is itself; an object with ``engine()`` and ``__call__`` (the planar
    ``ConstantSpeed``) is kept; any other callable ``t -> (f, ḟ, f̈)`` becomes a :class:`Callback`.
    """
    if isinstance(value, TimeFunction):
        return value
    if isinstance(value, bool):
        raise InputError(
            f"{what}: a prescribed motion must be a number, a time function or a callable, got {value!r}"
        )
    if isinstance(value, int | float | np.floating | np.integer):
        if not math.isfinite(float(value)):
            raise InputError(f"{what}: a constant must be finite, got {value!r}")
        return Polynomial([float(value)])
    if isinstance(value, str):
        return Expression(value)
    if callable(value):
        return Callback(value, what)
    if isinstance(value, Sequence | np.ndarray):
        return Polynomial(value)  # type: ignore[arg-type]
    raise InputError(
        f"{what}: a prescribed motion must be a number, a time function (Polynomial, Spline, "
        f"Expression) or a callable t -> (f, fd, fdd), got {type(value).__name__}"
    )
