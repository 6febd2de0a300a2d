"""Result records of the validation suite, the comparison table and the Markdown report."""

from __future__ import annotations

import datetime as _dt
import math
import os
import platform
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

__all__ = ["Check", "ValidationRecord", "format_table", "machine_info", "write_report"]

Comparison = Literal["<=", ">=", "==", "report"]


@dataclass(frozen=True)
class Check:
    """One measured quantity against its stated target.

    Attributes
    ----------
    name : str
        What is measured (e.g. ``"|B0(10) - B0_ref|"``).
    value : float, int, bool or str
        The measured value (``bool`` for yes/no checks such as "stays on branch"; ``str`` for
        reported-only descriptions).
    target : float or bool or None
        The stated target; ``None`` for reported-only quantities.
    comparison : {"<=", ">=", "==", "report"}
        How ``value`` must compare with ``target``; ``"report"`` never fails.
    unit : str
        Unit of ``value`` (free text).
    """

    name: str
    value: float | int | bool | str
    target: float | bool | None = None
    comparison: Comparison = "report"
    unit: str = ""

    @property
    def passed(self) -> bool:
        """Whether ``value`` meets ``target`` (always true for reported-only checks)."""
        if self.comparison == "report" or self.target is None:
            return True
        if isinstance(self.value, bool) or isinstance(self.target, bool):
            return bool(self.value) == bool(self.target)
        if isinstance(self.value, str):
            return False
        v = float(self.value)
        if not math.isfinite(v):
            return False
        t = float(self.target)
        if self.comparison == "<=":
            return v <= t
        if self.comparison == ">=":
            return v >= t
        return v == t

    def format_value(self) -> str:
        return _fmt(self.value)

    def format_target(self) -> str:
        if self.comparison == "report" or self.target is None:
            return "(reported)"
        return f"{self.comparison} {_fmt(self.target)}"

    def to_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "value": _jsonable(self.value),
            "target": _jsonable(self.target),
            "comparison": self.comparison,
            "unit": self.unit,
            "passed": self.passed,
        }


@dataclass(frozen=True)
class ValidationRecord:
    """The outcome of one validation benchmark.

    Attributes
    ----------
    name : str
        Benchmark name (``"A01 pendulum"``, ...).
    checks : tuple of Check
        Measured quantities with their targets.
    settings : mapping
        Simulator settings used (method, step or tolerances, stabilization, horizon).
    reference : str
        Where the reference values come from.
    wall_time : float
        Wall-clock seconds of the simulation(s) (setup and reference excluded).
    quick : bool
        Whether this is the shortened version of the benchmark.
    notes : str
        Anything the reader must know (failures are explained here).
    error : str
        Non-empty when the benchmark could not run (the exception, type and message).
    """

    name: str
    checks: tuple[Check, ...]
    settings: Mapping[str, Any] = field(default_factory=dict)
    reference: str = ""
    wall_time: float = math.nan
    quick: bool = False
    notes: str = ""
    error: str = ""

    @property
    def passed(self) -> bool:
        """True when the benchmark ran and every check met its target."""
        return not self.error and all(c.passed for c in self.checks)

    def check(self, name: str) -> Check:
        """The check called ``name`` (``KeyError`` if absent)."""
        for c in self.checks:
            if c.name == name:
                return c
        raise KeyError(name)

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> ValidationRecord:
        """Inverse of :meth:`to_dict` (e.g. to rewrite a report from saved results)."""
        checks = tuple(
            Check(c["name"], _from_json(c["value"]), _from_json(c["target"]), c["comparison"],
                  c.get("unit", ""))
            for c in d.get("checks", ())
        )
        return cls(name=d["name"], checks=checks, settings=dict(d.get("settings", {})),
                   reference=d.get("reference", ""), wall_time=float(d.get("wall_time", math.nan)),
                   quick=bool(d.get("quick", False)), notes=d.get("notes", ""),
                   error=d.get("error", ""))

    def to_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "passed": self.passed,
            "quick": self.quick,
            "settings": {k: _jsonable(v) for k, v in self.settings.items()},
            "reference": self.reference,
            "wall_time": self.wall_time,
            "notes": self.notes,
            "error": self.error,
            "checks": [c.to_dict() for c in self.checks],
        }


def _jsonable(x: Any) -> Any:
    if isinstance(x, bool | str) or x is None:
        return x
    if isinstance(x, int | np.integer):
        return int(x)
    if isinstance(x, float | np.floating):
        v = float(x)
        return v if math.isfinite(v) else str(v)
    if isinstance(x, list | tuple):
        return [_jsonable(v) for v in x]
    return str(x)


def _from_json(x: Any) -> Any:
    if isinstance(x, str) and x in ("inf", "-inf", "nan"):
        return float(x)
    return x


def _fmt(x: Any) -> str:
    if isinstance(x, bool | np.bool_):
        return "yes" if x else "no"
    if isinstance(x, int | np.integer):
        return str(int(x))
    if isinstance(x, float | np.floating):
        v = float(x)
        if v == 0.0:
            return "0"
        if not math.isfinite(v):
            return str(v)
        if 1e-3 <= abs(v) < 1e5:
            return f"{v:.6g}"
        return f"{v:.2e}"
    return str(x)


