"""Coulomb friction at spatial point contacts (issue #22): an exact isotropic cone (the force
opposite to the slip velocity, |F| = μ_f N; sticking when |λ_t| ≤ μ_f λ_n). A puck sliding on
the floor in a direction not aligned with the axes stops at t = v0/(μ_f g) after
v0²/(2 μ_f g) and sticks; a puck launched across a slope (its slip direction turns) follows an
independent SciPy integration of m v̇ = m g sin θ e_down − μ_f m g cos θ v/|v|."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from nonmin.errors import InputError
from nonmin.model.spatial import SpatialBuilder
from nonmin.sim import friction_state, simulate

G = 9.81


def _puck(mu: float, slope: float = 0.0):  # type: ignore[no-untyped-def]
    """A puck (contact point at its centre of mass) on a plane through the origin tilted by
    ``slope`` about the world x axis (gravity components g sin θ down the slope)."""
    b = SpatialBuilder("puck", gravity=(0.0, -G * math.sin(slope), -G * math.cos(slope)))
    b.add_body("puck", mass=0.7, inertia=(0.01, 0.012, 0.02))
    b.add_contact("floor", "ground", "puck", point=(0.0, 0.0, 0.0), normal=(0.0, 0.0, 1.0), friction=mu,
                  active=True)  # fmt: skip
    return b.build()


def _q0() -> np.ndarray:
    return np.array([0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0])


@pytest.mark.parametrize("method", ["rk4", "dopri5"])
def test_puck_slides_along_an_oblique_direction_and_sticks(method: str) -> None:
    mu, v0 = 0.4, 2.5
    d = np.array([math.cos(0.7), math.sin(0.7), 0.0])
    m = _puck(mu)
    qd0 = np.zeros(7)
    qd0[:3] = v0 * d
    tr = simulate(m, 1.0, _q0(), qd0, method=method, dt=1e-3, progress=False)
    t_stop = v0 / (mu * G)
    assert [e.name for e in tr.events] == ["stick:floor"]
    assert abs(tr.events[0].t - t_stop) < 1e-9
    tt = np.minimum(tr.t, t_stop)
    s_ref = v0 * tt - 0.5 * mu * G * tt**2
    assert np.max(np.abs(tr.q[:, :3] - s_ref[:, None] * d)) < 1e-9
    _, st = friction_state(m, tr.t[-1], tr.q[-1], tr.qd[-1], tr.active[-1])
    assert st["floor"].mode == "stick" and abs(st["floor"].N - 0.7 * G) < 1e-9 and st["floor"].F < 1e-9


def test_puck_across_a_slope_follows_the_independent_integration() -> None:
    """μ_f = 0.2 < tan θ = 0.36: it never sticks; the slip direction turns from across the slope
    to down it."""
    mu, th, v0 = 0.2, 0.35, 2.0
    m = _puck(mu, th)
    qd0 = np.zeros(7)
    qd0[0] = v0
    tr = simulate(m, 1.5, _q0(), qd0, method="dopri5", rtol=1e-11, atol=1e-13, progress=False,
                  t_eval=np.linspace(0, 1.5, 31))  # fmt: skip

    def rhs(t: float, y: np.ndarray) -> np.ndarray:
        v = y[2:]
        return np.concatenate((v, np.array([0.0, -G * math.sin(th)]) - mu * G * math.cos(th) * v / np.linalg.norm(v)))

    ref = solve_ivp(rhs, (0, 1.5), [0.0, 0.0, v0, 0.0], rtol=1e-12, atol=1e-14, t_eval=tr.t, method="DOP853")
    assert not tr.events
    assert np.max(np.abs(tr.q[:, :2] - ref.y[:2].T)) < 1e-8
    assert np.max(np.abs(tr.qd[:, :2] - ref.y[2:].T)) < 1e-8
    assert np.max(np.abs(tr.q[:, 2])) < 1e-12


def test_puck_at_rest_on_a_slope_sticks_below_the_cone() -> None:
    m = _puck(0.5, 0.35)  # tan θ = 0.365 < 0.5
    tr = simulate(m, 0.5, _q0(), np.zeros(7), dt=1e-3, progress=False)
    assert np.max(np.abs(tr.q[:, :3])) < 1e-12
    _, st = friction_state(m, 0.5, tr.q[-1], tr.qd[-1], tr.active[-1])
    assert st["floor"].mode == "stick"
    assert abs(st["floor"].F - 0.7 * G * math.sin(0.35)) < 1e-9


def test_add_contact_validates_friction() -> None:
    b = SpatialBuilder("bad")
    b.add_body("p", mass=1.0, inertia=(1.0, 1.0, 1.0))
    with pytest.raises(InputError, match="friction"):
        b.add_contact("floor", "ground", "p", point=(0, 0, 0), normal=(0, 0, 1), friction=-1.0)
