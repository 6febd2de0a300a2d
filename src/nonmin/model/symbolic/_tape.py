"""SymPy expressions → an expression tape the engine evaluates (``nonmin._engine.TapeProgram``).

The tape is straight-line SSA code over double registers: the inputs ``[t, q, qd, params]``,
then one register per instruction (``const``, ``add``, ``sub``, ``mul``, ``div``, ``neg``,
``powi``, ``pow``, ``sqrt``, ``sin``, ``cos``, ... — the list is ``OPS``, the same codes as
``TapeOp`` in ``engine/include/nonmin/tape.hpp``). :func:`compile_tape` runs ``sympy.cse`` over
every output expression at once, then walks the reduced expressions and the common
subexpressions, emitting each distinct operation once (hash-consing catches what CSE leaves,
e.g. the same product in two rows). The output table says which register holds which entry of
M, ``h = f_g − C qd``, f_passive, B, A, γ, φ, the velocity residual ``A qd + φ_t`` and V;
entries that are identically zero are not in it.

This runs once per symbolic model (it does not depend on the parameter values, which are
inputs); the engine evaluates the tape with no Python, no ``lambdify`` and no C compiler.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ...errors import ModelError

__all__ = ["OPS", "TARGETS", "Tape", "compile_tape"]

#: Instruction codes (``TapeOp`` in tape.hpp).
OPS: dict[str, int] = {
    "const": 0, "add": 1, "sub": 2, "mul": 3, "div": 4, "neg": 5, "powi": 6, "pow": 7,
    "sqrt": 8, "sin": 9, "cos": 10, "tan": 11, "exp": 12, "log": 13, "asin": 14, "acos": 15,
    "atan": 16, "atan2": 17, "sinh": 18, "cosh": 19, "tanh": 20, "abs": 21, "sign": 22,
    "min": 23, "max": 24, "square": 25,
}  # fmt: skip

#: Output arrays (``TapeTarget`` in tape.hpp).
TARGETS: dict[str, int] = {
    "M": 0, "h": 1, "f_passive": 2, "B": 3, "A": 4, "gamma": 5, "phi": 6, "velocity": 7, "V": 8,
}  # fmt: skip

#: SymPy functions of one argument and their op.
_UNARY = {
    "sin": "sin", "cos": "cos", "tan": "tan", "exp": "exp", "log": "log", "asin": "asin",
    "acos": "acos", "atan": "atan", "sinh": "sinh", "cosh": "cosh", "tanh": "tanh",
    "Abs": "abs", "sign": "sign",
}  # fmt: skip

_COMMUTATIVE = {OPS["add"], OPS["mul"], OPS["min"], OPS["max"]}
_I32 = np.int32


@dataclass(frozen=True)
class Tape:
    """A compiled tape: instructions and output table (arrays for ``TapeProgram``).

    Attributes
    ----------
    n_inputs : int
        ``1 + 2 n + n_params`` input registers ``[t, q, qd, params]``.
    op, a, b : ndarray of int32, shape (N,)
        Instruction codes and operand registers.
    c : ndarray, shape (N,)
        Constant of ``const`` instructions and the exponent of ``powi``.
    out_target, out_index, out_reg : ndarray of int32, shape (E,)
        Output table: array (:data:`TARGETS`), flat index in it, register.
    """

    n_inputs: int
    op: NDArray[np.int32]
    a: NDArray[np.int32]
    b: NDArray[np.int32]
    c: NDArray[np.float64]
    out_target: NDArray[np.int32]
    out_index: NDArray[np.int32]
    out_reg: NDArray[np.int32]

    @property
    def size(self) -> int:
        """Number of instructions."""
        return int(self.op.shape[0])


class _Emitter:
    """Emits instructions with hash-consing and converts SymPy expressions to registers."""

    def __init__(self, sp: Any, inputs: Mapping[Any, int], n_inputs: int) -> None:
        self.sp = sp
        self.base = n_inputs
        self.op: list[int] = []
        self.a: list[int] = []
        self.b: list[int] = []
        self.c: list[float] = []
        self.keys: dict[tuple[int, int, int, float], int] = {}
        self.regs: dict[Any, int] = dict(inputs)

    def emit(self, op: str, a: int = 0, b: int = 0, c: float = 0.0) -> int:
        code = OPS[op]
        if code in _COMMUTATIVE and a > b:
            a, b = b, a
        key = (code, a, b, c)
        reg = self.keys.get(key)
        if reg is None:
            reg = self.base + len(self.op)
            self.op.append(code)
            self.a.append(a)
            self.b.append(b)
            self.c.append(c)
            self.keys[key] = reg
        return reg

    def const(self, v: float) -> int:
        return self.emit("const", c=float(v))

    def fold(self, op: str, regs: Sequence[int]) -> int:
        r = regs[0]
        for x in regs[1:]:
            r = self.emit(op, r, x)
        return r

    def reg(self, e: Any) -> int:
        """The register of expression ``e`` (emitting what is missing)."""
        r = self.regs.get(e)
        if r is None:
            r = self._convert(e)
            self.regs[e] = r
        return r

    def _convert(self, e: Any) -> int:
        sp = self.sp
        if e.is_Symbol:
            raise ModelError(f"expression tape: unknown symbol {e} (not t, q, qd or a parameter)")
        if not e.free_symbols:
            try:
                return self.const(float(e))
            except (TypeError, ValueError):
                raise ModelError(f"expression tape: {e} is not a real number") from None
        if e.is_Add:
            pos: list[int] = []
            neg: list[int] = []
            for term in e.args:
                coeff, rest = term.as_coeff_Mul()
                if coeff.is_negative:
                    neg.append(self.reg(-coeff * rest))
                else:
                    pos.append(self.reg(term))
            if pos:
                r = self.fold("add", pos)
            else:
                r = self.emit("neg", neg.pop(0))
            for x in neg:
                r = self.emit("sub", r, x)
            return r
        if e.is_Mul:
            coeff, rest = e.as_coeff_Mul()
            num: list[int] = []
            den: list[int] = []
            for f in sp.Mul.make_args(rest):
                if f.is_Pow and f.exp.is_number and f.exp.is_negative:
                    den.append(self.reg(sp.Pow(f.base, -f.exp)))
                else:
                    num.append(self.reg(f))
            mag = abs(coeff)
            if mag != 1:
                num.insert(0, self.const(float(mag)))
            r = self.fold("mul", num) if num else self.const(1.0)
            if den:
                r = self.emit("div", r, self.fold("mul", den))
            if coeff.is_negative:
                r = self.emit("neg", r)
            return r
        if e.is_Pow:
            base, ex = e.base, e.exp
            if ex.is_Integer:
                k = int(ex)
                if k == 2:
                    return self.emit("square", self.reg(base))
                if k == -1:
                    return self.emit("div", self.const(1.0), self.reg(base))
                return self.emit("powi", self.reg(base), c=float(k))
            if ex == sp.Rational(1, 2):
                return self.emit("sqrt", self.reg(base))
            if ex == sp.Rational(-1, 2):
                return self.emit("div", self.const(1.0), self.emit("sqrt", self.reg(base)))
            if base == sp.E:
                return self.emit("exp", self.reg(ex))
            return self.emit("pow", self.reg(base), self.reg(ex))
        name = type(e).__name__
        if name in _UNARY and len(e.args) == 1:
            return self.emit(_UNARY[name], self.reg(e.args[0]))
        if name == "atan2":
            return self.emit("atan2", self.reg(e.args[0]), self.reg(e.args[1]))
        if name in ("Min", "Max"):
            return self.fold(name.lower(), [self.reg(x) for x in e.args])
        raise ModelError(
            f"expression tape: cannot compile {name} ({e}); supported: +, −, ×, /, powers, "
            f"{', '.join(sorted(_UNARY))}, atan2, Min, Max"
        )


def compile_tape(
    sp: Any,
    inputs: Sequence[Any],
    outputs: Mapping[str, Any],
) -> Tape:
    """Compile SymPy output matrices to a :class:`Tape`.

    Parameters
    ----------
    sp : module
        The ``sympy`` module.
    inputs : sequence of sympy.Symbol
        ``[t, q_0, …, q_{n−1}, qd_0, …, qd_{n−1}, p_0, …]``: register i is input i.
    outputs : mapping of target name (:data:`TARGETS`) to sympy Matrix (or scalar for ``V``)
        Row-major flat index of each entry is its index in the engine's array.

    Raises
    ------
    ModelError
        An expression uses a function the tape does not have, or an unknown symbol.
    """
    entries: list[tuple[int, int]] = []
    exprs: list[Any] = []
    for name, mat in outputs.items():
        code = TARGETS[name]
        flat = [sp.sympify(mat)] if name == "V" else list(sp.Matrix(mat))
        for idx, e in enumerate(flat):
            if e.is_zero is True or e == 0:
                continue
            entries.append((code, idx))
            exprs.append(e)
    repl, reduced = sp.cse(exprs, order="none") if exprs else ([], [])
    em = _Emitter(sp, {s: i for i, s in enumerate(inputs)}, len(inputs))
    for sym, e in repl:
        em.regs[sym] = em.reg(e)
    out_reg = [em.reg(e) for e in reduced]
    return Tape(
        n_inputs=len(inputs),
        op=np.array(em.op, dtype=_I32),
        a=np.array(em.a, dtype=_I32),
        b=np.array(em.b, dtype=_I32),
        c=np.array(em.c, dtype=np.float64),
        out_target=np.array([t for t, _ in entries], dtype=_I32),
        out_index=np.array([i for _, i in entries], dtype=_I32),
        out_reg=np.array(out_reg, dtype=_I32),
    )
