"""What a sweep varies, and how each run's inputs are built.

A sweep is a *base* — a scenario (file or :class:`~nonmin.io.Scenario`) or a model/mechanism
with :func:`~nonmin.sim.simulate` keywords — and *axes*: a key and its values. Axes of
explicit values and :class:`Grid` ranges are crossed (every combination); :class:`Uniform`
ranges are drawn ``samples`` times with a seeded generator (each draw crossed with the grid).
A tuple of keys is one *zipped* axis whose values give one entry per key (``{("q0", "qd0"):
[(q_a, qd_a), (q_b, qd_b)]}``: whole initial states). Runs are numbered in a fixed order, so a
rerun of the same sweep names the same runs.

Keys of a scenario base are dotted paths into its TOML (``model.params.omega0``,
``simulate.dt``, ``initial.qd[2]`` — an index sets one entry of a list). Keys of a model base
are ``q0``, ``qd0`` (whole vectors), ``q0.<coordinate>`` / ``qd0.<coordinate>`` (one entry,
by coordinate name), ``params.<field>`` (a field of ``model.replace``), ``t_final`` and any
:func:`simulate` keyword (``dt``, ``method``, ``restitution``, ...). A base may also be a
model source — a function returning a Model or Mechanism, e.g. ``nonmin.library.crossed_four_bar``
— whose keyword arguments are the ``params.<name>`` keys (called once per distinct set).
"""

from __future__ import annotations

import copy
import itertools
import json
import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import InputError, ScenarioError

__all__ = ["Grid", "RunInputs", "SweepSpec", "Uniform", "parse_vary"]


@dataclass(frozen=True)
class Grid:
    """``count`` evenly spaced values from ``start`` to ``stop`` (both included)."""

    start: float
    stop: float
    count: int

    def __post_init__(self) -> None:
        if not (math.isfinite(self.start) and math.isfinite(self.stop)):
            raise InputError(f"Grid: start and stop must be finite, got {self.start}, {self.stop}")
        if isinstance(self.count, bool) or not isinstance(self.count, int) or self.count < 1:
            raise InputError(f"Grid: count must be an integer ≥ 1, got {self.count!r}")

    def values(self) -> list[float]:
        return [float(v) for v in np.linspace(self.start, self.stop, self.count)]


@dataclass(frozen=True)
class Uniform:
    """Values drawn uniformly from ``[low, high)`` (``samples`` of them, seeded)."""

    low: float
    high: float

    def __post_init__(self) -> None:
        if not (math.isfinite(self.low) and math.isfinite(self.high) and self.high >= self.low):
            raise InputError(f"Uniform: need finite low ≤ high, got {self.low}, {self.high}")


def parse_vary(text: str) -> tuple[str, Any]:
    """``key=start:stop:count`` (grid), ``key=low:high`` (random, needs samples) or
    ``key=v1,v2,...`` (explicit values) → ``(key, axis)``."""
    key, sep, val = text.partition("=")
    key = key.strip()
    if not sep or not key or not val.strip():
        raise InputError(f"--vary: expected KEY=START:STOP:COUNT, KEY=LOW:HIGH or KEY=V1,V2,..., got {text!r}")

    def num(s: str) -> float | int | str | bool:
        s = s.strip()
        for conv in (int, float):
            try:
                return conv(s)
            except ValueError:
                pass
        if s in ("true", "false"):
            return s == "true"
        return s

    if ":" in val:
        parts = val.split(":")
        try:
            nums = [float(p) for p in parts]
        except ValueError:
            raise InputError(f"--vary {key}: {val!r} is not START:STOP:COUNT or LOW:HIGH numbers") from None
        if len(parts) == 3:
            if not nums[2].is_integer() or nums[2] < 1:
                raise InputError(f"--vary {key}: COUNT must be an integer ≥ 1, got {parts[2]!r}")
            return key, Grid(nums[0], nums[1], int(nums[2]))
        if len(parts) == 2:
            return key, Uniform(nums[0], nums[1])
        raise InputError(f"--vary {key}: expected START:STOP:COUNT or LOW:HIGH, got {val!r}")
    return key, [num(s) for s in val.split(",")]


