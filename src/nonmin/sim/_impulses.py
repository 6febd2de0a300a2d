"""The impulses of a simulation's impacts, by constraint name (issue #22).

After a run, every impact event (an automatic contact impact ``"impact:…"``, an
:class:`~nonmin.sim.Activate` transition, or another constraint transition that changed the
velocity, such as a friction contact that sticks) gets its impulse ``M (q̇⁺ − q̇⁻)`` split over the
constraints that carry it (:func:`nonmin.analysis.impulses`): the bilateral constraints active
across it and the contacts of the impact set, chosen as the event layer chose them
(``_set_impact`` / ``engine/src/sim_events.cpp``: the contacts that fired, the active ones, and
the touching ones, gap ≤ 0 with ``a q̇⁻ ≤ 0``).
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from ._events import EventRecord

__all__ = ["impact_losses", "impact_set", "with_impulses"]


def _is_impact(ev: EventRecord) -> bool:
    """An impact, an activation, or any other constraint transition that changed the velocity
    (a friction contact that sticks); not a user Reset (its jump is the user's map)."""
    if ev.name.startswith("impact:") or ev.transition.startswith("activate"):
        return True
    return not ev.transition.startswith("reset") and not np.array_equal(ev.qd_before, ev.qd_after)


def impact_set(model: Any, ev: EventRecord) -> frozenset[str]:
    """The constraints that carry the impulse of the impact ``ev``."""
    uni = [c.name for c in model.constraints if c.kind == "unilateral"]
    named = set(ev.name.partition(":")[2].split("+")) if ev.name.startswith("impact:") else set()
    chosen = set(ev.active_before) | set(ev.active_after) | (named & set(uni))
    rest = [nm for nm in uni if nm not in chosen]
    if rest:
        act = frozenset(rest)
        ct = model.constraint_terms(ev.t, ev.q_before, ev.qd_before, act)
        rows = model.row_slices(act)
        for nm in rest:
            i = rows[nm].start
            if ct.phi[i] <= 0.0 and float(ct.A[i] @ ev.qd_before) <= 0.0:
                chosen.add(nm)
    return frozenset(chosen)


def with_impulses(model: Any, events: tuple[EventRecord, ...], rtol: float | None) -> tuple[EventRecord, ...]:
    """``events`` with :attr:`EventRecord.impulses` filled in for the impacts (finite states)."""
    from ..analysis import impulses

    out = []
    for ev in events:
        if (
            _is_impact(ev)
            and not ev.impulses
            and all(np.isfinite(x).all() for x in (ev.q_before, ev.qd_before, ev.qd_after))
        ):
            act = impact_set(model, ev)
            names = [c.name for c in model.constraints if c.name in act]
            imp = impulses(model, ev.q_before, ev.qd_before, ev.qd_after, t=ev.t, active=act, names=names, rtol=rtol)
            ev = dataclasses.replace(ev, impulses=imp)
        out.append(ev)
    return tuple(out)


def event_loss(model: Any, ev: EventRecord) -> float:
    """The energy an event takes out (J): the kinetic energy before minus after,
    ``½ q̇⁻ᵀ M(q⁻) q̇⁻ − ½ q̇⁺ᵀ M(q⁻) q̇⁺``, when it changes the velocity (an impact, an
    activation, a contact that sticks: ``(1 − e²)·½ m v²`` for a point mass hitting a wall with
    restitution e); ``E⁻ − E⁺`` at a user ``Reset`` (the user's map may move q too); 0 otherwise."""
    if not all(np.isfinite(x).all() for x in (ev.q_before, ev.qd_before, ev.q_after, ev.qd_after)):
        return 0.0
    if ev.transition.startswith("reset"):
        return float(model.energy(ev.q_before, ev.qd_before) - model.energy(ev.q_after, ev.qd_after))
    if np.array_equal(ev.qd_before, ev.qd_after):
        return 0.0
    M = np.asarray(model.mass_matrix(ev.q_before), dtype=float)
    return 0.5 * float(ev.qd_before @ M @ ev.qd_before - ev.qd_after @ M @ ev.qd_after)


def impact_losses(model: Any, events: tuple[EventRecord, ...], t: Any) -> np.ndarray:
    """The cumulative energy taken out by the events at every sample time ``t`` (shape (N,)).

    An event at ``te`` counts from the samples after it: those with ``t > te`` and, of the
    samples at ``te`` itself (the one before the transition, the one after), the last one."""
    tv = np.asarray(t, dtype=float)
    out = np.zeros(tv.shape[0])
    for ev in events:
        loss = event_loss(model, ev)
        if loss == 0.0:
            continue
        out[tv > ev.t] += loss
        same = np.flatnonzero(tv == ev.t)
        if same.size >= 2:
            out[same[-1]] += loss
    return out
