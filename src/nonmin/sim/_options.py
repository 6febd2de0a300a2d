"""The options of :func:`nonmin.sim.simulate`, grouped into values.

A simulation states a problem (a model, a time span, an initial state, a controller) and three
choices about how to solve it, each one value:

- :class:`Solver`: the integrator, its step and tolerances, the rank tolerance of the kernel,
  the step budget and whether the initial state is projected onto the constraints;
- :class:`EventSet`: the user events and the automatic unilateral contact (restitution, the
  plastic-contact threshold, Zeno detection, re-arming);
- :class:`Output`: what is recorded (``t_eval``), shown (progress), saved on the way
  (checkpoints), and what happens on failure (``throw``).

The stabilization is already a value (:class:`~nonmin.sim.Projection`,
:class:`~nonmin.sim.Baumgarte`, ...). Every field also has a flat keyword shorthand in
:func:`~nonmin.sim.simulate` (``dt=``, ``rtol=``, ``t_eval=``, ``restitution=`` ...), which
:func:`resolve_options` folds into these values; giving a field both ways with different values
is an :class:`~nonmin.errors.InputError`.

All values are frozen dataclasses validated on construction, so a bad option fails where it is
written, with a message that names the field, what was expected and what came.
"""

from __future__ import annotations

import functools
import math
import os
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, fields, replace
from typing import Any

import numpy as np

from .._validation import as_float_array
from ..errors import InputError, ShapeError
from . import _durable
from ._events import Event
from ._integrators import Integrator

__all__ = ["EventSet", "Output", "Solver", "resolve_options"]


def _pos(name: str, x: Any, *, allow_none: bool = False) -> float | None:
    if x is None and allow_none:
        return None
    if isinstance(x, bool | str | bytes):  # float() would take True and "1e-3"
        raise InputError(f"{name} must be a positive finite number, got {x!r}")
    try:
        v = float(x)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a positive number, got {x!r}") from None
    if not (v > 0 and math.isfinite(v)):
        raise InputError(f"{name} must be a positive finite number, got {x!r}")
    return v


def _count(name: str, x: Any) -> int:
    if isinstance(x, bool) or not isinstance(x, int | np.integer) or x < 1:
        raise InputError(f"{name} must be an integer ≥ 1, got {x!r}")
    return int(x)


def _nonneg(name: str, x: Any) -> float:
    try:
        v = float(x)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a number ≥ 0, got {x!r}") from None
    if isinstance(x, bool) or not (v >= 0.0 and math.isfinite(v)):
        raise InputError(f"{name} must be ≥ 0, got {x!r}")
    return v


def _unit(name: str, x: Any) -> float:
    try:
        v = float(x)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a number in [0, 1], got {x!r}") from None
    if isinstance(x, bool) or not 0.0 <= v <= 1.0:
        raise InputError(f"{name} must lie in [0, 1], got {x!r}")
    return v


