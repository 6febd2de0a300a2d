"""Pinocchio's loop closures as the benchmarks' Pinocchio peers build them (one place).

``point_closures`` makes the 3-D point constraints (``CONTACT_3D`` between two joint frames,
local reference frame), sets Baumgarte's gains ``Kp`` and ``Kd = 2 √Kp`` on each, and prepares
the data and the proximal solver for a Python loop of ``pinocchio.constraintDynamics``. Used by
``sim_bench.py`` (planar bar mechanisms), ``library_wp.py`` (A04 Bricard) and
``andrews_peers.py`` (A03 Andrews).
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import Any

import numpy as np


def point_closures(
    model: Any, data: Any, pairs: Iterable[tuple[int, Any, int, Any]], kp: float, mu: float
) -> tuple[list[Any], list[Any], Any]:
    """Point closures ``(joint_a, point_a, joint_b, point_b)`` (points as 3-vectors in the joints'
    frames) for ``model``/``data``: the constraint models, their data, the proximal settings
    (absolute accuracy 1e-12, regularization ``mu``, at most 50 iterations), initialized."""
    import pinocchio as pin

    cms = []
    for ja, pa, jb, pb in pairs:
        cm = pin.RigidConstraintModel(
            pin.ContactType.CONTACT_3D, model, int(ja), pin.SE3(np.eye(3), np.asarray(pa, dtype=float)),
            int(jb), pin.SE3(np.eye(3), np.asarray(pb, dtype=float)), pin.ReferenceFrame.LOCAL,
        )  # fmt: skip
        cm.m_baumgarte_parameters.Kp = kp
        cm.m_baumgarte_parameters.Kd = 2.0 * math.sqrt(kp)
        cms.append(cm)
    cdatas = [cm.createData() for cm in cms]
    prox = pin.ProximalSettings(1e-12, mu, 50)
    pin.initConstraintDynamics(model, data, cms, cdatas)
    return cms, cdatas, prox


def step(acc: Any, q: np.ndarray, v: np.ndarray, dt: float, method: str) -> tuple[np.ndarray, np.ndarray]:
    """One step of the peers' Python loops on ``q̈ = acc(q, v)`` (vector-space coordinates):
    ``"euler"`` semi-implicit (symplectic) Euler, else classical RK4 in its second-order form."""
    if method == "euler":
        v = v + dt * acc(q, v)
        return q + dt * v, v
    k1 = acc(q, v)
    k2 = acc(q + 0.5 * dt * v, v + 0.5 * dt * k1)
    k3 = acc(q + 0.5 * dt * (v + 0.5 * dt * k1), v + 0.5 * dt * k2)
    k4 = acc(q + dt * (v + 0.5 * dt * k2), v + dt * k3)
    return q + dt * (v + dt / 6.0 * (k1 + k2 + k3)), v + dt / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)


def timed_runs(
    acc: Any, start: Any, sample: Any, dt: float, n: int, every: int, method: str, repeat: int,
    clock: Any, limit: float = math.inf,
) -> tuple[list[float], bool]:
    """``repeat + 1`` runs of ``n`` steps of :func:`step` (the first one a warm-up, not timed).

    ``start()`` returns the initial ``(q, v)`` and resets what ``sample(q, v)`` records; ``sample``
    is called at every ``every``-th step and at the end. A run stops as diverged when ``v[0]`` is
    not finite or exceeds ``limit`` in size. Returns the timed runs' ``clock()`` times and
    whether every run finished (a diverged run ends the repeats)."""
    walls: list[float] = []
    for rep in range(repeat + 1):
        q, v = start()
        t0 = clock()
        for k in range(n + 1):
            if k % every == 0:
                sample(q, v)
            if k == n:
                break
            q, v = step(acc, q, v, dt, method)
            if not math.isfinite(v[0]) or abs(v[0]) > limit:
                if rep:  # (the diverged run's time so far, as the peers' rows report it)
                    walls.append(clock() - t0)
                return walls, False
        if rep:
            walls.append(clock() - t0)
    return walls, True
