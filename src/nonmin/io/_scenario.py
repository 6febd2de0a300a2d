"""Scenario files (TOML): model, initial state, integrator, stabilization, controller, events,
duration and outputs. Every key maps to an API keyword (see ``docs/scenarios.md``)."""

from __future__ import annotations

import importlib
import tomllib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import NonminError, ScenarioError, UnknownNameError
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
                "t0": Key(_NUM),
                "assemble": Key((bool,), help="assemble q, qd onto the constraints first"),
                "fixed": Key((list,), item_types=(str,), help="coordinates assembly keeps"),
            }
        ),
        "simulate": Section(
            keys={
                "t_final": Key(_NUM, help="end time [s]"),
                "method": Key((str,), help="integrator name (see `nonmin list`)"),
                "dt": Key(_NUM, help="(initial) step size [s]"),
                "rtol": Key(_NUM),
                "atol": Key(_NUM),
                "stabilization": Key((str,), help="stabilizer name (see `nonmin list`)"),
                "contact": Key((bool,), help="automatic unilateral contact handling"),
                "restitution": Key(_NUM, help="restitution of automatic contact impacts"),
                "output_dt": Key(_NUM, help="sampling of the stored trajectory [s]"),
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
                "dir": Key((str,), help="output folder (relative to the scenario file)"),
                "plots": Key((bool,)),
                "animation": Key((str, bool), help="animation file name (.gif/.mp4) or false"),
                "csv": Key((bool,)),
                "trajectory": Key((str,), help="trajectory file name (.npz)"),
                "fps": Key(_NUM),
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
                "restitution": Key(_NUM),
            }
        )
    },
)


def resolve_entry_point(spec: str, file: str | Path, key: str) -> Callable[..., Any]:
    """Import ``'package.module:attr'``; errors name the scenario file and key."""
    if ":" not in spec:
        raise ScenarioError(
            f"{file}: key {key!r}: expected 'package.module:function', got {spec!r}"
        )
    mod_name, _, attr = spec.partition(":")
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
    """

    path: Path
    data: Mapping[str, Any] = field(repr=False)

    @property
    def name(self) -> str:
        return str(self.data.get("name", self.path.stem))

    def section(self, name: str) -> dict[str, Any]:
        return dict(self.data.get(name, {}))

    def resolve_path(self, rel: str) -> Path:
        p = Path(rel)
        return p if p.is_absolute() else (self.path.parent / p)

    def output_dir(self, override: str | Path | None = None) -> Path:
        if override is not None:
            return Path(override)
        rel = self.section("output").get("dir")
        return self.resolve_path(rel) if rel else Path.cwd() / f"{self.path.stem}-out"

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
                fn = resolve_entry_point(m["entry_point"], self.path, "model.entry_point")
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
        except UnknownNameError as exc:
            raise ScenarioError(f"{self.path}: key 'model.{src}': {exc}") from None
        except TypeError as exc:
            raise ScenarioError(f"{self.path}: table [model.params]: {exc}") from None
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


def load_scenario(path: str | Path) -> Scenario:
    """Read and validate a TOML scenario file.

    Raises
    ------
    ScenarioError
        If the file is missing, is not valid TOML, or has unknown keys / wrong types (the
        message names the file, the key, what was expected and what came).
    """
    p = Path(path)
    if not p.exists():
        raise ScenarioError(f"{p}: scenario file not found")
    try:
        data = tomllib.loads(p.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{p}: not valid TOML: {exc}") from None
    check(data, SCENARIO_SCHEMA, p)
    return Scenario(path=p, data=data)