@dataclass(frozen=True)
class Solver:
    """How the equations of motion are integrated.

    Parameters
    ----------
    method : str or Integrator, default "rk4"
        ``"rk4"`` (fixed step ``dt``), ``"dopri5"`` (adaptive, ``rtol``/``atol``),
        ``"dop853"`` (adaptive, order 8: tight tolerances, long runs), ``"rk8"`` (DOP853's
        8th-order stages with a fixed ``dt`` and no error estimate: coarse steps on smooth
        motion, the cheapest at Pinocchio's coarse accuracy on A02), ``"midpoint"``
        (implicit midpoint, fixed ``dt``), any name of
        :data:`nonmin.sim.METHODS`, or an :class:`~nonmin.sim.Integrator` value.
    dt : float, optional
        Step of fixed-step methods (default :data:`nonmin.sim.DEFAULT_DT`); for adaptive ones
        the largest step allowed.
    rtol, atol : float
        Tolerances of adaptive methods given by name.
    h0 : float, optional
        First step of adaptive methods (default: Hairer's starting-step heuristic).
    rank_rtol : float, optional
        Rank tolerance of A (relative, on the row-equilibrated A), in (0, 1); default: the
        core's 1e-10 for fixed-step methods, :data:`nonmin.sim.ADAPTIVE_RANK_RTOL` for adaptive
        ones.
    max_steps : int, default 10_000_000
        Fail after this many accepted steps (and refuse up front a fixed-step run that needs
        more).
    project_initial : bool, optional
        Project the initial state onto the active constraints (default: True with the
        projection stabilization, False otherwise).

    Examples
    --------
    >>> from nonmin.sim import Solver
    >>> Solver("dopri5", rtol=1e-10, atol=1e-12)
    Solver(method='dopri5', dt=None, rtol=1e-10, atol=1e-12, h0=None, rank_rtol=None, max_steps=10000000, project_initial=None)
    """

    method: str | Integrator = "rk4"
    dt: float | None = None
    rtol: float = 1e-8
    atol: float = 1e-10
    h0: float | None = None
    rank_rtol: float | None = None
    max_steps: int = 10_000_000
    project_initial: bool | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.method, str | Integrator):
            raise InputError(
                f"method must be an Integrator object or a method name, got {type(self.method).__name__}"
            )
        set_ = object.__setattr__
        set_(self, "dt", _pos("dt", self.dt, allow_none=True))
        set_(self, "rtol", _pos("rtol", self.rtol))
        set_(self, "atol", _pos("atol", self.atol))
        set_(self, "h0", _pos("h0", self.h0, allow_none=True))
        if self.rank_rtol is not None:
            try:
                r = float(self.rank_rtol)
            except (TypeError, ValueError):
                raise InputError(f"rank_rtol must be a number in (0, 1), got {self.rank_rtol!r}") from None
            if isinstance(self.rank_rtol, bool) or not 0.0 < r < 1.0:
                raise InputError(f"rank_rtol must lie in (0, 1), got {self.rank_rtol!r}")
            set_(self, "rank_rtol", r)
        set_(self, "max_steps", _count("max_steps", self.max_steps))
        if self.project_initial is not None:
            set_(self, "project_initial", bool(self.project_initial))


@dataclass(frozen=True)
class EventSet:
    """The events of a simulation: user events and the automatic unilateral contact.

    Parameters
    ----------
    events : iterable of Event
        User events (:class:`~nonmin.sim.Event`), located on the method's own partial steps.
    contact : bool, default True
        Automatic impact/release handling of the model's unilateral constraints.
    restitution : float or dict, default 0.0
        Newton restitution of automatic contact impacts, in [0, 1] (per constraint name with a
        dict; the names are checked against the model when the simulation starts).
    impact_velocity_threshold : float, default 1e-6
        A bounce whose separation speed (m/s along the gap) is at most this becomes a plastic,
        persistent contact (the Zeno accumulation point is truncated there). Bounces whose
        predicted flight time is below two fixed steps are treated the same way.
    zeno_max_events, zeno_window : int, float
        Raise :class:`~nonmin.errors.ZenoError` when more than ``zeno_max_events`` events fire
        within ``zeno_window`` seconds (defaults 20 and 1e-6 s).
    event_rearm : float, default 1e-9
        A user event that fired cannot fire again until ``|guard| > event_rearm``: guards that
        stay at 0 after their transition (a constraint that was just activated) do not chatter.

    Examples
    --------
    >>> from nonmin.sim import EventSet
    >>> EventSet(restitution={"floor": 0.5}).contact
    True
    """

    events: tuple[Event, ...] = ()
    contact: bool = True
    restitution: float | Mapping[str, float] = 0.0
    impact_velocity_threshold: float = 1e-6
    zeno_max_events: int = 20
    zeno_window: float = 1e-6
    event_rearm: float = 1e-9

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        if isinstance(self.events, Event):
            set_(self, "events", (self.events,))
        try:
            evs = tuple(self.events)
        except TypeError:
            raise InputError(f"events must be an iterable of Event values, got {type(self.events).__name__}") from None
        for ev in evs:
            if not isinstance(ev, Event):
                raise InputError(f"events must be Event values, got {type(ev).__name__}")
        set_(self, "events", evs)
        set_(self, "contact", bool(self.contact))
        if isinstance(self.restitution, Mapping):
            set_(self, "restitution", {str(k): _unit(f"restitution[{k!r}]", v) for k, v in self.restitution.items()})
        else:
            set_(self, "restitution", _unit("restitution", self.restitution))
        set_(self, "impact_velocity_threshold",
             _nonneg("impact_velocity_threshold", self.impact_velocity_threshold))  # fmt: skip
        set_(self, "zeno_max_events", _count("zeno_max_events", self.zeno_max_events))
        set_(self, "zeno_window", _pos("zeno_window", self.zeno_window))
        set_(self, "event_rearm", _nonneg("event_rearm", self.event_rearm))


