"""Shared scene builders for the control examples (not an example itself).

The mechanisms the control examples and ``tests/control`` need that the library
(:mod:`nonmin.library`) does not provide in the form control needs: a Cartesian pendulum
pushed by one oblique force, a crank-driven four-bar, and the dual-arm grasp with a fixture
that holds the object until it is grasped. Built with :class:`nonmin.model.planar.PlanarBuilder`.
"""

from __future__ import annotations

import math

import numpy as np

from nonmin.control import project_configuration
from nonmin.model import Model
from nonmin.model.planar import PlanarBuilder

__all__ = [
    "arm2r_configuration",
    "crank_four_bar",
    "crank_four_bar_configuration",
    "dual_arm_grasp_configuration",
    "dual_arm_with_fixture",
    "oblique_pendulum",
    "pendulum_configuration",
    "smoothstep",
    "wall_tip_path",
]


def oblique_pendulum(angle: float = 0.3, *, length: float = 1.0, mass: float = 1.0, g: float = 9.81) -> Model:
    """Point mass on a rod in Cartesian coordinates (x, y), pushed by one force along
    ``(cos angle, sin angle)`` (B a single oblique column; rank(PB) = 1 except where the rod
    is parallel to the force)."""
    b = PlanarBuilder("oblique_pendulum", gravity=(0.0, -g), description="Cartesian pendulum, oblique actuator")
    b.point_mass("bob", mass=mass, points=["P"])
    b.ground_point("O", (0.0, 0.0))
    b.rod("rod", "O", "P", length=length)
    b.force("push", "P", direction=(math.cos(angle), math.sin(angle)))
    b.output("P")
    return b.build()


def pendulum_configuration(theta: float, length: float = 1.0) -> np.ndarray:
    """(x, y) of the pendulum at angle θ from +x."""
    return length * np.array([math.cos(theta), math.sin(theta)])


_FB = {"ground": 2.0, "crank": 0.6, "coupler": 1.8, "rocker": 1.4}


def crank_four_bar(*, g: float = 9.81) -> Model:
    """Grashof crank-rocker four-bar in absolute coordinates, driven by a crank motor.

    Ground pivots A = (0, 0), D = (2, 0); crank 0.6 m, coupler 1.8 m, rocker 1.4 m (uniform
    bars, 1 kg/m). One actuator ``motor`` (torque at joint A). Crank-driven, the mechanism has
    no actuation singularity (|BD| ∈ [1.4, 2.6] never equals 1.8 ± 1.4).
    """
    b = PlanarBuilder("crank_four_bar", gravity=(0.0, -g), description="crank-driven four-bar")
    L = _FB
    for name in ("crank", "coupler", "rocker"):
        m = L[name]
        b.body(name, mass=m, inertia=m * L[name] ** 2 / 12.0)
    b.ground_point("A", (0.0, 0.0))
    b.ground_point("D", (L["ground"], 0.0))
    b.revolute("A", "A", ("crank", (-L["crank"] / 2, 0.0)))
    b.revolute("B", ("crank", (L["crank"] / 2, 0.0)), ("coupler", (-L["coupler"] / 2, 0.0)))
    b.revolute("C", ("coupler", (L["coupler"] / 2, 0.0)), ("rocker", (L["rocker"] / 2, 0.0)))
    b.revolute("D", ("rocker", (-L["rocker"] / 2, 0.0)), "D")
    b.actuator("motor", "A")
    return b.build()


def _bar(p: np.ndarray, r: np.ndarray) -> list[float]:
    m = 0.5 * (p + r)
    return [float(m[0]), float(m[1]), math.atan2(r[1] - p[1], r[0] - p[0])]


def crank_four_bar_configuration(model: Model, crank_angle: float) -> np.ndarray:
    """Assembled configuration (elbow-up branch) with the given crank angle."""
    L = _FB
    A, D = np.zeros(2), np.array([L["ground"], 0.0])
    B = A + L["crank"] * np.array([math.cos(crank_angle), math.sin(crank_angle)])
    d = D - B
    dist = float(np.hypot(*d))
    a = (L["coupler"] ** 2 - L["rocker"] ** 2 + dist**2) / (2 * dist)
    h = math.sqrt(max(L["coupler"] ** 2 - a * a, 0.0))
    e = d / dist
    C = B + a * e + h * np.array([-e[1], e[0]])
    guess = np.array(_bar(A, B) + _bar(B, C) + _bar(D, C))
    return project_configuration(model, guess, fixed=[2])


