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
        Tangential force: one row, along the row (``λ_t`` sticking, ``−μ s N`` slipping); two
        rows, its magnitude (``|λ_t|`` sticking; slipping ``−μ N``, opposite to the slip).
    v_t : float
        Slip velocity ``a_t q̇`` (two rows: its magnitude).
    s : int
        Slip direction (0 unless slipping).
    """

    mode: str
    N: float
    F: float
    v_t: float
    s: int


#: A slipping contact's state: its direction ``e`` (one row: ``(s,)``, s = ±1; two rows: the unit
#: direction of the slip velocity at the last event).
Slip = tuple[float, ...]


def engine_contacts(model: Model, slip: Mapping[str, Slip]) -> list[tuple[int, int, float, int, float, float]]:
    """The engine's friction contacts ``(normal index, tangent index, μ, slip, d0, d1)``."""
    index = {c.name: i for i, c in enumerate(model.constraints)}
    out = []
    for f in model.friction_contacts:
        e = slip.get(f.normal)
        if e is None:
            out.append((index[f.normal], index[f.tangent], float(f.mu), 0, 0.0, 0.0))
        elif len(e) == 1:
            out.append((index[f.normal], index[f.tangent], float(f.mu), int(e[0]), float(e[0]), 0.0))
        else:
            out.append((index[f.normal], index[f.tangent], float(f.mu), 1, float(e[0]), float(e[1])))
    return out


def slip_from_engine(model: Model, states: Any) -> dict[str, Slip]:
    """The slip states the engine returns (``(slip, d0, d1)`` per contact) by normal name."""
    out: dict[str, Slip] = {}
    for f, (s, d0, d1) in zip(model.friction_contacts, states, strict=True):
        if s:
            out[f.normal] = (float(s),) if model.constraint(f.tangent).dim == 1 else (float(d0), float(d1))
    return out


def _tangent_rows(model: Model, t: float, q: FloatArray, qd: FloatArray, fc: FrictionContact) -> FloatArray:
    """The tangential constraint's rows A_t, shape (dim, n)."""
    act = frozenset({fc.tangent})
    ct = model.constraint_terms(t, q, qd, act)
    return np.asarray(ct.A[model.row_slices(act)[fc.tangent]])


def _direction(At: FloatArray, qd: FloatArray, e: Slip) -> FloatArray:
    """The slip direction: ``(s,)`` for one row; v_t/|v_t| for two (``e`` when v_t vanishes)."""
    if At.shape[0] == 1:
        return np.array([float(e[0])])
    v = At @ qd
    nv = float(np.linalg.norm(v))
    ev = np.asarray(e, dtype=float)
    return v / nv if nv > 0.0 and float(v @ ev) > 0.0 else ev  # (past dir·v_t = 0: the event's direction)


def _solve(
    model: Model, t: float, q: FloatArray, qd: FloatArray, active: frozenset[str], slip: Mapping[str, Slip],
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
               if f.normal in slip and f.normal in active and f.tangent not in active]  # fmt: skip
    rows_t = []
    for f in sliding:  # the force −μ N along g = A_tᵀ e
        At = _tangent_rows(model, t, q, qd, f)
        rows_t.append(_direction(At, qd, slip[f.normal]) @ At)
    A_t = np.array(rows_t).reshape(len(sliding), model.n)
    b = ct.gamma if bias is None else bias(ct)
    sol = slip_dynamics(terms.M, g, ct.A, b, [rows[f.normal].start for f in sliding], A_t,
                        [f.mu for f in sliding], np.ones(len(sliding)), rtol=rank_rtol)  # fmt: skip
    lam = np.asarray(range_basis(ct.A, rank_rtol).pinv().T @ sol.f_c) if ct.A.shape[0] else np.zeros(0)
    return sol, lam, rows, sliding


