"""Scenario files (TOML): model, initial state, integrator, stabilization, controller, events,
duration and outputs. Every key maps to an API keyword (see ``docs/scenarios.md``)."""

from __future__ import annotations

import importlib
import math
import tomllib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .._files import confined
from ..errors import (
    FileFormatError,
    InputError,
    MissingDependencyError,
    ModelError,
    NonminError,
    ScenarioError,
    UnknownNameError,
    UntrustedCodeError,
)
from ._schema import Key, Section, check

__all__ = ["SCENARIO_SCHEMA", "Scenario", "load_scenario", "resolve_entry_point"]

_NUM = (float, int)
_NUMLIST = Key((list,), item_types=_NUM)

#: The schema of scenario files: every section and key, its type and help text.
_DESCRIPTION = Section(
    keys={
        "name": Key((str,)),
        "description": Key((str,)),
        "gravity": _NUMLIST,
    },
    array_sections={"items": Section(keys={"call": Key((str,), required=True)}, open_keys=True)},
    help="builder calls in order: call = method name, other keys = its arguments",
)

#: The schema of scenario files: every section and key, its type and help text.
SCENARIO_SCHEMA = Section(
    keys={
        "name": Key((str,), help="scenario name"),
        "description": Key((str,), help="free text"),
    },
    sections={
        "model": Section(
            required=True,
            keys={
                "library": Key((str,), help="name in nonmin.library (see `nonmin list`)"),
                "entry_point": Key(
                    (str,), help="'package.module:function' returning a Model or Mechanism"
                ),
                "urdf": Key((str,), help="URDF file (relative to the scenario file)"),
                "mjcf": Key((str,), help="MJCF file (relative to the scenario file)"),
                "root_joint": Key((str,), choices=("fixed", "freeflyer"), help="URDF base"),
                "inactive": Key(
                    (list,), item_types=(str,), help="[[model.constraints]] names starting inactive"
                ),
            },
            sections={
                "params": Section(open_keys=True, help="keyword arguments of the model source"),
                "planar": _DESCRIPTION,
                "spatial": _DESCRIPTION,
            },
            array_sections={
                "constraints": Section(keys={"type": Key((str,), required=True)}, open_keys=True)
            },
        ),
        "initial": Section(
            keys={
                "q": _NUMLIST,
                "qd": _NUMLIST,
                "active": Key((list,), item_types=(str,), help="active constraint names"),
                "t0": Key(_NUM, help="start time [s]"),
                "assemble": Key((bool,), help="assemble q, qd onto the constraints first"),
                "fixed": Key((list,), item_types=(str,), help="coordinates assembly keeps"),
            }
        ),
        "simulate": Section(
            keys={
                "t_final": Key(_NUM, help="end time [s]"),
                "method": Key((str,), help="integrator name (see `nonmin list`)"),
                "dt": Key(_NUM, low=0.0, low_open=True, help="(initial) step size [s]"),
                "rtol": Key(_NUM, low=0.0, low_open=True, high=1.0),
                "atol": Key(_NUM, low=0.0, low_open=True),
                "stabilization": Key((str,), help="stabilizer name (see `nonmin list`)"),
                "contact": Key((bool,), help="automatic unilateral contact handling"),
                "restitution": Key(_NUM, low=0.0, high=1.0, help="restitution of automatic contact impacts"),
                "output_dt": Key(_NUM, low=0.0, low_open=True, help="sampling of the stored trajectory [s]"),
            },
            sections={"options": Section(open_keys=True, help="further simulate() keywords")},
        ),
        "controller": Section(
            keys={"type": Key((str,), required=True, help="controller name (see `nonmin list`)")},
            open_keys=True,
            help="remaining keys are the controller's keyword arguments",
        ),
        "output": Section(
            keys={
                "dir": Key((str,), help="output folder, relative, inside the scenario's folder"),
                "plots": Key((bool,)),
                "animation": Key((str, bool), help="animation file name (.gif/.mp4) or false"),
                "csv": Key((bool,)),
                "trajectory": Key((str,), help="trajectory file name (.npz)"),
                "fps": Key(_NUM, low=0.0, low_open=True, high=1000.0),
            }
        ),
    },
    array_sections={
        "events": Section(
            keys={
                "name": Key((str,), required=True),
                "at_time": Key(_NUM, help="fire when t crosses this value"),
                "guard": Key(
                    (str,), help="'package.module:function' guard(t, q, qd, f_c) -> float"
                ),
                "direction": Key((int,), choices=(-1, 0, 1)),
                "terminal": Key((bool,)),
                "transition": Key((str,), choices=("none", "activate", "deactivate")),
                "constraints": Key((list,), item_types=(str,)),
                "restitution": Key(_NUM, low=0.0, high=1.0),
            }
        )
    },
)