@dataclass(frozen=True)
class RunInputs:
    """Everything one run needs (built on the worker)."""

    model: Any
    q0: np.ndarray
    qd0: np.ndarray
    active: frozenset[str]
    t_span: tuple[float, float]
    options: dict[str, Any]

    def group_key(self) -> str:
        """Runs with the same key share one batched engine call (same settings and horizon)."""
        opts = {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in self.options.items()}
        return json.dumps([self.t_span, opts], sort_keys=True, default=repr)


_INDEX = re.compile(r"^(.*)\[(\d+)\]$")


def _set_path(data: dict[str, Any], key: str, value: Any, where: str) -> None:
    parts = key.split(".")
    node: Any = data
    for p in parts[:-1]:
        if not isinstance(node, dict):
            raise ScenarioError(f"{where}: key {key!r}: {p!r} is not a table")
        node = node.setdefault(p, {})
    last = parts[-1]
    m = _INDEX.match(last)
    if m:
        name, i = m.group(1), int(m.group(2))
        lst = node.get(name)
        if not isinstance(lst, list) or i >= len(lst):
            raise ScenarioError(f"{where}: key {key!r}: {name!r} has no entry {i} (set the whole list first)")
        lst[i] = value
    else:
        node[last] = value


@dataclass(frozen=True)
class SweepSpec:
    """A sweep: base, axes, sampling, and the settings shared by every run. Pickles cleanly
    (a scenario's parsed TOML, or the model itself, plus plain values)."""

    base: Any  # Scenario or Model/Mechanism
    axes: tuple[tuple[Any, Any], ...]  # (key or tuple of keys: a zipped axis, values)
    samples: int | None = None
    seed: int | None = None
    t_span: Any = None  # model base: (t0, t1) or t1
    options: Mapping[str, Any] = field(default_factory=dict)  # model base: simulate keywords

    # ------------------------------------------------------------------ the runs
    def table(self) -> list[dict[str, Any]]:
        """The value of every key for every run, in run order."""
        grid = [(k, v) for k, v in self.axes if not isinstance(v, Uniform)]
        rand = [(k, v) for k, v in self.axes if isinstance(v, Uniform)]
        if rand and not self.samples:
            raise InputError(f"axes {[k for k, _ in rand]} are random ranges: give samples=N")
        gvals = []
        for k, v in grid:
            vals = v.values() if isinstance(v, Grid) else list(v)
            if not vals:
                raise InputError(f"axis {k!r} has no values")
            gvals.append(vals)
        combos = list(itertools.product(*gvals)) if grid else [()]

        def assign(row: dict[str, Any], key: Any, value: Any) -> None:
            if isinstance(key, tuple):  # a zipped axis: one value per key
                if not isinstance(value, Sequence) or len(value) != len(key):
                    raise InputError(f"axis {key!r}: each value must give {len(key)} entries, got {value!r}")
                row.update(zip(key, value))
            else:
                row[key] = value

        rows: list[dict[str, Any]] = []
        for c in combos:
            base: dict[str, Any] = {}
            for (k, _), v in zip(grid, c):
                assign(base, k, v)
            if rand or self.samples:
                rows.extend({**base} for _ in range(int(self.samples or 1)))
            else:
                rows.append(base)
        if rand:
            rng = np.random.default_rng(self.seed)
            draws = [rng.uniform(u.low, u.high, int(self.samples or 1)) for _, u in rand]
            for r, row in enumerate(rows):
                s = r % int(self.samples or 1)
                row.update({k: float(d[s]) for (k, _), d in zip(rand, draws)})
        return rows

    def describe(self) -> dict[str, Any]:
        """A JSON summary (stored with the sweep; a rerun must match it)."""
        axes = []
        for k0, v in self.axes:
            k = list(k0) if isinstance(k0, tuple) else k0
            if isinstance(v, Grid):
                axes.append({"key": k, "grid": [v.start, v.stop, v.count]})
            elif isinstance(v, Uniform):
                axes.append({"key": k, "uniform": [v.low, v.high]})
            else:
                axes.append({"key": k, "values": [_jsonable(x) for x in v]})
        from ..io import Scenario

        if isinstance(self.base, Scenario):
            base: Any = {"scenario": str(self.base.path), "data": _jsonable(self.base.data)}
        else:
            from ..model import Model

            model = getattr(self.base, "model", self.base)
            if isinstance(model, Model):
                name = model.name
            else:  # a model source
                name = f"{getattr(model, '__module__', '?')}.{getattr(model, '__qualname__', type(model).__name__)}"
            base = {"model": name, "t_span": _jsonable(self.t_span), "options": _jsonable(dict(self.options))}
        return {"base": base, "axes": axes, "samples": self.samples, "seed": self.seed}

    # ------------------------------------------------------------------ one run's inputs
    def inputs(self, values: Mapping[str, Any], cache: dict[str, Any]) -> RunInputs:
        """The model, state, horizon and simulate keywords of the run with these key values."""
        from ..io import Scenario

        if isinstance(self.base, Scenario):
            return self._scenario_inputs(self.base, values, cache)
        return self._model_inputs(values, cache)

    def _scenario_inputs(self, sc: Any, values: Mapping[str, Any], cache: dict[str, Any]) -> RunInputs:
        from ..io import Scenario
        from ..io._run import _end_time, _output_times, simulate_kwargs
        from ..io._scenario import SCENARIO_SCHEMA
        from ..io._schema import check

        data = copy.deepcopy(dict(sc.data))
        for k, v in values.items():
            _set_path(data, k, v.tolist() if isinstance(v, np.ndarray) else v, str(sc.path))
        check(data, SCENARIO_SCHEMA, sc.path)
        run_sc = Scenario(path=sc.path, data=data, allow_code=sc.allow_code)
        mkey = f"scenario:{sc.path}:{sc.allow_code}:" + json.dumps(_jsonable(data.get("model", {})), sort_keys=True)
        built = _BUILT.get(mkey)
        if built is None:
            built = run_sc.build_source()
            _remember(mkey, built)
        model, default, horizon = built
        state = run_sc.initial_state(model, default)
        t1 = _end_time(run_sc, state.t, horizon, None)
        kw = simulate_kwargs(run_sc)
        t_eval = _output_times(run_sc, state.t, t1)
        if t_eval is not None:
            kw["t_eval"] = t_eval
        if run_sc.section("controller") or run_sc.data.get("events"):
            from ..io._run import build_controller, build_events

            ctl = build_controller(run_sc, model)
            if ctl is not None:
                kw["controller"] = ctl
            evs = build_events(run_sc, model)
            if evs:
                kw["events"] = evs
        return RunInputs(model, state.q, state.qd, frozenset(state.active), (state.t, t1), kw)

    def _model_inputs(self, values: Mapping[str, Any], cache: dict[str, Any]) -> RunInputs:
        from ..model import Model

        base = self.base
        factory = None
        if not isinstance(base, Model) and not isinstance(getattr(base, "model", None), Model) and callable(base):
            factory = base  # a model source: params.<name> are its keyword arguments
            fkw = {k[7:]: v for k, v in values.items() if k.startswith("params.")}
            fkey = f"factory:{getattr(factory, '__module__', '')}.{getattr(factory, '__qualname__', id(factory))}:" \
                + repr(sorted(fkw.items()))  # fmt: skip
            base = _BUILT.get(fkey)
            if base is None:
                base = factory(**fkw)
                _remember(fkey, base)
            values = {k: v for k, v in values.items() if not k.startswith("params.")}
            if not isinstance(base, Model) and not isinstance(getattr(base, "model", None), Model):
                raise InputError(f"sweep: the model source returned {type(base).__name__}, not a Model or Mechanism")
        model = base if isinstance(base, Model) else base.model
        st = None if isinstance(base, Model) else getattr(base, "state", None)
        opts = dict(self.options)
        q0 = opts.pop("q0", None)
        qd0 = opts.pop("qd0", None)
        active = opts.pop("active", None)
        t_span = self.t_span
        if t_span is None:
            t_span = getattr(base, "t_final", None)
        fields: dict[str, Any] = {}
        if q0 is not None:
            q: np.ndarray | None = np.array(q0, dtype=float)
        else:
            q = None if st is None else np.array(st.q, dtype=float)
        if qd0 is not None:
            qd = np.array(qd0, dtype=float)
        else:
            qd = np.zeros(model.n) if st is None else np.array(st.qd, dtype=float)
        if active is None and st is not None:
            active = st.active
        names = list(model.coordinate_names)
        for k, v in values.items():
            if k in ("q0", "qd0"):
                arr = np.array(v, dtype=float)
                if arr.shape != (model.n,):
                    raise InputError(f"sweep key {k!r}: expected {model.n} numbers, got shape {arr.shape}")
                if k == "q0":
                    q = arr
                else:
                    qd = arr
            elif k.startswith(("q0.", "qd0.")):
                head, _, coord = k.partition(".")
                if coord not in names:
                    raise InputError(f"sweep key {k!r}: unknown coordinate {coord!r}; known: {names}")
                if head == "q0":
                    if q is None:
                        raise InputError(f"sweep key {k!r}: the model has no default q0 to change")
                    q = q.copy()
                    q[names.index(coord)] = float(v)
                else:
                    qd = qd.copy()
                    qd[names.index(coord)] = float(v)
            elif k.startswith("params."):
                fields[k[7:]] = v
            elif k == "t_final":
                t_span = float(v)
            elif k == "active":
                active = v
            else:
                opts[k] = v
        if q is None:
            raise InputError("sweep: q0 is required for a bare model (options q0=... or a q0 axis)")
        if fields:
            key = repr(sorted(fields.items()))
            m2 = cache.get(key)
            if m2 is None:
                m2 = model.replace(**fields)
                cache[key] = m2
            model = m2
        if t_span is None:
            raise InputError("sweep: t_span is required for a bare model")
        ts: Any = t_span
        span: Any = (0.0, float(ts)) if isinstance(ts, int | float | np.number) else ts
        return RunInputs(model, q, qd, model.resolve_active(active), (float(span[0]), float(span[1])), opts)


#: Models built in this process (a scenario's [model] table, a model source's arguments), so
#: the blocks of a sweep on one worker build each model once. Bounded; oldest dropped first.
_BUILT: dict[str, Any] = {}
_BUILT_MAX = 256


def _remember(key: str, value: Any) -> None:
    if len(_BUILT) >= _BUILT_MAX:
        _BUILT.pop(next(iter(_BUILT)))
    _BUILT[key] = value


def _jsonable(x: Any) -> Any:
    if isinstance(x, Mapping):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, float | int | str | bool) or x is None:
        return x
    return repr(x)


def key_values(table: Sequence[Mapping[str, Any]]) -> dict[str, np.ndarray]:
    """The per-run value of every key as an array (run,) or (run, width)."""
    keys: list[str] = []
    for row in table:
        for k in row:
            if k not in keys:
                keys.append(k)
    out: dict[str, np.ndarray] = {}
    for k in keys:
        vals = [row.get(k) for row in table]
        try:
            arr = np.array(vals, dtype=float)
        except (TypeError, ValueError):
            arr = np.array([str(v) for v in vals])
        out[k] = arr
    return out
