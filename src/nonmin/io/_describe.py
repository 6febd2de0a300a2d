"""Mechanism descriptions in scenario files: builder calls and frame constraints as tables.

``[model.planar]`` / ``[model.spatial]`` hold an ordered array ``[[model.planar.items]]``; each
item names a builder method in ``call`` and gives its arguments as keys (checked against the
method's signature: unknown keys and missing arguments are errors naming the file and key).
``[[model.constraints]]`` tables add frame constraints to URDF/MJCF robots: ``type`` names a
:class:`~nonmin.model.robots.FrameConstraint` constructor, the other keys are its arguments.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import NonminError, ScenarioError

__all__ = ["build_planar", "build_spatial", "frame_constraints"]


def _convert(value: Any) -> Any:
    """TOML lists to tuples; a planar point reference ``[body, [x, y]]`` to ``(body, (x, y))``."""
    if isinstance(value, list):
        if len(value) == 2 and isinstance(value[0], str) and isinstance(value[1], list):
            return (value[0], tuple(value[1]))
        return tuple(_convert(v) for v in value)
    if isinstance(value, dict):
        return {k: _convert(v) for k, v in value.items()}
    return value


def _bind(fn: Callable[..., Any], item: Mapping[str, Any], file: Path, key: str, what: str) -> dict[str, Any]:
    sig = inspect.signature(fn)
    params = {n: p for n, p in sig.parameters.items() if n != "self"}
    kwargs = {k: _convert(v) for k, v in item.items()}
    unknown = sorted(set(kwargs) - set(params))
    if unknown:
        raise ScenarioError(
            f"{file}: {key}: unknown key(s) {unknown} for {what}; expected {sorted(params)}"
        )
    missing = [
        n for n, p in params.items()
        if p.default is inspect.Parameter.empty
        and p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)
        and n not in kwargs
    ]
    if missing:
        raise ScenarioError(f"{file}: {key}: missing key(s) {missing} for {what}")
    return kwargs


def _run_items(builder: Any, items: Sequence[Mapping[str, Any]], file: Path, section: str, forbidden: set[str]) -> None:
    for i, item in enumerate(items):
        key = f"model.{section}.items[{i}]"
        call = item.get("call")
        methods = sorted(
            n for n, _ in inspect.getmembers(type(builder), inspect.isfunction)
            if not n.startswith("_") and n not in forbidden
        )
        if not isinstance(call, str) or call not in methods:
            raise ScenarioError(f"{file}: key {key}.call: expected one of {methods}, got {call!r}")
        args = {k: v for k, v in item.items() if k != "call"}
        fn = getattr(builder, call)
        kwargs = _bind(fn, args, file, key, f"{type(builder).__name__}.{call}")
        try:
            fn(**kwargs)
        except NonminError as exc:
            raise ScenarioError(f"{file}: {key}: {exc}") from None
        except TypeError as exc:
            raise ScenarioError(f"{file}: {key}: {exc}") from None


def build_planar(desc: Mapping[str, Any], file: Path) -> Any:
    """A :class:`~nonmin.model.planar.PlanarModel` from a ``[model.planar]`` table."""
    from ..model.planar import PlanarBuilder

    b = PlanarBuilder(
        str(desc.get("name", file.stem)),
        gravity=tuple(desc.get("gravity", (0.0, -9.81))),
        description=str(desc.get("description", "")),
    )
    _run_items(b, desc.get("items", []), file, "planar", {"build"})
    try:
        return b.build()
    except NonminError as exc:
        raise ScenarioError(f"{file}: table [model.planar]: {exc}") from None


def build_spatial(desc: Mapping[str, Any], file: Path) -> Any:
    """A :class:`~nonmin.model.spatial.SpatialModel` from a ``[model.spatial]`` table."""
    from ..model.spatial import SpatialBuilder

    b = SpatialBuilder(str(desc.get("name", file.stem)), gravity=tuple(desc.get("gravity", (0.0, 0.0, -9.81))))
    _run_items(b, desc.get("items", []), file, "spatial", {"build"})
    try:
        return b.build()
    except NonminError as exc:
        raise ScenarioError(f"{file}: table [model.spatial]: {exc}") from None


def frame_constraints(items: Sequence[Mapping[str, Any]], file: Path) -> list[Any]:
    """Frame constraints from ``[[model.constraints]]`` tables (URDF/MJCF robots)."""
    from ..model.robots import FrameConstraint

    kinds = ("point", "weld", "hinge", "planar_point", "planar_weld", "point_on_plane", "contact")
    out = []
    for i, item in enumerate(items):
        key = f"model.constraints[{i}]"
        kind = item.get("type")
        if kind not in kinds:
            raise ScenarioError(f"{file}: key {key}.type: expected one of {list(kinds)}, got {kind!r}")
        fn = getattr(FrameConstraint, kind)
        args = {k: v for k, v in item.items() if k not in ("type", "active")}
        kwargs = _bind(fn, args, file, key, f"FrameConstraint.{kind}")
        for k, v in list(kwargs.items()):
            if isinstance(v, tuple):
                try:
                    kwargs[k] = np.asarray(v, dtype=float)
                except (TypeError, ValueError):
                    raise ScenarioError(f"{file}: key {key}.{k}: expected a list of numbers, got "
                                        f"{list(v)!r}") from None  # fmt: skip
        try:
            out.append(fn(**kwargs))
        except NonminError as exc:
            raise ScenarioError(f"{file}: {key}: {exc}") from None
    return out
