"""Borrowed array views for compiled loops (numba only; imported lazily).

Numba reference-counts every array: each array that crosses a call between compiled functions,
or is taken out of a tuple, or is sliced or reshaped, costs an atomic increment and decrement
of its memory-info block (``lock inc``/``lock dec``). In the simulation loop, whose helpers pass
tuples of some forty scratch arrays around, that bookkeeping took more than half of the wall
time (measured with ``perf``: 55 % of the samples of the crossed four-bar run at ``dt = 2e-2``
in ``NRT_incref``/``NRT_decref``).

:func:`borrow` returns the same arrays (same data, shape, strides and numba type) with an empty
memory-info pointer: numba's reference counting skips them (``NRT_incref(NULL)`` returns at
once), and so does every view taken from them. The caller must keep the owners alive for as
long as the borrowed views are used; the intended use is a compiled loop that borrows arrays
which its (Python) caller owns for the duration of the call.
"""

from __future__ import annotations

from typing import Any

from numba import types
from numba.core import cgutils
from numba.core.errors import TypingError
from numba.extending import intrinsic


def _members(ty: Any) -> tuple[Any, ...]:
    return tuple(ty.types)


def _check(ty: Any) -> None:
    if isinstance(ty, types.Array) or isinstance(ty, (types.Number, types.Boolean)):
        return
    if isinstance(ty, types.BaseTuple):
        for t in _members(ty):
            _check(t)
        return
    raise TypingError(f"borrow() takes arrays, numbers and tuples of them, got {ty}")


def _borrowed(context: Any, builder: Any, ty: Any, val: Any) -> Any:
    if isinstance(ty, types.Array):
        src = context.make_array(ty)(context, builder, value=val)
        dst = context.make_array(ty)(context, builder)
        context.populate_array(dst, data=src.data, shape=src.shape, strides=src.strides,
                               itemsize=src.itemsize, meminfo=None, parent=None)  # fmt: skip
        return dst._getvalue()
    if isinstance(ty, types.BaseTuple):
        out = cgutils.get_null_value(val.type)
        for i, t in enumerate(_members(ty)):
            item = _borrowed(context, builder, t, builder.extract_value(val, i))
            out = builder.insert_value(out, item, i)
        return out
    return val  # a number: no reference to count


def _borrow_typer(typingctx: Any, x: Any) -> Any:
    """``x`` (an array, or a possibly nested tuple of arrays and numbers) with every array
    replaced by a view without reference counting. Same numba type as ``x``."""
    _check(x)
    sig = x(x)

    def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
        return _borrowed(context, builder, x, args[0])

    return sig, codegen


#: The intrinsic (call it from compiled code only).
borrow: Any = intrinsic(_borrow_typer)
