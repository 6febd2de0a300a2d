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
    "crank_four_bar",
    "crank_four_bar_configuration",
    "dual_arm_with_fixture",
    "oblique_pendulum",
    "pendulum_configuration",
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
    with the arms folded away from the object (elbows down).
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
    for s, sh, el in (("L", 1.2, -1.9), ("R", math.pi - 1.2, 1.9)):
        p0 = bases[s]
        p1 = p0 + link * np.array([math.cos(sh), math.sin(sh)])
        p2 = p1 + link * np.array([math.cos(sh + el), math.sin(sh + el)])
        q += _bar(p0, p1) + _bar(p1, p2)
    q += [0.0, object_height, 0.0]
    return model, np.array(q)
