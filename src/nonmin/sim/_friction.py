"""Coulomb friction in :func:`nonmin.simulate`: the model-level reference of the engine's
friction (``engine/src/sim_friction.cpp``) and the pieces the driver needs.

A frictional contact (:class:`nonmin.model.FrictionContact`: a unilateral normal constraint,
a tangential row, μ_f) is **open** (normal inactive), **sticking** (normal and tangential rows
active: a bilateral constraint whose force ``λ_t`` is read from ``f_c`` like ``λ_n``) or
**slipping** with direction ``s = ±1`` (tangential row inactive; the force ``−μ s N`` applied
along it, N solved exactly: :func:`nonmin.core.slip_dynamics`). The engine's event layer
switches between them: sticking → slipping when ``|λ_t|`` reaches ``μ λ_n``, slipping →
sticking (or slipping the other way) when the slip velocity ``s v_t`` reaches zero. This
module holds the same decisions in NumPy: the initial modes (:func:`initial_modes`), the state
of every contact at a state (:func:`friction_state`, public as
``nonmin.sim.friction_state``), used by the tests as the engine's oracle.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..core.friction import SlipDynamics, slip_dynamics
from ..core.linalg import range_basis
from ..errors import InputError, PainleveError, SimulationError
from ..model import FrictionContact, Model

FloatArray = NDArray[np.float64]

__all__ = ["ContactState", "friction_state", "initial_modes"]


class ContactState(NamedTuple):
    """One frictional contact at a state.

    Attributes
    ----------
    mode : {"open", "stick", "slip"}
    N : float
        Normal force (``λ_n``; 0 when open).
    F : float
        Tangential force along the tangential row (``λ_t`` sticking, ``−μ s N`` slipping).
    v_t : float
        Slip velocity ``a_t q̇``.
    s : int
        Slip direction (0 unless slipping).
    """

    mode: str
    N: float
    F: float
    v_t: float
    s: int


def engine_contacts(model: Model, slip: Mapping[str, int]) -> list[tuple[int, int, float, int]]:
    """The engine's friction contacts ``(normal index, tangent index, μ, s)``."""
    index = {c.name: i for i, c in enumerate(model.constraints)}
    return [(index[f.normal], index[f.tangent], float(f.mu), int(slip.get(f.normal, 0)))
            for f in model.friction_contacts]  # fmt: skip


def _tangent_row(model: Model, t: float, q: FloatArray, qd: FloatArray, fc: FrictionContact) -> FloatArray:
    act = frozenset({fc.tangent})
    ct = model.constraint_terms(t, q, qd, act)
    return np.asarray(ct.A[model.row_slices(act)[fc.tangent].start])


def _solve(
    model: Model, t: float, q: FloatArray, qd: FloatArray, active: frozenset[str], slip: Mapping[str, int],
    g_extra: FloatArray | None, rank_rtol: float | None, bias: Any,
) -> tuple[SlipDynamics, FloatArray, dict[str, slice], list[FrictionContact]]:  # fmt: skip
    """slip_dynamics at a state, with the slipping contacts of ``slip`` (normal active, tangent
    not); also λ of all active rows and the row slices."""
    terms = model.evaluate(t, q, qd, active)
    ct = terms.constraints
    g = terms.h + terms.f_passive
    if g_extra is not None:
        g = g + g_extra
    rows = model.row_slices(active)
    sliding = [f for f in model.friction_contacts
               if slip.get(f.normal, 0) and f.normal in active and f.tangent not in active]  # fmt: skip
    A_t = np.array([_tangent_row(model, t, q, qd, f) for f in sliding]).reshape(len(sliding), model.n)
    b = ct.gamma if bias is None else bias(ct)
    sol = slip_dynamics(terms.M, g, ct.A, b, [rows[f.normal].start for f in sliding], A_t,
                        [f.mu for f in sliding], [slip[f.normal] for f in sliding], rtol=rank_rtol)  # fmt: skip
    lam = np.asarray(range_basis(ct.A, rank_rtol).pinv().T @ sol.f_c) if ct.A.shape[0] else np.zeros(0)
    return sol, lam, rows, sliding


