"""Events and transitions: frozen values, validated when constructed.

An :class:`Event` watches a scalar guard ``g(t, q, qd, f_c)``; the simulator locates the time
where ``g`` changes sign (in the given direction) to ~1e-10 and then applies the event's
transition: :class:`Activate` (switch constraints on, with the impact map),
:class:`Deactivate` (switch them off) or :class:`Reset` (a user map of the state).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..errors import InputError

__all__ = ["Activate", "Deactivate", "Event", "EventRecord", "Reset", "Transition"]

FloatArray = NDArray[np.float64]
Guard = Callable[[float, FloatArray, FloatArray, FloatArray], float]


def _names(names: Iterable[str] | str, what: str) -> tuple[str, ...]:
    if isinstance(names, str):
        names = (names,)
    try:
        out = tuple(names)
    except TypeError:
        raise InputError(f"{what}: names must be a string or an iterable of strings, got {names!r}") from None
    if not out or not all(isinstance(n, str) and n for n in out):
        raise InputError(f"{what}: names must be non-empty strings, got {out!r}")
    return out


@dataclass(frozen=True)
class Activate:
    """Switch the named constraints on, applying the impact map.

    Parameters
    ----------
    names : str or iterable of str
        Constraints to activate (must exist in the model; checked by :func:`simulate`).
    restitution : float, default 0.0
        Newton coefficient e ∈ [0, 1] of the impact map ``qd⁺ = qd⁻ + (1+e)(M̄⁻¹PM qd⁻ − qd⁻)``
        (ERRATA, "Impact map"). With e > 0 the constraint is switched on only for the impact
        when it is unilateral (the bodies separate again).
    """

    names: tuple[str, ...]
    restitution: float = 0.0

    def __init__(self, names: Iterable[str] | str, restitution: float = 0.0) -> None:
        object.__setattr__(self, "names", _names(names, "Activate"))
        e = float(restitution)
        if not (0.0 <= e <= 1.0):
            raise InputError(f"Activate: restitution must lie in [0, 1], got {restitution!r}")
        object.__setattr__(self, "restitution", e)


@dataclass(frozen=True)
class Deactivate:
    """Switch the named constraints off (no velocity jump)."""

    names: tuple[str, ...]

    def __init__(self, names: Iterable[str] | str) -> None:
        object.__setattr__(self, "names", _names(names, "Deactivate"))


@dataclass(frozen=True)
class Reset:
    """A user map ``fn(t, q, qd, active) -> (q, qd, active)`` applied at the event."""

    fn: Callable[[float, FloatArray, FloatArray, frozenset[str]], tuple[Any, Any, Any]]

    def __post_init__(self) -> None:
        if not callable(self.fn):
            raise InputError(f"Reset: fn must be callable, got {type(self.fn).__name__}")


Transition = Activate | Deactivate | Reset


@dataclass(frozen=True)
class Event:
    """A guard function whose zero crossing triggers a transition.

    Parameters
    ----------
    guard : callable ``(t, q, qd, f_c) -> float``
        Scalar guard; ``f_c`` is the generalized constraint force, shape (n,).
    direction : {0, +1, -1}, default 0
        Only crossings with that sign of ``dg/dt`` count (0: both).
    transition : Activate, Deactivate, Reset or None
        What happens at the event (None: only recorded).
    terminal : bool, default False
        Stop the simulation at the event (status ``event_terminated``).
    name : str, optional
        Label in the trajectory's event list (default: the guard's ``__name__``).
    """

    guard: Guard
    direction: int = 0
    transition: Transition | None = None
    terminal: bool = False
    name: str = field(default="")

    def __post_init__(self) -> None:
        if not callable(self.guard):
            raise InputError(f"Event: guard must be callable, got {type(self.guard).__name__}")
        if self.direction not in (0, 1, -1):
            raise InputError(f"Event: direction must be 0, +1 or -1, got {self.direction!r}")
        if self.transition is not None and not isinstance(self.transition, Activate | Deactivate | Reset):
            raise InputError(
                "Event: transition must be Activate(...), Deactivate(...), Reset(...) or None, "
                f"got {type(self.transition).__name__}"
            )
        if not self.name:
            object.__setattr__(self, "name", getattr(self.guard, "__name__", "event"))


@dataclass(frozen=True, eq=False)
class EventRecord:
    """One event that fired during a simulation.

    Attributes
    ----------
    t : float
    name : str
        Event name; automatic contact events are ``"impact:<constraint>"`` (one impact over
        every contact closing at that instant: ``"impact:<c1>+<c2>+…"``, the contacts whose gap
        crossed, in declaration order; docs/theory.md "Simultaneous impacts"),
        ``"release:<constraint>"`` and ``"release-refused:<constraint>"``; frictional contacts
        (docs/theory.md "Coulomb friction") add ``"stick:<contact>"``, ``"slip:<contact>"``
        (the transition text gives the slip direction) and ``"open:<contact>"``.
    transition : str
        Human-readable description of the transition applied.
    q_before, qd_before, q_after, qd_after : ndarray, shape (n,)
    active_before, active_after : frozenset of str
    impulses : dict of str to Reaction
        For an impact (automatic contact, an :class:`Activate` transition, or another
        constraint transition that changed the velocity, e.g. a contact that sticks): the impulse
        ``M (qd_after − qd_before)`` split over the constraints that carry it, by name, as force
        and torque impulses (N·s, N·m·s) on the two bodies each joins, in their frames, with
        ``determined`` masks for redundant sets (:func:`nonmin.analysis.impulses`). The set:
        the constraints active before or after, the contacts of the impact (named, or touching
        and approaching). Empty for other events. Saved and exported with the event.
    """

    t: float
    name: str
    transition: str
    q_before: FloatArray
    qd_before: FloatArray
    q_after: FloatArray
    qd_after: FloatArray
    active_before: frozenset[str]
    active_after: frozenset[str]
    impulses: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-serializable form."""
        out: dict[str, Any] = {
            "t": self.t,
            "name": self.name,
            "transition": self.transition,
            "q_before": self.q_before.tolist(),
            "qd_before": self.qd_before.tolist(),
            "q_after": self.q_after.tolist(),
            "qd_after": self.qd_after.tolist(),
            "active_before": sorted(self.active_before),
            "active_after": sorted(self.active_after),
        }
        if self.impulses:
            out["impulses"] = [
                {**r.metadata(), **{k: v.tolist() for k, v in r.to_arrays("").items()}}
                for r in self.impulses.values()
            ]
        return out

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> EventRecord:
        """Inverse of :meth:`to_dict`."""
        return cls(
            t=float(d["t"]),
            name=str(d["name"]),
            transition=str(d["transition"]),
            q_before=np.asarray(d["q_before"], float),
            qd_before=np.asarray(d["qd_before"], float),
            q_after=np.asarray(d["q_after"], float),
            qd_after=np.asarray(d["qd_after"], float),
            active_before=frozenset(d["active_before"]),
            active_after=frozenset(d["active_after"]),
            impulses=_impulses_from(d.get("impulses", [])),
        )


def _impulses_from(raw: Any) -> dict[str, Any]:
    """The impulses of :meth:`EventRecord.to_dict` back as Reactions."""
    if not raw:
        return {}
    from ..analysis import Reaction

    if not isinstance(raw, list):
        raise TypeError(f"impulses must be a list, got {type(raw).__name__}")
    out: dict[str, Any] = {}
    for item in raw:
        arrays = {k: np.asarray(v, dtype=bool if k.startswith(("determined", "multipliers_d", "active")) else float)
                  for k, v in item.items() if k not in ("name", "kind", "body_a", "body_b", "point_a", "point_b", "frame")}
        r = Reaction.from_arrays(item, arrays)
        out[r.name] = r
    return out


def describe_transition(tr: Transition | None) -> str:
    """Short text for an event record."""
    if tr is None:
        return "none"
    if isinstance(tr, Activate):
        return f"activate {list(tr.names)} (e={tr.restitution:g})"
    if isinstance(tr, Deactivate):
        return f"deactivate {list(tr.names)}"
    return f"reset {getattr(tr.fn, '__name__', 'fn')}"
