"""Diagnostics that plots, the demo summary and the viewer share (NumPy only, no matplotlib).

* :func:`singularity_distance` — σ_r/σ₁ of the *active* constraint matrix at every sample.
* :func:`energy_balance` — ``E − E₀ − W − W_fr + L_imp`` with ``W`` the work of the applied
  non-conservative forces (actuators/controllers, dampers, rheonomic drivers), ``W_fr`` the work
  of Coulomb friction and ``L_imp`` the energy taken out at impacts (both recorded by the
  simulation in the trajectory), so that neither the work done on a system nor its physical
  dissipation shows as drift.
* :func:`coordinate_units` — the physical unit of each coordinate (m, rad or 1).
"""

from __future__ import annotations

import itertools
from typing import Any, NamedTuple

import numpy as np

from .._export import coordinate_units as coordinate_units

__all__ = ["EnergyBalance", "coordinate_units", "energy_balance", "singularity_distance"]


def singularity_distance(traj: Any, model: Any) -> np.ndarray | None:
    """σ_r/σ₁ of the active constraint matrix A at every sample.

    ``A`` holds the rows of the constraints active *at that sample* (``traj.active_mask``),
    and ``r`` is the largest rank met on the samples that share that active set (the rank of
    the active constraints at a regular configuration). Dips towards 0 show the configurations
    where the active A loses rank (singular or change points), which the sampled rank itself
    rarely hits exactly. Samples with no active row give NaN (nothing to be singular).

    Parameters
    ----------
    traj : Trajectory
        With ``t`` (T,), ``q`` (T, n), ``rank`` (T,), ``active_mask`` (T, c) and
        ``constraint_names``.
    model : Model
        The model the trajectory came from.

    Returns
    -------
    ndarray, shape (T,), or None
        None when the trajectory has no rank information.
    """
    from ..core import range_basis

    q = getattr(traj, "q", None)
    rank = getattr(traj, "rank", None)
    if q is None or rank is None or len(rank) == 0:
        return None
    q = np.asarray(q)
    rank = np.asarray(rank)
    names = tuple(getattr(traj, "constraint_names", ()))
    mask = getattr(traj, "active_mask", None)
    keys: list[bytes] = (
        [np.asarray(row, dtype=bool).tobytes() for row in mask]
        if mask is not None and len(names)
        else [b""] * len(q)
    )
    rmax: dict[bytes, int] = {}
    for k, r in zip(keys, rank, strict=True):
        rmax[k] = max(rmax.get(k, 0), int(r))
    out = np.full(len(q), np.nan)
    for i, qi in enumerate(q):
        r = rmax[keys[i]]
        if r == 0:
            continue
        act = None
        if mask is not None and len(names):
            act = [n for n, a in zip(names, mask[i], strict=True) if a]
        A = model.constraint_jacobian(float(traj.t[i]), qi, act)
        s = range_basis(A).s
        out[i] = s[r - 1] / s[0] if s.size >= r and s[0] > 0 else 0.0
    return out


class EnergyBalance(NamedTuple):
    """Energy bookkeeping of a trajectory (all in J, shape (T,)).

    Attributes
    ----------
    energy : ndarray
        ``E = T + V`` at each sample.
    work : ndarray
        ``W(t) = ∫ q̇ᵀ (B u + f_passive + f_c) dt`` from t₀: the work of actuators/controllers,
        dampers and of the constraint forces of rheonomic (driven) constraints; scleronomic
        constraints do no work (``A q̇ = 0``). The trajectory's ``work`` when the simulation
        recorded it (integrated with the method's own stage weights: the balance is then the
        integration error alone); else Simpson's rule on the samples' power (a trajectory
        without it: an old file, a batch run), zero when no model was given either (``known``
        is then False).
    balance : ndarray
        ``E − E₀ − W − friction + impacts``: the integration error (drift) alone. For a
        conservative system without contacts W = 0 and this is ``E − E₀``.
    known : bool
        Whether ``work`` was computed (a model was given).
    friction : ndarray
        ``W_fr(t)``, the work of the Coulomb friction forces of slipping contacts (≤ 0), as the
        simulation integrated it (the trajectory's ``friction_work``; zeros when absent).
    impacts : ndarray
        ``L_imp(t)``, the energy taken out at impacts and other velocity jumps (≥ 0 when
        dissipative; the trajectory's ``impact_loss``; zeros when absent).
    """

    energy: np.ndarray
    work: np.ndarray
    balance: np.ndarray
    known: bool
    friction: np.ndarray
    impacts: np.ndarray