def resolve_entry_point(
    spec: str, file: str | Path, key: str, *, allow_code: bool = False
) -> Callable[..., Any]:
    """Import ``'package.module:attr'``; errors name the scenario file and key.

    Importing a module runs its code, and the function is then called: a scenario file that
    names an entry point is a program. Without ``allow_code=True`` (``--allow-code`` on the
    command line) this raises :class:`~nonmin.errors.UntrustedCodeError` before importing
    anything.
    """
    if not allow_code:
        raise UntrustedCodeError(
            f"{file}: key {key!r}: {spec!r} names code to import and run; scenario files with "
            "entry points are programs — run them only if you trust their author, with "
            "--allow-code (command line) or allow_code=True (load_scenario / run_scenario)"
        )
    if not isinstance(spec, str) or spec.count(":") != 1:
        raise ScenarioError(
            f"{file}: key {key!r}: expected 'package.module:function', got {spec!r}"
        )
    mod_name, _, attr = spec.partition(":")
    if not mod_name or not attr or not all(p.isidentifier() for p in (*mod_name.split("."), *attr.split("."))):
        raise ScenarioError(
            f"{file}: key {key!r}: expected 'package.module:function' (dotted identifiers), got {spec!r}"
        )
    try:
        mod = importlib.import_module(mod_name)
    except ImportError as exc:
        raise ScenarioError(
            f"{file}: key {key!r}: cannot import module {mod_name!r}: {exc}"
        ) from None
    obj: Any = mod
    for part in attr.split("."):
        if not hasattr(obj, part):
            raise ScenarioError(
                f"{file}: key {key!r}: module {mod_name!r} has no attribute {attr!r}"
            )
        obj = getattr(obj, part)
    if not callable(obj):
        raise ScenarioError(f"{file}: key {key!r}: {spec!r} is not callable")
    return obj  # type: ignore[no-any-return]


@dataclass(frozen=True)
class Scenario:
    """A parsed, validated scenario file.

    Attributes
    ----------
    path : Path
        The scenario file.
    data : dict
        The parsed TOML (validated against :data:`SCENARIO_SCHEMA`).
    allow_code : bool
        Whether ``entry_point`` and ``guard`` keys may import and run code (see
        :func:`load_scenario`).
    """

    path: Path
    data: Mapping[str, Any] = field(repr=False)
    allow_code: bool = False

    @property
    def name(self) -> str:
        return str(self.data.get("name", self.path.stem))

    def section(self, name: str) -> dict[str, Any]:
        return dict(self.data.get(name, {}))

    def resolve_path(self, rel: str) -> Path:
        p = Path(rel)
        return p if p.is_absolute() else (self.path.parent / p)

    def output_dir(self, override: str | Path | None = None) -> Path:
        """The output folder: ``override`` (the caller's, e.g. ``--out``), else ``[output] dir``
        (relative, inside the scenario file's folder), else ``./<scenario stem>-out``."""
        if override is not None:
            return Path(override)
        rel = self.section("output").get("dir")
        if rel:
            return confined(self.path.parent, rel, file=self.path, key="output.dir")
        return Path.cwd() / f"{self.path.stem}-out"

    # ------------------------------------------------------------------ building
    def build_model(self) -> tuple[Any, Any]:
        """Return ``(model, default_state_or_None)`` from the [model] table."""
        model, state, _ = self.build_source()
        return model, state

    def build_source(self) -> tuple[Any, Any, float | None]:
        """``(model, default_state_or_None, horizon_or_None)`` from the [model] table, built once;
        the horizon is a mechanism's benchmark ``t_final`` (library or entry point)."""
        m = self.section("model")
        sources = [k for k in ("library", "entry_point", "urdf", "mjcf", "planar", "spatial") if k in m]
        if len(sources) != 1:
            raise ScenarioError(
                f"{self.path}: table [model] needs exactly one of 'library', 'entry_point', "
                f"'urdf', 'mjcf', [model.planar], [model.spatial], got {sources or 'none'}"
            )
        if "constraints" in m and sources[0] not in ("urdf", "mjcf"):
            raise ScenarioError(
                f"{self.path}: [[model.constraints]] applies to 'urdf'/'mjcf' models only"
            )
        params = dict(m.get("params", {}))
        src = sources[0]
        obj: Any
        try:
            if src == "library":
                from .. import library

                obj = library.get(m["library"], **params)
            elif src in ("planar", "spatial"):
                from ._describe import build_planar, build_spatial

                build = build_planar if src == "planar" else build_spatial
                obj = build(m[src], self.path)
                if src == "spatial":
                    return obj, obj.state(obj.reference_configuration()), None
            elif src == "entry_point":
                fn = resolve_entry_point(
                    m["entry_point"], self.path, "model.entry_point", allow_code=self.allow_code
                )
                obj = fn(**params)
            else:
                from ..model import robots

                path = self.resolve_path(m[src])
                if not path.exists():
                    raise ScenarioError(f"{self.path}: key 'model.{src}': file not found: {path}")
                from ._describe import frame_constraints

                cons = frame_constraints(m.get("constraints", []), self.path)
                if cons:
                    params["constraints"] = cons
                    inactive = set(m.get("inactive", []))
                    params.setdefault(
                        "default_active", [c.name for c in cons if c.name not in inactive]
                    )
                if src == "urdf":
                    kw = dict(params)
                    if m.get("root_joint") == "freeflyer":
                        kw["root_joint"] = "freeflyer"
                    obj = robots.RobotModel.from_urdf(path, **kw)
                else:
                    obj = robots.RobotModel.from_mjcf(path, **params)
        except (UnknownNameError, FileFormatError) as exc:
            raise ScenarioError(f"{self.path}: key 'model.{src}': {exc}") from None
        except (ScenarioError, MissingDependencyError):
            raise
        except (InputError, ModelError) as exc:
            raise ScenarioError(f"{self.path}: key 'model.{src}' (with [model.params]): {exc}") from None
        except (TypeError, ValueError, ArithmeticError) as exc:
            raise ScenarioError(f"{self.path}: table [model.params]: {type(exc).__name__}: {exc}") from None
        if hasattr(obj, "model") and hasattr(obj, "state"):
            horizon = getattr(obj, "t_final", None)
            return obj.model, obj.state, None if horizon is None else float(horizon)
        from ..model import Model

        if not isinstance(obj, Model):
            raise ScenarioError(
                f"{self.path}: key 'model.{src}': expected a Model or Mechanism, got {type(obj).__name__}"
            )
        return obj, None, None

    def initial_state(self, model: Any, default: Any) -> Any:
        """The initial :class:`~nonmin.model.State` from [initial] (over the default one)."""
        ini = self.section("initial")
        t0 = float(ini.get("t0", default.t if default is not None else 0.0))
        active = ini.get("active", sorted(default.active) if default is not None else None)
        if "q" in ini:
            q = np.asarray(ini["q"], dtype=float)
        elif default is not None:
            q = default.q
        else:
            raise ScenarioError(
                f"{self.path}: table [initial] needs 'q' for a model without a default state"
            )
        if "qd" in ini:
            qd = np.asarray(ini["qd"], dtype=float)
        elif default is not None and "q" not in ini:
            qd = default.qd
        else:
            qd = np.zeros(model.n)
        for key, arr in (("q", q), ("qd", qd)):
            if arr.shape != (model.n,):
                raise ScenarioError(
                    f"{self.path}: key 'initial.{key}': expected {model.n} numbers "
                    f"(one per coordinate {list(model.coordinate_names)}), got {arr.size}"
                )
        try:
            state = model.state(q, qd, t=t0, active=active)
        except NonminError as exc:
            raise ScenarioError(f"{self.path}: table [initial]: {exc}") from None
        if ini.get("assemble", False):
            from ..model import assemble

            try:
                state = assemble(
                    model, state.q, state.qd, t=state.t, active=state.active, fixed=ini.get("fixed")
                )
            except NonminError as exc:
                raise ScenarioError(f"{self.path}: table [initial]: {exc}") from None
        return state