@dataclass(frozen=True)
class Output:
    """What a simulation records, shows and saves, and what it does on failure.

    Parameters
    ----------
    t_eval : array_like, optional
        Record at these times (non-decreasing, inside ``t_span``) plus the two samples (before
        and after the transition) of every event; default: every accepted step. Values between
        step ends come from the method's continuous extension (dopri5's own; for the fixed-step
        rk4 and midpoint the quintic Hermite interpolant of ``q, qd, qdd`` at the projected
        step ends), then the stabilization.
    progress : bool or None
        Progress bar (None: only when stderr is a terminal).
    checkpoint : path, optional
        A ``.npz`` file that receives the samples so far (status ``interrupted``) every
        ``checkpoint_every`` seconds of simulated time, and when the run is interrupted,
        written durably (temporary file, fsync, rename).
    checkpoint_every : float, optional
        Simulated seconds between checkpoints (needs ``checkpoint``).
    throw : bool, default True
        Raise on failure; with False return the partial trajectory with ``status`` failed.
    reactions : bool or tuple of str, default False
        Store each constraint's reaction (its wrench on the bodies it joins, per sample) in
        ``Trajectory.reactions``: True for every constraint, or the names to keep
        (:meth:`Trajectory.with_reactions`, read from the recorded ``f_c`` after the run).

    Examples
    --------
    >>> import numpy as np
    >>> from nonmin.sim import Output
    >>> Output(t_eval=np.linspace(0.0, 1.0, 11)).t_eval.shape
    (11,)
    """

    t_eval: Any = None
    progress: bool | None = None
    checkpoint: str | os.PathLike[str] | None = None
    checkpoint_every: float | None = None
    throw: bool = True
    reactions: bool | tuple[str, ...] = False

    def __post_init__(self) -> None:
        if not isinstance(self.reactions, bool):
            if isinstance(self.reactions, str) or not all(isinstance(x, str) for x in self.reactions):
                raise InputError(f"reactions must be True/False or constraint names, got {self.reactions!r}")
            object.__setattr__(self, "reactions", tuple(self.reactions))
        if self.t_eval is not None:
            size = np.size(self.t_eval)
            if size * _durable.sample_bytes(1, 0, 0) > _durable.MAX_RECORD_BYTES:  # before copying it
                raise InputError(
                    f"t_eval has {size} times: recording them needs more than the "
                    f"{_durable.MAX_RECORD_BYTES / 2**30:g} GiB budget of a run; pass a coarser t_eval"
                )
            try:
                t = np.array(as_float_array(self.t_eval, "t_eval"))
            except ShapeError:
                raise InputError(f"t_eval must be an array of times, got {type(self.t_eval).__name__}") from None
            if t.ndim > 1 or t.size == 0:  # a (k, m) array was flattened, an empty one recorded nothing
                raise ShapeError(f"t_eval must be a non-empty 1-D array of times, got shape {t.shape}")
            t = t.ravel()
            t.flags.writeable = False
            object.__setattr__(self, "t_eval", t)
        if self.progress is not None:
            object.__setattr__(self, "progress", bool(self.progress))
        object.__setattr__(self, "throw", bool(self.throw))

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Output):
            return NotImplemented
        same_t = (self.t_eval is None and other.t_eval is None) or (
            self.t_eval is not None and other.t_eval is not None
            and np.array_equal(self.t_eval, other.t_eval)
        )  # fmt: skip
        return same_t and all(getattr(self, f.name) == getattr(other, f.name)
                              for f in fields(self) if f.name != "t_eval")  # fmt: skip

    __hash__ = None  # type: ignore[assignment]