def energy_balance(traj: Any, model: Any | None = None) -> EnergyBalance | None:
    """The energy balance ``E − E₀ − W − W_fr + L_imp`` of a trajectory (see
    :class:`EnergyBalance`).

    ``W``, ``W_fr`` and ``L_imp`` are read from the trajectory (``work``, ``friction_work``,
    ``impact_loss``: the simulation records them, viz does not recompute the dynamics); W is
    computed here only for a trajectory that did not record it (``work`` NaN).

    Parameters
    ----------
    traj : Trajectory
    model : Model, optional
        Needed for W (its ``B`` and ``f_passive`` at each sample). Without it W = 0 and
        ``known`` is False (friction and impacts are still subtracted).

    Returns
    -------
    EnergyBalance or None
        None when the trajectory has no energy samples.
    """
    e = getattr(traj, "energy", None)
    if e is None or len(e) == 0:
        return None
    e = np.asarray(e, dtype=float)
    t = np.asarray(traj.t, dtype=float)
    fr, imp = (_recorded(traj, name, e) for name in ("friction_work", "impact_loss"))
    w = getattr(traj, "work", None)
    if w is not None and np.shape(w) == e.shape and e.size and bool(np.all(np.isfinite(w))):
        w = np.asarray(w, dtype=float)
        return EnergyBalance(e, w, e - e[0] - w - fr + imp, True, fr, imp)
    if model is None:
        return EnergyBalance(e, np.zeros_like(e), e - e[0] - fr + imp, False, fr, imp)
    qd = np.asarray(traj.qd, dtype=float)
    fc = np.asarray(getattr(traj, "f_c", np.zeros_like(qd)), dtype=float)
    u = np.asarray(getattr(traj, "u", np.zeros((len(t), 0))), dtype=float)
    names = tuple(getattr(traj, "constraint_names", ()))
    mask = getattr(traj, "active_mask", None)
    power = np.empty(len(t))
    for i in range(len(t)):
        act = None
        if mask is not None and len(names):
            act = [n for n, a in zip(names, mask[i], strict=True) if a]
        terms = model.evaluate(float(t[i]), traj.q[i], qd[i], act)
        f = np.asarray(terms.f_passive, dtype=float) + fc[i]
        B = np.asarray(terms.B, dtype=float)
        if u.shape[1] and B.size:
            f = f + B @ u[i]
        power[i] = float(qd[i] @ f)
    work = _cumulative_work(t, power)
    return EnergyBalance(e, work, e - e[0] - work - fr + imp, True, fr, imp)


def _recorded(traj: Any, name: str, like: np.ndarray) -> np.ndarray:
    """A recorded per-sample energy array of the trajectory (zeros when it has none)."""
    a = getattr(traj, name, None)
    a = np.zeros_like(like) if a is None else np.asarray(a, dtype=float)
    return a if a.shape == like.shape else np.zeros_like(like)


def _cumulative_work(t: np.ndarray, power: np.ndarray) -> np.ndarray:
    """``∫ P dt`` from t[0] at every sample: Simpson's rule on each run of increasing times
    (a repeated time marks an event: the work is continuous across it), trapezoids on runs of
    two samples."""
    work = np.zeros(len(t))
    cuts = [0, *(np.flatnonzero(np.diff(t) <= 0) + 1).tolist(), len(t)]
    base = 0.0
    for a, b in itertools.pairwise(cuts):
        seg_t, seg_p = t[a:b], power[a:b]
        if b - a >= 3:
            from scipy.integrate import cumulative_simpson

            acc = np.concatenate([[0.0], cumulative_simpson(seg_p, x=seg_t)])
        elif b - a == 2:
            acc = np.array([0.0, 0.5 * (seg_p[0] + seg_p[1]) * (seg_t[1] - seg_t[0])])
        else:
            acc = np.zeros(b - a)
        work[a:b] = base + acc
        base = float(work[b - 1])
    return work


def velocity_unit(unit: str) -> str:
    """The rate unit of a coordinate unit (m → m/s, rad → rad/s, 1 → 1/s)."""
    return "?" if unit == "?" else f"{unit}/s"


def force_unit(unit: str) -> str:
    """The unit of the generalized force conjugate to a coordinate (m → N, rad → N·m, 1 → J)."""
    return {"m": "N", "rad": "N·m", "1": "J"}.get(unit, "?")