def _finite_everywhere(data: Any, file: Path, prefix: str = "") -> None:
    """TOML accepts ``inf`` and ``nan``: refuse them in every table, open ones included."""
    if isinstance(data, dict):
        for k, v in data.items():
            _finite_everywhere(v, file, f"{prefix}{k}" if not prefix else f"{prefix}.{k}")
    elif isinstance(data, list):
        for i, v in enumerate(data):
            _finite_everywhere(v, file, f"{prefix}[{i}]")
    elif isinstance(data, float) and not math.isfinite(data):
        raise ScenarioError(f"{file}: key {prefix!r}: expected a finite number, got {data!r}")


#: Largest scenario file read (bytes): scenario files are small, anything bigger is a mistake.
MAX_SCENARIO_BYTES = 4 * 2**20


def load_scenario(path: str | Path, *, allow_code: bool = False) -> Scenario:
    """Read and validate a TOML scenario file.

    Parameters
    ----------
    path : str or Path
    allow_code : bool, default False
        Let ``[model] entry_point`` and ``[[events]] guard`` import and run the functions they
        name. Scenario files with entry points are programs: opt in only for files you trust.
        Without it such a scenario raises :class:`~nonmin.errors.UntrustedCodeError` when it is
        built (nothing is imported).

    Raises
    ------
    ScenarioError
        If the file is missing, is not valid TOML, or has unknown keys / wrong types / numbers
        out of range (the message names the file, the key, what was expected and what came).
    """
    p = Path(path)
    if not p.is_file():
        raise ScenarioError(f"{p}: scenario file not found")
    try:
        size = p.stat().st_size
        if size > MAX_SCENARIO_BYTES:
            raise ScenarioError(f"{p}: {size} bytes; scenario files are at most {MAX_SCENARIO_BYTES}")
        text = p.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise ScenarioError(f"{p}: not UTF-8 text: {exc}") from None
    except OSError as exc:
        raise ScenarioError(f"{p}: cannot read the scenario file: {exc.strerror or exc}") from None
    try:
        data = tomllib.loads(text)
    except (tomllib.TOMLDecodeError, RecursionError) as exc:
        raise ScenarioError(f"{p}: not valid TOML: {exc}") from None
    _finite_everywhere(data, p)
    check(data, SCENARIO_SCHEMA, p)
    return Scenario(path=p, data=data, allow_code=bool(allow_code))