def _settings_str(settings: Mapping[str, Any]) -> str:
    return ", ".join(f"{k}={_fmt(v)}" for k, v in settings.items())


def format_table(records: Sequence[ValidationRecord]) -> str:
    """Plain-text table: one line per check, grouped by benchmark, with PASS/FAIL.

    Parameters
    ----------
    records : sequence of ValidationRecord

    Returns
    -------
    str
    """
    rows: list[tuple[str, ...]] = [("benchmark", "quantity", "value", "target", "result")]
    for r in records:
        if r.error:
            rows.append((r.name, "(did not run)", r.error[:60], "", "FAIL"))
            continue
        for i, c in enumerate(r.checks):
            rows.append(
                (
                    r.name if i == 0 else "",
                    c.name + (f" [{c.unit}]" if c.unit else ""),
                    c.format_value(),
                    c.format_target(),
                    "pass" if c.passed else "FAIL",
                )
            )
        rows.append(("", "wall time [s]", _fmt(r.wall_time), "", ""))
    widths = [max(len(row[i]) for row in rows) for i in range(5)]
    lines = []
    for k, row in enumerate(rows):
        lines.append("  ".join(cell.ljust(w) for cell, w in zip(row, widths)).rstrip())
        if k == 0:
            lines.append("  ".join("-" * w for w in widths))
    n_fail = sum(not r.passed for r in records)
    lines.append("")
    lines.append(
        f"{len(records) - n_fail}/{len(records)} benchmarks passed"
        + ("" if n_fail == 0 else f"; FAILED: {', '.join(r.name for r in records if not r.passed)}")
    )
    return "\n".join(lines)


def machine_info() -> dict[str, Any]:
    """Platform, CPU, core count, load average and library versions (for reports)."""
    cpu = ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        cpu = platform.processor()
    try:
        load: tuple[float, ...] = tuple(round(x, 2) for x in os.getloadavg())
    except OSError:
        load = ()
    import scipy

    from .._version import __version__

    return {
        "platform": platform.platform(),
        "cpu": cpu,
        "cpu_count": os.cpu_count(),
        "load_average_1_5_15min": load,
        "python": platform.python_version(),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "nonmin": __version__,
        "OPENBLAS_NUM_THREADS": os.environ.get("OPENBLAS_NUM_THREADS", "(unset)"),
    }


def _md_escape(s: str) -> str:
    return s.replace("|", "\\|")


def write_report(
    records: Sequence[ValidationRecord],
    path: str | os.PathLike[str] = "docs/validation.md",
    *,
    command: str = "nonmin validate --full --report docs/validation.md",
    notes: str = "",
) -> Path:
    """Write the validation report as Markdown.

    Parameters
    ----------
    records : sequence of ValidationRecord
    path : path-like, default ``"docs/validation.md"``
    command : str
        The command that regenerates the report (written at the top).
    notes : str
        Markdown written after the machine section (how the runs were made, findings).

    Returns
    -------
    pathlib.Path
        The file written.
    """
    info = machine_info()
    quick = any(r.quick for r in records)
    out: list[str] = []
    out.append("# Validation report")
    out.append("")
    out.append(
        "Generated by `nonmin.validation` "
        f"({'QUICK versions' if quick else 'full versions'} of the benchmarks) on "
        f"{_dt.datetime.now(_dt.UTC).strftime('%Y-%m-%d %H:%M UTC')}."
    )
    out.append("")
    out.append(f"Regenerate with: `{command}`")
    out.append("")
    out.append(
        "Problems and reference values: IFToMM / A Coruña benchmark library (A01–A04), "
        "the Test Set for IVP Solvers (A03 Andrews), closed-form or exact 1-DOF reductions; "
        "see `src/nonmin/data/validation/` for the reference files."
    )
    out.append("")
    out.append("## Machine")
    out.append("")
    for k, v in info.items():
        out.append(f"- {k}: {v}")
    out.append("")
    if notes:
        out.append(notes.rstrip())
        out.append("")
    n_pass = sum(r.passed for r in records)
    out.append(f"## Summary: {n_pass}/{len(records)} benchmarks meet every target")
    out.append("")
    out.append("| benchmark | result | wall time [s] | settings |")
    out.append("|---|---|---|---|")
    for r in records:
        out.append(
            f"| {r.name} | {'pass' if r.passed else '**FAIL**'} | {_fmt(r.wall_time)} | "
            f"{_md_escape(_settings_str(r.settings))} |"
        )
    out.append("")
    for r in records:
        out.append(f"## {r.name}")
        out.append("")
        if r.reference:
            out.append(f"Reference: {r.reference}")
            out.append("")
        out.append(f"Settings: {_settings_str(r.settings)}")
        out.append("")
        if r.error:
            out.append(f"**Did not run:** `{r.error}`")
            out.append("")
        else:
            out.append("| quantity | value | target | result |")
            out.append("|---|---|---|---|")
            for c in r.checks:
                name = c.name + (f" [{c.unit}]" if c.unit else "")
                out.append(
                    f"| {_md_escape(name)} | {c.format_value()} | "
                    f"{_md_escape(c.format_target())} | {'pass' if c.passed else '**FAIL**'} |"
                )
            out.append("")
        if r.notes:
            out.append(r.notes)
            out.append("")
    from .._files import write_text

    return write_text(Path(path), "\n".join(out) + "\n")