def friction_state(
    model: Model,
    t: float,
    q: ArrayLike,
    qd: ArrayLike,
    active: Iterable[str],
    slip: Mapping[str, float | tuple[float, ...]] | None = None,
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
    slip : mapping of normal name to ±1 (one tangential row) or a unit 2-vector (two), optional
        Slip directions of the slipping contacts (normal active, tangent not); by default
        the direction of the slip velocity. (Two rows: the force is always opposite to the slip
        velocity; the vector is used only where that velocity vanishes.)
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
    vts = {fc.normal: _tangent_rows(model, t, qv, qdv, fc) @ qdv for fc in model.friction_contacts}
    slips: dict[str, Slip] = {}
    if slip is None:
        for fc in model.friction_contacts:
            v = vts[fc.normal]
            if fc.normal in act and fc.tangent not in act and np.any(v != 0.0):
                slips[fc.normal] = (float(np.sign(v[0])),) if v.size == 1 else tuple(v / np.linalg.norm(v))
    else:
        for k, e in slip.items():
            slips[k] = tuple(float(x) for x in np.ravel(np.asarray(e, dtype=float)))
    fx = None if f is None else np.asarray(f, dtype=float)
    sol, lam, rows, sliding = _solve(model, t, qv, qdv, act, slips, fx, rank_rtol, None)
    if not sol.consistent:
        _raise_painleve(model, sliding, sol, t)
    out: dict[str, ContactState] = {}
    for fc in model.friction_contacts:
        v = vts[fc.normal]
        vt = float(v[0]) if v.size == 1 else float(np.linalg.norm(v))
        if fc.normal not in act:
            out[fc.normal] = ContactState("open", 0.0, 0.0, vt, 0)
        elif fc.tangent in act:
            lt = lam[rows[fc.tangent]]
            out[fc.normal] = ContactState("stick", float(lam[rows[fc.normal].start]),
                                          float(lt[0]) if lt.size == 1 else float(np.linalg.norm(lt)), vt, 0)  # fmt: skip
        else:
            j = next((i for i, g in enumerate(sliding) if g.normal == fc.normal), None)
            if j is None:  # closed, no direction: no friction force
                out[fc.normal] = ContactState("slip", float(lam[rows[fc.normal].start]), 0.0, vt, 0)
            else:
                e = slips[fc.normal]
                sgn = int(e[0]) if len(e) == 1 else 1
                out[fc.normal] = ContactState("slip", float(sol.N[j]), float(sgn * sol.F[j]), vt, sgn)
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
) -> tuple[frozenset[str], dict[str, Slip]]:
    """The contacts' modes at the start (the engine's decision ``mode 0``, in declaration
    order): open when the normal is inactive; slipping along the slip velocity when
    ``|v_t| > v_thresh``; else sticking when the sticking force lies in the cone
    (``|λ_t| ≤ μ λ_n``), else slipping opposite to it."""
    act = set(active)
    slip: dict[str, Slip] = {}
    for fc in model.friction_contacts:
        if fc.normal not in act:
            act.discard(fc.tangent)
            continue
        v = _tangent_rows(model, t, q, qd, fc) @ qd
        if fc.tangent not in act and float(np.linalg.norm(v)) > v_thresh:
            slip[fc.normal] = (float(np.sign(v[0])),) if v.size == 1 else tuple(v / np.linalg.norm(v))
            continue
        trial = frozenset(act | {fc.tangent})
        sol, lam, rows, sliding = _solve(model, t, q, qd, trial, slip, g_extra, rank_rtol, bias)
        if not sol.consistent:
            _raise_painleve(model, sliding, sol, t)
        lam_n, lam_t = float(lam[rows[fc.normal].start]), lam[rows[fc.tangent]]
        nt = float(np.linalg.norm(lam_t))
        if nt <= fc.mu * lam_n:
            act.add(fc.tangent)
        else:
            act.discard(fc.tangent)
            slip[fc.normal] = (float(-np.sign(lam_t[0])),) if lam_t.size == 1 else tuple(-lam_t / nt)
    return frozenset(act), slip


def first_point(
    model: Model, p: Any, active: frozenset[str], slip: Mapping[str, Slip], *, rank_rtol: float | None,
    bias: Any, B_u: FloatArray | None,
) -> Any:  # fmt: skip
    """The general driver's first sample with the slipping contacts' friction applied."""
    if not slip:
        return p
    sol, lam, _, _ = _solve(model, p.t, p.q, p.qd, active, slip, B_u, rank_rtol, bias)
    if not sol.consistent:  # the engine's first evaluation reports it (PainleveError)
        return p
    return p._replace(qdd=sol.qdd, f_c=sol.f_c, lam=lam if p.lam.size else p.lam)


def check_friction_run(model: Model, engine: str, use_engine: bool, why: str | None, events: tuple[Any, ...]) -> None:
    """Friction runs need the engine's event layer (user events are located on its partial
    steps: ``_simulate._friction_step``)."""
    if not use_engine:
        raise InputError(
            f"model {model.name!r} has frictional contacts, which run on the compiled engine only "
            f"(engine='auto' or 'engine'); here: engine={engine!r}"
            + (f" ({why})" if why else "")
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