def friction_state(
    model: Model,
    t: float,
    q: ArrayLike,
    qd: ArrayLike,
    active: Iterable[str],
    slip: Mapping[str, int] | None = None,
    *,
    f: ArrayLike | None = None,
    rank_rtol: float | None = None,
) -> tuple[FloatArray, dict[str, ContactState]]:
    """Accelerations and the state of every frictional contact at one state (NumPy reference).

    Parameters
    ----------
    model : Model
        With :attr:`~nonmin.model.Model.friction_contacts`.
    t, q, qd : float, array_like (n,), array_like (n,)
    active : iterable of str
        The active set (a sticking contact has its tangential constraint in it).
    slip : mapping of normal name to ±1, optional
        Slip directions of the slipping contacts (normal active, tangent not); by default
        the sign of the slip velocity.
    f : array_like (n,), optional
        Applied generalized force besides ``h`` and the model's passive forces.
    rank_rtol : float, optional

    Returns
    -------
    qdd : ndarray (n,)
    contacts : dict of str to ContactState
        Keyed by the normal constraint's name.

    Raises
    ------
    PainleveError
        When the slipping contacts' normal forces are inconsistent.
    """
    act = model.resolve_active(active)
    qv = np.asarray(q, dtype=float)
    qdv = np.asarray(qd, dtype=float)
    vts = {fc.normal: float(_tangent_row(model, t, qv, qdv, fc) @ qdv) for fc in model.friction_contacts}
    if slip is None:
        slip = {
            fc.normal: int(np.sign(vts[fc.normal]))
            for fc in model.friction_contacts
            if fc.normal in act and fc.tangent not in act
        }
    fx = None if f is None else np.asarray(f, dtype=float)
    sol, lam, rows, sliding = _solve(model, t, qv, qdv, act, slip, fx, rank_rtol, None)
    if not sol.consistent:
        _raise_painleve(model, sliding, sol, t)
    out: dict[str, ContactState] = {}
    for fc in model.friction_contacts:
        vt = vts[fc.normal]
        if fc.normal not in act:
            out[fc.normal] = ContactState("open", 0.0, 0.0, vt, 0)
        elif fc.tangent in act:
            out[fc.normal] = ContactState("stick", float(lam[rows[fc.normal].start]),
                                          float(lam[rows[fc.tangent].start]), vt, 0)  # fmt: skip
        else:
            j = next((i for i, g in enumerate(sliding) if g.normal == fc.normal), None)
            if j is None:  # closed, no direction: no friction force
                out[fc.normal] = ContactState("slip", float(lam[rows[fc.normal].start]), 0.0, vt, 0)
            else:
                out[fc.normal] = ContactState("slip", float(sol.N[j]), float(sol.F[j]), vt, int(slip[fc.normal]))
    return sol.qdd, out


def _raise_painleve(model: Model, sliding: list[FrictionContact], sol: SlipDynamics, t: float) -> None:
    j = int(np.argmin(np.diag(sol.W))) if sol.W.size else 0
    name = sliding[j].normal if sliding else ""
    raise PainleveError(
        f"Painlevé's inconsistency at contact {name!r} at t = {t:.12g}: sliding with mu = "
        f"{sliding[j].mu if sliding else float('nan'):g} needs 1 + mu s dN/dF = {sol.min_minor:.6g} <= 0, "
        "so no normal force is consistent with it (Coulomb friction with rigid contact has no "
        "solution here; lower the friction or model the contact's compliance)",
        contact=name, t=t, factor=sol.min_minor,
    )  # fmt: skip