def dual_arm_with_fixture(
    *, link: float = 0.8, object_length: float = 0.6, object_height: float = 0.8,
    base_distance: float = 2.0, g: float = 9.81,
) -> tuple[Model, np.ndarray]:
    """Two 2R arms and a bar object held by a ``fixture`` (weld to the ground) until grasped.

    Same geometry as :func:`nonmin.library.dual_arm_grasp`, plus the weld ``fixture`` (active by
    default) so that the object does not fall before the grasp, and the pin grasps
    ``grasp_L``, ``grasp_R`` (inactive by default). Returns the model and a configuration
    with the arms raised away from the object. Coordinates: ``L1, L2, R1, R2, object``
    (x, y, θ each); the object's are the last three.
    """
    b = PlanarBuilder("dual_arm_fixture", gravity=(0.0, -g), description="dual-arm grasp with fixture")
    Ib = link**2 / 12.0
    for s in ("L", "R"):
        b.body(f"{s}1", mass=1.0, inertia=Ib)
        b.body(f"{s}2", mass=1.0, inertia=Ib, points={f"{s}_tip": (link / 2, 0.0)})
    b.body("object", mass=0.5, inertia=0.5 * object_length**2 / 12.0,
           points={"O_left": (-object_length / 2, 0.0), "O_right": (object_length / 2, 0.0)})
    b.ground_point("table", (0.0, object_height))
    bases = {"L": np.array([-base_distance / 2, 0.0]), "R": np.array([base_distance / 2, 0.0])}
    for s in ("L", "R"):
        b.revolute(f"{s}_shoulder", ("ground", tuple(bases[s])), (f"{s}1", (-link / 2, 0.0)))
        b.revolute(f"{s}_elbow", (f"{s}1", (link / 2, 0.0)), (f"{s}2", (-link / 2, 0.0)))
    b.weld("fixture", "table", ("object", (0.0, 0.0)), angle=0.0)
    b.revolute("grasp_L", "L_tip", "O_left", active=False)
    b.revolute("grasp_R", "R_tip", "O_right", active=False)
    for s in ("L", "R"):
        b.actuator(f"{s}_shoulder", f"{s}_shoulder")
        b.actuator(f"{s}_elbow", f"{s}_elbow")
    b.output("L_tip", "R_tip")
    model = b.build()
    # arms folded: shoulder angle, elbow angle (relative)
    q: list[float] = []
    for s, sh, el in (("L", 2.0, -1.0), ("R", math.pi - 2.0, 1.0)):
        p0 = bases[s]
        p1 = p0 + link * np.array([math.cos(sh), math.sin(sh)])
        p2 = p1 + link * np.array([math.cos(sh + el), math.sin(sh + el)])
        q += _bar(p0, p1) + _bar(p1, p2)
    q += [0.0, object_height, 0.0]
    return model, np.array(q)


def arm2r_configuration(tip: np.ndarray, l1: float = 1.0, l2: float = 1.0) -> np.ndarray:
    """Absolute coordinates ``(link1.x, link1.y, link1.θ, link2.x, link2.y, link2.θ)`` of the 2R
    arm of :func:`nonmin.library.arm2r_wall` with its tip at ``tip`` (elbow with q2 > 0)."""
    x, y = float(tip[0]), float(tip[1])
    c2 = (x * x + y * y - l1 * l1 - l2 * l2) / (2 * l1 * l2)
    q2 = math.acos(max(-1.0, min(1.0, c2)))
    q1 = math.atan2(y, x) - math.atan2(l2 * math.sin(q2), l1 + l2 * math.cos(q2))
    a2 = q1 + q2
    p1 = l1 * np.array([math.cos(q1), math.sin(q1)])
    return np.array([0.5 * p1[0], 0.5 * p1[1], q1,
                     p1[0] + 0.5 * l2 * math.cos(a2), p1[1] + 0.5 * l2 * math.sin(a2), a2])


def smoothstep(s: float) -> float:
    """Quintic 0 → 1 on [0, 1] with zero end velocity and acceleration (clamped outside)."""
    s = min(max(s, 0.0), 1.0)
    return s * s * s * (10.0 - 15.0 * s + 6.0 * s * s)


def wall_tip_path(
    t: float,
    *,
    start: tuple[float, float] = (1.0, 0.0),
    wall_x: float = 1.5,
    overshoot: float = 0.1,
    slide: float = 0.5,
    t_reach: float = 1.0,
    t_settle: float = 0.4,
    t_slide: float = 2.0,
) -> np.ndarray:
    """Tip path of the wall examples.

    The tip heads for ``wall_x + overshoot`` (behind the wall, so contact surely happens) by
    ``t_reach``; then its x returns to ``wall_x`` within ``t_settle`` (from then on the path is
    consistent with the contact) while it slides up by ``slide`` during ``t_slide``.
    """
    s1 = smoothstep(t / t_reach)
    s2 = smoothstep((t - t_reach) / t_settle)
    s3 = smoothstep((t - t_reach) / t_slide)
    x = start[0] + s1 * (wall_x + overshoot - start[0]) - s2 * overshoot
    y = start[1] + slide * s3
    return np.array([x, y])


def dual_arm_grasp_configuration(model: Model, object_pose=(0.0, 0.8, 0.0), *, link: float = 0.8,
                                 object_length: float = 0.6, base_distance: float = 2.0) -> np.ndarray:
    """Configuration with the object at ``object_pose`` and both tips at its ends (elbows out)."""
    xo, yo, th = (float(v) for v in object_pose)
    half = 0.5 * object_length * np.array([math.cos(th), math.sin(th)])
    ends = {"L": np.array([xo, yo]) - half, "R": np.array([xo, yo]) + half}
    bases = {"L": np.array([-base_distance / 2, 0.0]), "R": np.array([base_distance / 2, 0.0])}
    q: list[float] = []
    for s, side in (("L", 1.0), ("R", -1.0)):
        d = ends[s] - bases[s]
        dist = float(np.hypot(*d))
        a = dist / 2
        h = math.sqrt(max(link * link - a * a, 0.0))
        e = d / dist
        elbow = bases[s] + a * e + side * h * np.array([-e[1], e[0]])
        q += _bar(bases[s], elbow) + _bar(elbow, ends[s])
    q += [xo, yo, th]
    return np.array(q)