#: Which value each flat keyword of :func:`~nonmin.sim.simulate` belongs to.
SHORTHANDS: dict[str, type] = {
    **{f.name: Solver for f in fields(Solver)},
    **{f.name: EventSet for f in fields(EventSet) if f.name != "events"},
    **{f.name: Output for f in fields(Output)},
}


#: ``EventSet()``: no user events, the default contact settings.
_NO_EVENTS = EventSet()


def _same(a: Any, b: Any) -> bool:
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        try:
            return bool(np.array_equal(np.asarray(a, dtype=float), np.asarray(b, dtype=float)))
        except (TypeError, ValueError):
            return False
    try:
        return bool(a == b)
    except Exception:  # an incomparable pair is not the same
        return False


_PLAIN = (str, int, float, bool, type(None))


@functools.lru_cache(maxsize=256)
def _built(kind: type, items: tuple[tuple[str, str, Any], ...]) -> Any:
    """The value built from flat shorthands alone, ``items`` = ((name, type name, value), ...)
    of plain str/int/float/bool/None values: the values are frozen and validated, so a call with
    the same shorthands shares the first call's value (an invalid one raises and is not kept)."""
    return kind(**{k: v for k, _, v in items})


def _fold(kind: type, flat: dict[str, Any], given: Any) -> Any:
    """``given`` (a value of ``kind``, or None for the defaults) with the shorthands from ``flat``."""
    mine = {k: v for k, v in flat.items() if SHORTHANDS.get(k) is kind}
    if given is None:
        if not all(type(v) in _PLAIN for v in mine.values()):
            return kind(**mine)
        return _built(kind, tuple(sorted((k, type(v).__name__, v) for k, v in mine.items())))
    for k, v in mine.items():
        ours = getattr(given, k)
        probe = getattr(kind(**{k: v}), k)  # validated and normalised the same way
        if not _same(ours, probe):
            raise InputError(
                f"simulate: {k}={v!r} contradicts the {kind.__name__} value given "
                f"({kind.__name__}.{k} = {ours!r}); set it in one place"
            )
    return given


def resolve_options(
    solver: Solver | None,
    events: EventSet | Iterable[Event] | Event,
    output: Output | None,
    flat: dict[str, Any],
) -> tuple[Solver, EventSet, Output]:
    """Fold the flat keyword shorthands into the three option values.

    Parameters
    ----------
    solver, events, output
        The values as given to :func:`~nonmin.sim.simulate` (``events`` may also be a plain
        iterable of :class:`~nonmin.sim.Event`).
    flat : dict
        The flat keywords given (only those the caller wrote); unknown names raise.

    Returns
    -------
    (Solver, EventSet, Output)

    Raises
    ------
    InputError
        A flat keyword that is unknown, or that contradicts a value given explicitly, or a
        value of the wrong type.
    """
    if not flat.keys() <= SHORTHANDS.keys():
        unknown = sorted(set(flat) - set(SHORTHANDS))
        raise InputError(
            f"simulate: unknown keyword argument(s) {unknown}; known: the values solver=, "
            f"stabilization=, events=, output= and the shorthands {sorted(SHORTHANDS)}"
        )
    if solver is not None and not isinstance(solver, Solver):
        raise InputError(f"solver must be a nonmin.sim.Solver value, got {type(solver).__name__}")
    if output is not None and not isinstance(output, Output):
        raise InputError(f"output must be a nonmin.sim.Output value, got {type(output).__name__}")
    s = _fold(Solver, flat, solver)
    if isinstance(events, EventSet):
        ev = _fold(EventSet, flat, events)
    elif isinstance(events, tuple | list) and not events and not any(SHORTHANDS.get(k) is EventSet for k in flat):
        ev = _NO_EVENTS  # the default (a frozen value): most calls
    else:
        ev = _fold(EventSet, flat, None)
        ev = replace(ev, events=events)  # validated by __post_init__
    o = _fold(Output, flat, output)
    return s, ev, o