def initial_modes(
    model: Model,
    t: float,
    q: FloatArray,
    qd: FloatArray,
    active: frozenset[str],
    *,
    v_thresh: float,
    rank_rtol: float | None,
    bias: Any = None,
    g_extra: FloatArray | None = None,
) -> tuple[frozenset[str], dict[str, int]]:
    """The contacts' modes at the start (the engine's decision ``mode 0``, in declaration
    order): open when the normal is inactive; slipping along the slip velocity when
    ``|v_t| > v_thresh``; else sticking when the sticking force lies in the cone
    (``|λ_t| ≤ μ λ_n``), else slipping opposite to it."""
    act = set(active)
    slip: dict[str, int] = {}
    for fc in model.friction_contacts:
        if fc.normal not in act:
            act.discard(fc.tangent)
            continue
        vt = float(_tangent_row(model, t, q, qd, fc) @ qd)
        if fc.tangent not in act and abs(vt) > v_thresh:
            slip[fc.normal] = 1 if vt > 0 else -1
            continue
        trial = frozenset(act | {fc.tangent})
        sol, lam, rows, sliding = _solve(model, t, q, qd, trial, slip, g_extra, rank_rtol, bias)
        if not sol.consistent:
            _raise_painleve(model, sliding, sol, t)
        lam_n, lam_t = float(lam[rows[fc.normal].start]), float(lam[rows[fc.tangent].start])
        if abs(lam_t) <= fc.mu * lam_n:
            act.add(fc.tangent)
        else:
            act.discard(fc.tangent)
            slip[fc.normal] = -1 if lam_t > 0 else 1
    return frozenset(act), slip


def first_point(
    model: Model, p: Any, active: frozenset[str], slip: Mapping[str, int], *, rank_rtol: float | None,
    bias: Any, B_u: FloatArray | None,
) -> Any:  # fmt: skip
    """The general driver's first sample with the slipping contacts' friction applied."""
    if not any(slip.get(f.normal, 0) for f in model.friction_contacts):
        return p
    sol, lam, _, _ = _solve(model, p.t, p.q, p.qd, active, slip, B_u, rank_rtol, bias)
    if not sol.consistent:  # the engine's first evaluation reports it (PainleveError)
        return p
    return p._replace(qdd=sol.qdd, f_c=sol.f_c, lam=lam if p.lam.size else p.lam)


def check_friction_run(model: Model, engine: str, use_engine: bool, why: str | None, events: tuple[Any, ...]) -> None:
    """Friction runs need the engine's event layer and no user events."""
    if not use_engine:
        raise InputError(
            f"model {model.name!r} has frictional contacts, which run on the compiled engine only "
            f"(engine='auto' or 'engine'); here: engine={engine!r}"
            + (f" ({why})" if why else "")
        )
    if events:
        raise InputError(
            "frictional contacts run in the engine's event layer, which does not take user events yet; "
            f"got events {[e.name for e in events]}"
        )


def check_engine_result(model: Model, er: Any, t: float) -> None:
    """After an engine run of a friction model: Painlevé's inconsistency or an engine failure
    (the general driver, which has no friction, cannot take over) raise."""
    fcs = model.friction_contacts
    if er.painleve is not None:
        j, tp, factor = er.painleve
        fc = fcs[int(j)]
        raise PainleveError(
            f"Painlevé's inconsistency at contact {fc.normal!r} at t = {tp:.12g}: sliding with mu = {fc.mu:g} "
            f"needs 1 + mu s dN/dF = {factor:.6g} <= 0, so no normal force is consistent with it "
            "(rigid contact with Coulomb friction has no solution here; lower the friction or model "
            "the contact's compliance)",
            contact=fc.normal, t=float(tp), factor=float(factor),
        )  # fmt: skip
    if er.handover or er.event:
        raise SimulationError(
            f"frictional contact run: the engine could not go on at t = {er.t:.12g} ({er.message or 'event step failed'}); "
            "the general driver has no friction to continue with"
        )
