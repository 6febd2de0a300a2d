"""Closed-chain planar mechanisms for the analysis tests (built with PlanarBuilder)."""

from __future__ import annotations

import numpy as np

from nonmin.model import assemble
from nonmin.model.planar import PlanarBuilder


def _bar(b: PlanarBuilder, name: str, length: float, mass: float = 1.0) -> None:
    b.body(
        name,
        mass=mass,
        inertia=mass * length**2 / 12.0,
        points={f"{name}.0": (-length / 2, 0.0), f"{name}.1": (length / 2, 0.0)},
    )


def _guess(p0: np.ndarray, p1: np.ndarray) -> list[float]:
    c = 0.5 * (p0 + p1)
    d = p1 - p0
    return [c[0], c[1], float(np.arctan2(d[1], d[0]))]


def five_bar(actuated: tuple[str, ...] = ("act1", "act4")):
    """Planar 5-bar: ground pins at (0, 0) and (1, 0), links 0.6, 0.8, 0.8, 0.6; 2 dof.

    Returns (model, state) with the actuators named in ``actuated`` (torques at the joints
    ``O1`` (ground–l1), ``B`` (l1–l2), ``C`` (l2–l3), ``D`` (l3–l4), ``O2`` (l4–ground)).
    """
    b = PlanarBuilder("five_bar")
    for nm, L in (("l1", 0.6), ("l2", 0.8), ("l3", 0.8), ("l4", 0.6)):
        _bar(b, nm, L)
    b.revolute("O1", ("ground", (0.0, 0.0)), "l1.0")
    b.revolute("B", "l1.1", "l2.0")
    b.revolute("C", "l2.1", "l3.0")
    b.revolute("D", "l3.1", "l4.0")
    b.revolute("O2", "l4.1", ("ground", (1.0, 0.0)))
    joints = {"act1": "O1", "act2": "B", "act3": "C", "act4": "O2"}
    for a in actuated:
        b.actuator(a, joints[a])
    m = b.build()
    P = [np.array(p) for p in ((0.0, 0.0), (0.2, 0.55), (0.6, 1.2), (1.1, 0.6), (1.0, 0.0))]
    q = [x for i in range(4) for x in _guess(P[i], P[i + 1])]
    return m, assemble(m, q)


def three_rrr(redundant: bool = False):
    """3-RRR planar parallel robot: three legs (0.5 + 0.5) from a triangle of base pins to a
    triangular platform; 3 dof; base joints actuated (and the middle ones when
    ``redundant``)."""
    b = PlanarBuilder("3rrr")
    base = [np.array([0.0, 0.0]), np.array([1.2, 0.0]), np.array([0.6, 1.04])]
    plat_c = np.array([0.6, 0.4])
    rp = 0.15
    ang = [np.pi * 7 / 6, -np.pi / 6, np.pi / 2]
    plat_local = [rp * np.array([np.cos(a), np.sin(a)]) for a in ang]
    b.body(
        "plat", mass=2.0, inertia=0.02, points={f"pp{i}": tuple(plat_local[i]) for i in range(3)}
    )
    q: list[float] = []
    for i in range(3):
        _bar(b, f"u{i}", 0.5)
        _bar(b, f"v{i}", 0.5)
    guess_plat = [plat_c[0], plat_c[1], 0.1]
    for i in range(3):
        pp = plat_c + plat_local[i]
        mid = 0.5 * (base[i] + pp)
        d = pp - base[i]
        nrm = np.array([-d[1], d[0]]) / np.linalg.norm(d)
        knee = mid + 0.3 * nrm
        q += _guess(base[i], knee) + _guess(knee, pp)
        b.revolute(f"A{i}", ("ground", tuple(base[i])), f"u{i}.0")
        b.revolute(f"K{i}", f"u{i}.1", f"v{i}.0")
        b.revolute(f"P{i}", f"v{i}.1", f"pp{i}")
        b.actuator(f"base{i}", f"A{i}")
        if redundant:
            b.actuator(f"knee{i}", f"K{i}")
    m = b.build()
    return m, assemble(m, guess_plat + q)


def admissible_velocity(model, q, rng, active=None):
    A = model.constraint_jacobian(0.0, q, active)
    _, s, Vt = np.linalg.svd(A)
    r = int(np.sum(s > 1e-10 * s[0]))
    Z = Vt[r:].T
    return Z @ rng.normal(size=Z.shape[1])
