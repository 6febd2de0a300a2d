"""A small typed schema for TOML scenario files: unknown keys and wrong types are errors that
name the file, the key (dotted path), what was expected and what came."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..errors import ScenarioError

__all__ = ["Key", "Section", "check"]


@dataclass(frozen=True)
class Key:
    """One key: accepted Python types (after TOML parsing), whether required, help text."""

    types: tuple[type, ...]
    required: bool = False
    help: str = ""
    choices: tuple[Any, ...] | None = None
    item_types: tuple[type, ...] | None = None  # for lists
    #: numbers (and numbers in lists) must lie in [low, high]; open ends with low_open/high_open.
    #: Every number must be finite (TOML accepts inf and nan) unless ``finite`` is False.
    low: float | None = None
    high: float | None = None
    low_open: bool = False
    finite: bool = True
    max_items: int | None = None

    def range_text(self) -> str:
        lo = "-inf" if self.low is None else f"{self.low:g}"
        hi = "inf" if self.high is None else f"{self.high:g}"
        return f"{'(' if self.low_open or self.low is None else '['}{lo}, {hi}{']' if self.high is not None else ')'}"

    def number_ok(self, v: float) -> bool:
        if self.finite and not math.isfinite(v):
            return False
        if self.low is not None and (v < self.low or (self.low_open and v == self.low)):
            return False
        return not (self.high is not None and v > self.high)

    def expected(self) -> str:
        names = {
            bool: "a boolean",
            int: "an integer",
            float: "a number",
            str: "a string",
            list: "a list",
            dict: "a table",
        }
        txt = " or ".join(names.get(t, t.__name__) for t in self.types)
        if self.item_types is not None:
            txt += " of " + " or ".join(names.get(t, t.__name__) for t in self.item_types)
        if self.choices is not None:
            txt += f" (one of {list(self.choices)})"
        return txt


@dataclass(frozen=True)
class Section:
    """A table: its keys and sub-sections; ``open_keys`` allows free keys (e.g. params)."""

    keys: Mapping[str, Key] = field(default_factory=dict)
    sections: Mapping[str, Section] = field(default_factory=dict)
    array_sections: Mapping[str, Section] = field(default_factory=dict)  # [[events]]
    open_keys: bool = False
    required: bool = False
    help: str = ""


def _type_name(v: Any) -> str:
    return {
        bool: "boolean",
        int: "integer",
        float: "number",
        str: "string",
        list: "list",
        dict: "table",
    }.get(type(v), type(v).__name__)


def _ok(value: Any, types: tuple[type, ...]) -> bool:
    if isinstance(value, bool):
        return bool in types
    if isinstance(value, int) and float in types:
        return True
    return isinstance(value, types)


def check(data: Mapping[str, Any], schema: Section, file: str | Path, prefix: str = "") -> None:
    """Validate parsed TOML ``data`` against ``schema``; raise :class:`ScenarioError`.

    Messages read ``<file>: key 'simulate.dt': expected a number, got string 'abc'``.
    """
    where = str(file)
    known = set(schema.keys) | set(schema.sections) | set(schema.array_sections)
    for key, value in data.items():
        path = f"{prefix}{key}"
        if key in schema.sections:
            if not isinstance(value, dict):
                raise ScenarioError(
                    f"{where}: key {path!r}: expected a table, got {_type_name(value)} {value!r}"
                )
            check(value, schema.sections[key], file, prefix=path + ".")
        elif key in schema.array_sections:
            if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
                raise ScenarioError(
                    f"{where}: key {path!r}: expected an array of tables ([[{path}]]), got {_type_name(value)}"
                )
            for i, item in enumerate(value):
                check(item, schema.array_sections[key], file, prefix=f"{path}[{i}].")
        elif key in schema.keys:
            spec = schema.keys[key]
            if not _ok(value, spec.types):
                raise ScenarioError(
                    f"{where}: key {path!r}: expected {spec.expected()}, got {_type_name(value)} {value!r}"
                )
            if spec.item_types is not None and isinstance(value, list):
                for i, item in enumerate(value):
                    if not _ok(item, spec.item_types):
                        raise ScenarioError(
                            f"{where}: key {path}[{i}]: expected {spec.expected()}, got {_type_name(item)} {item!r}"
                        )
            if spec.max_items is not None and isinstance(value, list) and len(value) > spec.max_items:
                raise ScenarioError(
                    f"{where}: key {path!r}: expected at most {spec.max_items} items, got {len(value)}"
                )
            numbers = value if isinstance(value, list) else [value]
            for i, item in enumerate(numbers):
                if isinstance(item, int | float) and not isinstance(item, bool) and not spec.number_ok(float(item)):
                    at = f"{path}[{i}]" if isinstance(value, list) else path
                    want = "a finite number" if spec.low is None and spec.high is None else f"a finite number in {spec.range_text()}"
                    raise ScenarioError(f"{where}: key {at!r}: expected {want}, got {item!r}")
            if spec.choices is not None and value not in spec.choices:
                raise ScenarioError(
                    f"{where}: key {path!r}: expected one of {list(spec.choices)}, got {value!r}"
                )
        elif not schema.open_keys:
            raise ScenarioError(f"{where}: unknown key {path!r}; expected one of {sorted(known)}")
    for key, spec in schema.keys.items():
        if spec.required and key not in data:
            raise ScenarioError(
                f"{where}: missing required key {prefix + key!r} ({spec.expected()}: {spec.help})"
            )
    for key, sec in schema.sections.items():
        if sec.required and key not in data:
            raise ScenarioError(f"{where}: missing required table [{prefix + key}]")
