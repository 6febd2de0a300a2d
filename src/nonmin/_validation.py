"""Validation at the public boundary: coerce once, check shapes and finiteness, name the argument.

Kernels in :mod:`nonmin.core` call these helpers once on entry and then work on plain float
arrays. Every message names the argument, what was expected and what came.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .errors import InputError, NonFiniteError, NotSymmetricError, ShapeError

FloatArray = NDArray[np.float64]

#: Relative tolerance of the symmetry check of M (‖M − Mᵀ‖ ≤ tol·‖M‖, max-norm).
SYMMETRY_RTOL = 1e-9
_TINY = float(np.finfo(float).tiny)


def _shape_str(shape: Sequence[int | str]) -> str:
    return "(" + ", ".join(str(s) for s in shape) + ("," if len(shape) == 1 else "") + ")"


def as_float_array(x: ArrayLike, name: str) -> FloatArray:
    """Coerce ``x`` to a float64 array, raising :class:`ShapeError` if it is not numeric.

    Real numbers only: text (``"1.5"``, which NumPy would parse) is a :class:`ShapeError`,
    booleans and complex values with a non-zero imaginary part (which NumPy would drop with a
    warning) an :class:`InputError`, each naming ``name``.
    """
    if isinstance(x, np.ndarray) and x.dtype == np.float64:
        return x
    try:
        raw = np.asarray(x)
    except (TypeError, ValueError) as exc:
        raise ShapeError(
            f"{name} must be a numeric array, got {type(x).__name__}: {exc}"
        ) from None
    kind = raw.dtype.kind
    if kind in "US" or (kind == "O" and any(isinstance(v, (str, bytes)) for v in raw.flat)):
        raise ShapeError(f"{name} must be a numeric array, got text: {x!r:.80}")
    if kind == "b" or (kind == "O" and any(isinstance(v, (bool, np.bool_)) for v in raw.flat)):
        raise InputError(f"{name} must be numbers, got booleans: {x!r:.80}")
    if kind == "c":
        if np.any(raw.imag != 0):
            raise InputError(f"{name} must be real numbers, got complex values (dtype {raw.dtype})")
        raw = raw.real
    try:
        arr = np.asarray(raw, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ShapeError(
            f"{name} must be a numeric array, got {type(x).__name__}: {exc}"
        ) from None
    return arr


def check_finite(arr: FloatArray, name: str) -> None:
    """Raise :class:`NonFiniteError` if ``arr`` holds NaN or infinity."""
    if not np.isfinite(arr).all():
        bad = np.argwhere(~np.isfinite(arr))
        where = tuple(int(i) for i in bad[0]) if bad.size else ()
        raise NonFiniteError(
            f"{name} must be finite, but it contains {np.count_nonzero(~np.isfinite(arr))} "
            f"NaN/inf entries (first at index {where})"
        )


def matrix(x: ArrayLike, name: str, rows: int | None = None, cols: int | None = None) -> FloatArray:
    """Validate a batched matrix ``(..., rows, cols)``; ``None`` leaves a size free."""
    arr = as_float_array(x, name)
    expected = _shape_str(["...", rows if rows is not None else "m", cols if cols is not None else "n"])
    if arr.ndim < 2:
        raise ShapeError(f"{name} must have shape {expected}, got shape {_shape_str(arr.shape)}")
    if (rows is not None and arr.shape[-2] != rows) or (cols is not None and arr.shape[-1] != cols):
        raise ShapeError(f"{name} must have shape {expected}, got shape {_shape_str(arr.shape)}")
    check_finite(arr, name)
    return arr


def square(x: ArrayLike, name: str, n: int | None = None) -> FloatArray:
    """Validate a batched square matrix ``(..., n, n)``."""
    arr = as_float_array(x, name)
    if arr.ndim < 2 or arr.shape[-1] != arr.shape[-2] or (n is not None and arr.shape[-1] != n):
        want = _shape_str(["...", n if n is not None else "n", n if n is not None else "n"])
        raise ShapeError(f"{name} must be square with shape {want}, got shape {_shape_str(arr.shape)}")
    check_finite(arr, name)
    return arr


def symmetric(x: ArrayLike, name: str, n: int | None = None) -> FloatArray:
    """Validate a batched symmetric matrix; raise :class:`NotSymmetricError` otherwise."""
    arr = square(x, name, n)
    if arr.ndim == 2 and arr.size and np.abs(arr - arr.T).max() <= SYMMETRY_RTOL * max(np.abs(arr).max(), _TINY):
        return arr  # one matrix (the kernels' every call): the same test on its two maxima
    scale = np.max(np.abs(arr), axis=(-2, -1), initial=0.0)
    asym = np.max(np.abs(arr - np.swapaxes(arr, -1, -2)), axis=(-2, -1), initial=0.0)
    bad = asym > SYMMETRY_RTOL * np.maximum(scale, np.finfo(float).tiny)
    if np.any(bad):
        worst = float(np.max(asym / np.maximum(scale, np.finfo(float).tiny)))
        raise NotSymmetricError(
            f"{name} must be symmetric (|{name} - {name}ᵀ| ≤ {SYMMETRY_RTOL:g}·|{name}|), "
            f"got a relative asymmetry of {worst:.3g}"
        )
    return arr


def vector(x: ArrayLike, name: str, n: int) -> FloatArray:
    """Validate a batched vector ``(..., n)``."""
    arr = as_float_array(x, name)
    if arr.ndim < 1 or arr.shape[-1] != n:
        raise ShapeError(
            f"{name} must have shape {_shape_str(['...', n])}, got shape {_shape_str(arr.shape)}"
        )
    check_finite(arr, name)
    return arr


def batch_shape(name_shapes: Sequence[tuple[str, tuple[int, ...]]]) -> tuple[int, ...]:
    """Broadcast the leading (batch) shapes of several arguments; name the culprits on failure."""
    try:
        return tuple(np.broadcast_shapes(*(s for _, s in name_shapes)))
    except ValueError:
        desc = ", ".join(f"{n}: {_shape_str(s)}" for n, s in name_shapes)
        raise ShapeError(f"leading (batch) dimensions do not broadcast: {desc}") from None


def positive_scalar_or_batch(x: ArrayLike, name: str) -> FloatArray:
    """Validate a positive scalar or a batch of positive scalars."""
    arr = as_float_array(x, name)
    check_finite(arr, name)
    if np.any(arr <= 0.0):
        raise InputError(f"{name} must be > 0, got {arr if arr.ndim == 0 else arr[arr <= 0][0]}")
    return arr


def nonnegative_float(x: object, name: str, upper: float | None = None) -> float:
    """Validate a scalar in ``[0, upper]``."""
    try:
        val = float(x)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a real number, got {x!r}") from None
    if not np.isfinite(val) or val < 0.0 or (upper is not None and val > upper):
        rng = f"[0, {upper:g}]" if upper is not None else "[0, inf)"
        raise InputError(f"{name} must lie in {rng}, got {val!r}")
    return val
