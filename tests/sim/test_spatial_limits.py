"""Spatial joint limits (issue #22): a revolute joint's angle limits are unilateral constraints
(gap ``sin(θ − lower)`` / ``sin(upper − θ)``) with Newton's impact at the stop. A uniform rod
pinned at one end on a hinge about world y, released horizontal from rest, falls to its stop at
``upper``: the angular speed there is the energy's ``ω⁻ = √(2 m g l sin θ_s / I_O)``, the time
the exact pendulum quadrature ``t = ∫₀^θ_s dθ/ω(θ)``, it leaves at ``−e ω⁻`` and the limit's
impulse is the couple ``I_O (1 + e) ω⁻``."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import quad

from nonmin.errors import InputError, ModelError, UnknownNameError
from nonmin.model.spatial import SpatialBuilder
from nonmin.sim import EventSet, simulate

G = 9.81
M, L = 2.0, 1.2
LH, I_O = L / 2, M * L * L / 3


def _rod(upper: float = 0.5):  # type: ignore[no-untyped-def]
    b = SpatialBuilder("limited", gravity=(0.0, 0.0, -G))
    b.add_body("rod", mass=M, inertia=(1e-4, M * L * L / 12, M * L * L / 12), position=(LH, 0.0, 0.0))
    b.add_revolute("hinge", "ground", "rod", point=(0.0, 0.0, 0.0), axis=(0.0, 1.0, 0.0))
    assert b.add_angle_limit("stop", "hinge", lower=-0.5, upper=upper) == ("stop.lower", "stop.upper")
    return b.build()


def _theta(q: np.ndarray) -> np.ndarray:
    """The hinge angle from the rod's centre of mass (x, z) = l (cos θ, −sin θ)."""
    return np.arctan2(-q[..., 2], q[..., 0])


@pytest.mark.parametrize("engine", ["python", "engine"])
def test_spatial_revolute_limit_stops_the_pendulum_at_the_exact_time_and_speed(engine: str) -> None:
    e, th_s = 0.5, 0.5
    model = _rod(th_s)
    q0 = np.array([LH, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0])
    tr = simulate(model, 0.35 if engine == "python" else 1.2, q0, np.zeros(7), events=EventSet(restitution={"stop.lower": e, "stop.upper": e}),
                  dt=1e-3, engine=engine, progress=False)  # fmt: skip
    th = _theta(tr.q)
    assert th.max() <= th_s + 1e-8 and th.min() >= -0.5 - 1e-8
    ev = tr.events[0]
    assert ev.name == "impact:stop.upper"
    w = math.sqrt(2 * M * G * LH * math.sin(th_s) / I_O)
    # exact time of the fall: θ = u² removes the 1/√θ singularity at the release
    t_hit = quad(lambda u: 2 * u / math.sqrt(2 * M * G * LH * math.sin(u * u) / I_O), 0.0, math.sqrt(th_s),
                 epsabs=1e-13, epsrel=1e-13)[0]  # fmt: skip
    assert abs(ev.t - t_hit) < 1e-6
    assert abs(_theta(ev.q_before) - th_s) < 1e-8
    v_before = np.linalg.norm(ev.qd_before[:3])  # COM speed l ω
    v_after = np.linalg.norm(ev.qd_after[:3])
    assert abs(v_before - LH * w) < 1e-6 * LH * w
    assert abs(v_after - e * v_before) < 1e-9 * v_before
    assert ev.qd_after[2] > 0.0  # bounced back up
    lam = ev.impulses["stop.upper"].multipliers[0]
    assert abs(abs(lam) - I_O * (1 + e) * v_before / LH) < 1e-8 * I_O * w


@pytest.mark.parametrize("engine", ["python", "engine"])
def test_spatial_prismatic_limit_stops_the_falling_slider(engine: str) -> None:
    """A slider on a vertical prismatic joint falls from rest to its stop 0.1 below: free fall
    ``t = √(2 d / g)``, ``v⁻ = √(2 g d)``, leaves at ``e v⁻`` (slide gap ``s − lower``)."""
    e, d = 0.4, 0.1
    b = SpatialBuilder("slider", gravity=(0.0, 0.0, -G))
    b.add_body("block", mass=1.5, inertia=(0.01, 0.02, 0.03))
    b.add_prismatic("rail", "ground", "block", point=(0.0, 0.0, 0.0), axis=(0.0, 0.0, 1.0))
    assert b.add_slide_limit("stop", "rail", lower=-d, upper=0.5) == ("stop.lower", "stop.upper")
    q0 = np.array([0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0])
    tr = simulate(b.build(), 0.2, q0, np.zeros(7), events=EventSet(restitution=e), dt=1e-3, engine=engine,
                  progress=False)  # fmt: skip
    ev = tr.events[0]
    assert ev.name == "impact:stop.lower"
    assert abs(ev.t - math.sqrt(2 * d / G)) < 1e-9
    assert abs(ev.qd_before[2] + math.sqrt(2 * G * d)) < 1e-9
    assert abs(ev.qd_after[2] + e * ev.qd_before[2]) < 1e-9
    assert tr.q[:, 2].min() >= -d - 1e-9


def test_angle_limit_validates_its_bounds() -> None:
    b = SpatialBuilder("bad")
    b.add_body("rod", mass=1.0, inertia=(0.1, 0.1, 0.1))
    b.add_revolute("hinge", "ground", "rod", point=(0.0, 0.0, 0.0), axis=(0.0, 1.0, 0.0))
    b.add_prismatic("slide", "ground", "rod", point=(0.0, 0.0, 0.0), axis=(1.0, 0.0, 0.0))
    with pytest.raises(ModelError, match="lower must be < upper"):
        b.add_angle_limit("s", "hinge", lower=0.3, upper=0.3)
    with pytest.raises(InputError, match="upper must be finite"):
        b.add_angle_limit("s", "hinge", lower=0.0, upper=math.inf)
    with pytest.raises(InputError, match="lower must be finite"):
        b.add_angle_limit("s", "hinge", lower=math.nan)
    with pytest.raises(InputError, match="give lower, upper or both"):
        b.add_angle_limit("s", "hinge")
    with pytest.raises(ModelError, match="< π"):
        b.add_angle_limit("s", "hinge", lower=-2.0, upper=2.0)
    with pytest.raises(ModelError, match="must be revolute or cylindrical"):
        b.add_angle_limit("s", "slide", lower=0.0)
    with pytest.raises(UnknownNameError):
        b.add_angle_limit("s", "nope", lower=0.0)
    with pytest.raises(ModelError, match="lower must be < upper"):
        b.add_slide_limit("p", "slide", lower=1.0, upper=-1.0)
    assert b.add_slide_limit("p", "slide", upper=0.2) == ("p.upper",)
