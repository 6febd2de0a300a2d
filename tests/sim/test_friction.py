"""Coulomb friction with stick–slip at point contacts (issue #22), planar: closed forms for the
block on an incline (stick below μ_f = tan θ, slip above with a = g (sin θ − μ_f cos θ), the
threshold), a block pushed by a ramp force (stick → slip at k t = μ_f m g), a block thrown
up the incline (slip → stick, or slip reversal), a disk launched sliding without spin (it rolls
from t* = v0/(3 μ_f g) on at 2 v0/3), Painlevé's rod (the inconsistency detected and reported
with the contact and the time), and the engine against the NumPy reference
(nonmin.core.slip_dynamics through nonmin.sim.friction_state) sample by sample."""

from __future__ import annotations

import math

import numpy as np
import pytest

from nonmin.core import slip_dynamics
from nonmin.errors import InputError, ModelError, PainleveError
from nonmin.model.planar import PlanarBuilder
from nonmin.sim import Deactivate, Event, Reset, friction_state, simulate

G = 9.81


def _incline(theta: float, mu: float, *, push: bool = False):  # type: ignore[no-untyped-def]
    """A point mass (1 kg) on the ground line through the origin along (cos θ, sin θ)."""
    b = PlanarBuilder("incline")
    b.point_mass("block", mass=1.0, points=["p"])
    b.contact("slope", ("ground", (0.0, 0.0)), "p", axis=(math.cos(theta), math.sin(theta)), friction=mu, active=True)
    if push:
        b.force("push", "p", direction=(math.cos(theta), math.sin(theta)))
    return b.build()


def _along(tr, theta: float) -> np.ndarray:  # type: ignore[no-untyped-def]
    return tr.q[:, 0] * math.cos(theta) + tr.q[:, 1] * math.sin(theta)


@pytest.mark.parametrize("method", ["rk4", "dopri5"])
def test_block_on_incline_slips_above_the_threshold(method: str) -> None:
    theta, mu = 0.5, 0.3  # tan θ = 0.546 > μ
    m = _incline(theta, mu)
    tr = simulate(m, 1.0, [0.0, 0.0], [0.0, 0.0], method=method, dt=1e-3, progress=False)
    a = G * (math.sin(theta) - mu * math.cos(theta))
    s = _along(tr, theta)
    assert np.max(np.abs(s + 0.5 * a * tr.t**2)) < 1e-9
    assert not tr.active_mask[:, m.constraint_names.index("slope.stick")].any()
    assert tr.metadata["engine"] == "engine"


def test_block_on_incline_sticks_below_the_threshold() -> None:
    theta, mu = 0.5, 0.6  # tan θ = 0.546 < μ
    m = _incline(theta, mu)
    tr = simulate(m, 1.0, [0.0, 0.0], [0.0, 0.0], dt=1e-3, progress=False)
    assert np.max(np.abs(tr.q)) < 1e-12 and np.max(np.abs(tr.qd)) < 1e-12
    assert tr.active_mask[:, m.constraint_names.index("slope.stick")].all()
    _, st = friction_state(m, 0.0, tr.q[-1], tr.qd[-1], tr.active[-1])
    assert st["slope"].mode == "stick"
    assert abs(abs(st["slope"].F) - G * math.sin(theta)) < 1e-12  # the sticking force
    assert abs(st["slope"].N - G * math.cos(theta)) < 1e-12


@pytest.mark.parametrize("delta", [1e-6, -1e-6])
def test_incline_threshold(delta: float) -> None:
    """μ_f = tan θ (1 ± 1e-6): sticks just above the threshold, slips just below."""
    theta = 0.5
    m = _incline(theta, math.tan(theta) * (1 + delta))
    tr = simulate(m, 0.2, [0.0, 0.0], [0.0, 0.0], dt=1e-3, progress=False)
    stuck = tr.active_mask[-1, m.constraint_names.index("slope.stick")]
    assert stuck == (delta > 0)


def test_ramp_force_breaks_sticking_at_mu_m_g() -> None:
    """Flat ground, a push k t: sticks until k t = μ m g, then x = k (t − t_s)³ / (6 m)."""
    mu, k = 0.4, 10.0
    m = _incline(0.0, mu, push=True)
    ts = mu * G / k
    tr = simulate(m, 0.8, [0.0, 0.0], [0.0, 0.0], controller=lambda t, q, qd, s, active=None: np.array([k * t]),
                  dt=1e-3, progress=False)  # fmt: skip
    names = [e.name for e in tr.events]
    assert names == ["slip:slope"]
    assert abs(tr.events[0].t - ts) < 1e-9
    x_ref = np.where(tr.t > ts, k * np.clip(tr.t - ts, 0, None) ** 3 / 6.0, 0.0)
    assert np.max(np.abs(tr.q[:, 0] - x_ref)) < 1e-8


@pytest.mark.parametrize("mu", [0.3, 0.8])
def test_block_thrown_up_the_incline(mu: float) -> None:
    """Up at v0: decelerates at g (sin θ + μ cos θ), stops at t1 = v0 / that; then sticks
    (μ > tan θ) or slides back at g (sin θ − μ cos θ)."""
    theta, v0 = 0.5, 2.0
    m = _incline(theta, mu)
    u = np.array([math.cos(theta), math.sin(theta)])
    tr = simulate(m, 1.0, [0.0, 0.0], v0 * u, dt=1e-3, progress=False)
    a_up = G * (math.sin(theta) + mu * math.cos(theta))
    t1 = v0 / a_up
    ev = tr.events[0]
    assert abs(ev.t - t1) < 1e-9
    s1 = v0 * t1 - 0.5 * a_up * t1**2
    a_dn = G * (math.sin(theta) - mu * math.cos(theta))
    s_ref = np.where(tr.t <= t1, v0 * tr.t - 0.5 * a_up * tr.t**2, s1 - 0.5 * max(a_dn, 0.0) * (tr.t - t1) ** 2)
    assert np.max(np.abs(_along(tr, theta) - s_ref)) < 1e-8
    if mu > math.tan(theta):
        assert ev.name == "stick:slope"
    else:
        assert ev.name == "slip:slope" and "s = -1" in ev.transition


def _disk(mu: float, R: float = 0.2, mass: float = 1.5):  # type: ignore[no-untyped-def]
    b = PlanarBuilder("disk")
    b.body("disk", mass=mass, inertia=0.5 * mass * R**2, points={"c": (0.0, 0.0)})
    b.contact("floor", ("ground", (0.0, 0.0)), "c", axis=(1.0, 0.0), friction=mu, radius=R, active=True)
    return b.build()


@pytest.mark.parametrize("method", ["rk4", "dopri5", "dop853"])
def test_disk_launched_without_spin_rolls_from_t_star(method: str) -> None:
    mu, R, v0 = 0.25, 0.2, 3.0
    m = _disk(mu, R)
    tr = simulate(m, 2.0, [0.0, R, 0.0], [v0, 0.0, 0.0], method=method, dt=1e-3, progress=False)
    t_star = v0 / (3 * mu * G)
    assert [e.name for e in tr.events] == ["stick:floor"]
    assert abs(tr.events[0].t - t_star) < 1e-9
    after = tr.t > t_star + 1e-9
    assert np.max(np.abs(tr.qd[after, 0] - 2 * v0 / 3)) < 1e-9
    assert np.max(np.abs(tr.qd[after, 0] + R * tr.qd[after, 2])) < 1e-9  # rolling
    before = tr.t < t_star
    assert np.max(np.abs(tr.qd[before, 0] - (v0 - mu * G * tr.t[before]))) < 1e-9
    assert np.max(np.abs(tr.qd[before, 2] + 2 * mu * G / R * tr.t[before])) < 1e-9
    assert np.max(np.abs(tr.q[:, 1] - R)) < 1e-12


def test_engine_matches_the_numpy_reference_sample_by_sample() -> None:
    """The engine's q̈ against nonmin.sim.friction_state (nonmin.core.slip_dynamics) at every
    sample of a run that slips then rolls."""
    m = _disk(0.25)
    tr = simulate(m, 0.6, [0.0, 0.2, 0.0], [3.0, 0.0, 0.0], dt=1e-3, progress=False)
    worst = 0.0
    for i in range(0, len(tr.t), 7):
        if abs(tr.t[i] - tr.events[0].t) < 1e-9:
            continue
        qdd, _ = friction_state(m, tr.t[i], tr.q[i], tr.qd[i], tr.active[i])
        worst = max(worst, float(np.max(np.abs(qdd - tr.qdd[i]))))
    assert worst < 1e-11


def _rod(mu: float, half: float = 0.5):  # type: ignore[no-untyped-def]
    b = PlanarBuilder("painleve")
    b.body("rod", mass=1.0, inertia=half**2 / 3.0, points={"end": (-half, 0.0)})
    b.contact("floor", ("ground", (0.0, 0.0)), "end", axis=(1.0, 0.0), friction=mu, active=True)
    return b.build()


def _rod_state(theta: float, half: float, v_end: float, omega: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Rod at angle θ (lower end on the floor at x = 0), end sliding at v_end, spinning at ω."""
    q = np.array([half * math.cos(theta), half * math.sin(theta), theta])
    # end velocity (v_end, 0): ṙ = v_end e_x − ω (R s)^⊥ with R s = (−l cos θ, −l sin θ)
    qd = np.array([v_end - omega * half * math.sin(theta), omega * half * math.cos(theta), omega])
    return q, qd


def test_painleve_factor_matches_the_closed_form() -> None:
    """One slipping contact: N = N0 / (1 + μ s K) with, for the rod, 1 + μ s K =
    1 + 3 μ s sin θ cos θ / (1 + 3 cos² θ) (I = m l²/3), and N = m (g − l sin θ θ̇²) / (1 + 3 cos θ (cos θ + μ s sin θ))."""
    half, theta = 0.5, math.radians(60)
    for mu, s in ((0.5, 1), (1.2, -1), (1.5, -1)):
        m = _rod(mu, half)
        q, qd = _rod_state(theta, half, 0.7 * s, omega=0.4)
        act = frozenset({"floor"})
        terms = m.evaluate(0.0, q, qd, act)
        At = m.constraint_terms(0.0, q, qd, frozenset({"floor.stick"})).A
        sol = slip_dynamics(terms.M, terms.h, terms.constraints.A, terms.constraints.gamma, [0], At, [mu], [s])
        c, sn = math.cos(theta), math.sin(theta)
        factor = 1 + 3 * mu * s * sn * c / (1 + 3 * c * c)
        assert abs(sol.min_minor - factor) < 1e-12
        assert sol.consistent == (factor > 0)
        if factor > 0:
            N = (G - half * sn * 0.4**2) / (1 + 3 * c * (c + mu * s * sn))
            assert abs(sol.N[0] - N) < 1e-12
            assert abs(sol.F[0] + mu * s * N) < 1e-12


def test_painleve_rod_inconsistency_detected_and_reported() -> None:
    """Painlevé's classical case: the rod at tan θ = 2 (where 3 sin θ cos θ / (1 + 3 cos² θ) has
    its maximum 3/4), its end sliding so that s = −1, μ_f = 1.5 > 4/3: 1 + μ s K = 1 − 1.5·3/4
    < 0. The run stops with PainleveError naming the contact, the time and the factor."""
    half, mu = 0.5, 1.5
    m = _rod(mu, half)
    q0, qd0 = _rod_state(math.atan(2.0), half, -1.0)
    with pytest.raises(PainleveError) as info:
        simulate(m, 1.0, q0, qd0, dt=1e-4, progress=False)
    err = info.value
    assert err.contact == "floor" and err.t == 0.0
    assert abs(err.factor - (1 - mu * 0.75)) < 1e-12
    assert "floor" in str(err) and "Painlev" in str(err)
    tr = simulate(m, 1.0, q0, qd0, dt=1e-4, progress=False, throw=False)
    assert tr.status.name == "FAILED" and "Painlev" in tr.message


def test_rod_below_four_thirds_slides_then_sticks() -> None:
    """The same state with μ_f = 1.3 < 4/3: consistent (1 + μ s K = 0.025); N = N0/0.025 is
    large, the slip stops at once and the end sticks."""
    half = 0.5
    m = _rod(1.3, half)
    q0, qd0 = _rod_state(math.atan(2.0), half, -1.0)
    tr = simulate(m, 0.2, q0, qd0, dt=1e-4, progress=False)
    assert tr.status.name == "SUCCESS"
    assert tr.events[0].name == "stick:floor" and tr.events[0].t < 0.01


def test_contact_declaration_is_validated() -> None:
    b = PlanarBuilder("bad")
    b.point_mass("p", mass=1.0, points=["c"])
    with pytest.raises(InputError, match="friction"):
        b.contact("floor", ("ground", (0.0, 0.0)), "c", axis=(1.0, 0.0), friction=-0.1)
    with pytest.raises(InputError, match="radius"):
        b.contact("floor", ("ground", (0.0, 0.0)), "c", axis=(1.0, 0.0), friction=0.1, radius=float("nan"))
    with pytest.raises(ModelError, match="point mass"):
        b.contact("floor", ("ground", (0.0, 0.0)), "c", axis=(1.0, 0.0), friction=0.1, radius=0.1)


def test_friction_needs_the_engine() -> None:
    m = _incline(0.5, 0.3)
    with pytest.raises(InputError, match="engine"):
        simulate(m, 0.1, [0.0, 0.0], [0.0, 0.0], engine="python", progress=False)


def test_tangent_row_is_the_slip_velocity_and_the_engine_row_equals_python() -> None:
    """A wheel (radius 0.25) on a line of a moving plate: A_t q̇ is the relative velocity of the
    two material points at the contact along the line; γ_t = Ȧ_t q̇ (central differences); the
    C++ PlanarProgram's rows equal the Python element's to 1e-13."""
    R = 0.25
    b = PlanarBuilder("plate_wheel")
    b.body("plate", mass=2.0, inertia=0.3, points={"o": (0.1, -0.2)})
    b.body("wheel", mass=1.0, inertia=0.05, points={"c": (0.0, 0.0)})
    b.contact("rim", "o", "c", axis=(0.6, 0.8), friction=0.4, radius=R)
    m = b.build()
    act = frozenset({"rim", "rim.stick"})
    prog = m.engine_program()
    mask = m.active_mask(act)
    rng = np.random.default_rng(3)

    def rot(th: float, v: np.ndarray) -> np.ndarray:
        return np.array([[math.cos(th), -math.sin(th)], [math.sin(th), math.cos(th)]]) @ v

    def perp(v: np.ndarray) -> np.ndarray:
        return np.array([-v[1], v[0]])

    for _ in range(5):
        q, qd = rng.standard_normal(6), rng.standard_normal(6)
        ct = m.constraint_terms(0.0, q, qd, act)
        T = prog.evaluate(0.0, q, qd, mask)
        for name in ("A", "gamma", "phi", "velocity"):
            assert np.max(np.abs(getattr(T, name) - getattr(ct, name))) < 1e-13 * max(1.0, np.max(np.abs(getattr(ct, name))))
        u, n = rot(q[2], np.array([0.6, 0.8])), rot(q[2], np.array([-0.8, 0.6]))
        pw = q[3:5]
        c = pw - R * n
        v_b = qd[3:5] + qd[5] * perp(c - pw)
        v_a = qd[0:2] + qd[2] * perp(c - q[0:2])
        assert abs(ct.A[1] @ qd - u @ (v_b - v_a)) < 1e-13
        assert abs(ct.phi[0] - (n @ (pw - q[0:2] - rot(q[2], np.array([0.1, -0.2])))) + R) < 1e-13 + 0 * R
        h = 1e-6
        Ap = m.constraint_terms(0.0, q + h * qd, qd, act).A[1]
        Am = m.constraint_terms(0.0, q - h * qd, qd, act).A[1]
        assert abs((Ap - Am) @ qd / (2 * h) - ct.gamma[1]) < 1e-7


def test_foot_demo_lands_slips_and_sticks() -> None:
    """The demo mechanism (library foot_friction, scenario foot_friction.toml): the heel lands
    first, both corners slip, then stick at the same instant; at rest the corners carry the
    weight (N_heel + N_toe = m g) and no tangential force."""
    from nonmin import library

    mech = library.get("foot_friction")
    tr = simulate(mech, mech.t_final, restitution=0.3, dt=1e-3, progress=False)
    names = [e.name for e in tr.events]
    assert names[0] == "impact:heel"
    assert "slip:heel" in names and "slip:toe" in names
    assert names[-2:] == ["stick:heel", "stick:toe"]
    _, st = friction_state(mech.model, tr.t[-1], tr.q[-1], tr.qd[-1], tr.active[-1])
    assert st["heel"].mode == st["toe"].mode == "stick"
    assert abs(st["heel"].N + st["toe"].N - 1.2 * G) < 1e-9
    assert abs(st["heel"].F) < 1e-9 and abs(st["toe"].F) < 1e-9
    assert np.max(np.abs(tr.qd[-1])) < 1e-12


SCENARIO = """
name = "block on a slope"
[model.planar]
name = "slope"
[[model.planar.items]]
call = "point_mass"
name = "block"
mass = 1.0
points = ["p"]
[[model.planar.items]]
call = "contact"
name = "slope"
a = ["ground", [0.0, 0.0]]
b = "p"
axis = [0.8775825618903728, 0.479425538604203]
friction = {mu}
active = true
[initial]
q = [0.0, 0.0]
qd = [0.0, 0.0]
active = ["slope"]
[simulate]
t_final = 0.5
dt = 1e-3
contact = true
"""


def test_scenario_files_declare_frictional_contacts(tmp_path) -> None:  # type: ignore[no-untyped-def]
    """A TOML scenario's builder call ``contact`` with ``friction``; a bad value is a typed error
    naming the argument."""
    from nonmin.errors import NonminError
    from nonmin.io import load_scenario, run_scenario

    path = tmp_path / "slope.toml"
    path.write_text(SCENARIO.format(mu=0.3), encoding="utf-8")
    res = run_scenario(load_scenario(path), progress=False, write=False)
    tr = res.trajectory
    a = G * (math.sin(0.5) - 0.3 * math.cos(0.5))
    assert abs(_along(tr, 0.5)[-1] + 0.5 * a * tr.t[-1] ** 2) < 1e-9
    path.write_text(SCENARIO.format(mu=-1.0), encoding="utf-8")
    with pytest.raises(NonminError, match="friction must be >= 0"):
        run_scenario(load_scenario(path), progress=False, write=False)


def test_zeno_bouncing_then_sliding_then_sticking() -> None:
    """A point dropped from h = 0.2 m moving at 1 m/s onto a floor with e = 0.5, μ_f = 0.3:
    impacts accumulate at t∞ = t1 + 2 e v1 / (g (1 − e)) (Zeno: the bounces below two steps of
    flight are made plastic), then the contact slips at μ_f g and sticks at t∞ + vx/(μ_f g),
    x = vx t∞ + vx²/(2 μ_f g). The truncated bounces shift it by less than their remaining
    flight time (≤ 2 dt/(1 − e) = 4e-3 s)."""
    h, vx, e, mu = 0.2, 1.0, 0.5, 0.3
    b = PlanarBuilder("ball")
    b.point_mass("ball", mass=1.0, points=["p"])
    b.contact("floor", ("ground", (0.0, 0.0)), "p", axis=(1.0, 0.0), friction=mu)
    m = b.build()
    tr = simulate(m, 1.5, [0.0, h], [vx, 0.0], restitution=e, dt=1e-3, progress=False)
    t1, v1 = math.sqrt(2 * h / G), math.sqrt(2 * G * h)
    t_inf = t1 + 2 * e * v1 / (G * (1 - e))
    names = [ev.name for ev in tr.events]
    assert names.count("slip:floor") == 1 and names[-1] == "stick:floor"
    assert sum(n.startswith("impact:") for n in names) >= 5
    t_stick = tr.events[-1].t
    assert abs(t_stick - (t_inf + vx / (mu * G))) < 4e-3
    assert abs(tr.q[-1, 0] - (vx * t_inf + vx**2 / (2 * mu * G))) < 4e-3 * vx
    assert np.max(np.abs(tr.qd[-1])) < 1e-12


def _floor(mu: float):  # type: ignore[no-untyped-def]
    b = PlanarBuilder("floor")
    b.point_mass("block", mass=1.0, points=["p"])
    b.contact("floor", ("ground", (0.0, 0.0)), "p", axis=(1.0, 0.0), friction=mu, active=True)
    return b.build()


@pytest.mark.parametrize("method", ["rk4", "dopri5"])
def test_user_reset_mid_slide(method: str) -> None:
    """A user Event with friction: a block sliding at v0 = 3 m/s (μ_f = 0.3) is set to v1 = 2 m/s
    where it passes x1 = 0.5 m (a Reset, located on the engine's friction steps), then slides
    to rest: t1 = (v0 − √(v0² − 2 a x1))/a, the stop at t1 + v1/a, at x1 + v1²/(2a), a = μ_f g."""
    mu, v0, x1, v1 = 0.3, 3.0, 0.5, 2.0
    a = mu * G
    m = _floor(mu)

    def kick(t, q, qd, active):  # type: ignore[no-untyped-def]
        qd = qd.copy()
        qd[0] = v1
        return q, qd, active

    ev = Event(lambda t, q, qd, fc: q[0] - x1, direction=1, transition=Reset(kick), name="kick")
    tr = simulate(m, 1.2, [0.0, 0.0], [v0, 0.0], events=[ev], method=method, dt=1e-3, progress=False)
    assert tr.status.name == "SUCCESS" and tr.metadata["engine"] == "engine"
    assert [e.name for e in tr.events] == ["kick", "stick:floor"]
    t1 = (v0 - math.sqrt(v0**2 - 2 * a * x1)) / a
    assert abs(tr.events[0].t - t1) < 1e-12
    assert abs(tr.events[0].qd_after[0] - v1) < 1e-12
    assert abs(tr.events[1].t - (t1 + v1 / a)) < 1e-12
    assert abs(tr.q[-1, 0] - (x1 + v1**2 / (2 * a))) < 1e-12
    slide = (tr.t > t1 + 1e-9) & (tr.t < t1 + v1 / a - 1e-9)
    assert np.max(np.abs(tr.qd[slide, 0] - (v1 - a * (tr.t[slide] - t1)))) < 1e-10


@pytest.mark.parametrize("method", ["rk4", "dopri5"])
def test_user_reset_while_sticking_slides_again(method: str) -> None:
    """A block at rest (sticking) set moving at 1 m/s at t = 0.5 s (a time guard, t_eval given):
    it slips from there and sticks again at 0.5 + 1/(μ_f g), x = (t−0.5) − a (t−0.5)²/2."""
    mu = 0.3
    a = mu * G
    m = _floor(mu)

    def kick(t, q, qd, active):  # type: ignore[no-untyped-def]
        qd = qd.copy()
        qd[0] = 1.0
        return q, qd, active

    ev = Event(lambda t, q, qd, fc: t - 0.5, direction=1, transition=Reset(kick), name="kick")
    te = np.linspace(0.0, 1.2, 121)
    tr = simulate(m, 1.2, [0.0, 0.0], [0.0, 0.0], events=[ev], method=method, dt=1e-3, t_eval=te,
                  progress=False)  # fmt: skip
    assert [e.name for e in tr.events] == ["kick", "stick:floor"]
    assert abs(tr.events[0].t - 0.5) < 1e-12 and abs(tr.events[1].t - (0.5 + 1 / a)) < 1e-12
    assert "floor.stick" in tr.events[0].active_before and "floor.stick" not in tr.events[0].active_after
    s = np.clip(tr.t - 0.5, 0.0, 1 / a)
    assert np.max(np.abs(tr.q[:, 0] - (s - 0.5 * a * s**2))) < 1e-12
    assert np.all(np.isin(te, tr.t))


def test_terminal_user_event_while_slipping() -> None:
    """A terminal Event at x = 0.3 m of a block sliding from 3 m/s: it ends the run there."""
    mu, v0, x1 = 0.3, 3.0, 0.3
    a = mu * G
    ev = Event(lambda t, q, qd, fc: q[0] - x1, direction=1, terminal=True, name="mark")
    tr = simulate(_floor(mu), 1.0, [0.0, 0.0], [v0, 0.0], events=[ev], dt=1e-3, progress=False)
    assert tr.status.name == "EVENT_TERMINATED"
    assert abs(tr.t[-1] - (v0 - math.sqrt(v0**2 - 2 * a * x1)) / a) < 1e-12


def _dropped_rod(mu: float, half: float, gap: float, vx: float):  # type: ignore[no-untyped-def]
    """The rod of Painlevé's case at tan θ = 2, its end ``gap`` above the floor (contact open),
    the rod translating at (vx, 0)."""
    b = PlanarBuilder("painleve-drop")
    b.body("rod", mass=1.0, inertia=half**2 / 3.0, points={"end": (-half, 0.0)})
    b.contact("floor", ("ground", (0.0, 0.0)), "end", axis=(1.0, 0.0), friction=mu)
    th = math.atan(2.0)
    q0 = np.array([half * math.cos(th), gap + half * math.sin(th), th])
    return b.build(), q0, np.array([vx, 0.0, 0.0])


@pytest.mark.parametrize("method", ["rk4", "dopri5"])
def test_painleve_reached_during_the_run_at_touchdown(method: str) -> None:
    """Painlevé's inconsistency met mid-run: the rod falls flat-free (θ fixed at tan θ = 2, ω = 0)
    and its end lands at t = √(2 gap/g); the plastic, frictionless normal impact leaves the end
    sliding at ẋ_c + 3 sin θ cos θ v_y/(1 + 3 cos² θ) < 0 (s = −1), where μ_f = 1.5 gives
    1 + μ s K = 1 − 1.5·3/4 = −1/8. The run stops there with PainleveError (contact, t, factor);
    throw=False returns the samples up to it as a FAILED Trajectory with that message. The
    same drop translating the other way (s = +1, 1 + μ K = 2.125) is consistent and runs on."""
    half, mu, gap = 0.5, 1.5, 0.05
    t_land = math.sqrt(2 * gap / G)
    m, q0, qd0 = _dropped_rod(mu, half, gap, -1.0)
    with pytest.raises(PainleveError) as info:
        simulate(m, 0.5, q0, qd0, dt=1e-3, method=method, progress=False)
    err = info.value
    assert err.contact == "floor"
    assert abs(err.t - t_land) < 1e-12
    assert abs(err.factor - (1.0 - mu * 0.75)) < 1e-12
    tr = simulate(m, 0.5, q0, qd0, dt=1e-3, method=method, progress=False, throw=False)
    assert tr.status.name == "FAILED" and "PainleveError" in tr.message and "'floor'" in tr.message
    assert f"{t_land:.9f}" in tr.message and "-0.125" in tr.message
    assert len(tr) > 10 and t_land - 2e-3 < tr.t[-1] <= t_land + 1e-12
    m2, q2, qd2 = _dropped_rod(mu, half, gap, +1.0)
    ok = simulate(m2, 0.2, q2, qd2, dt=1e-3, method=method, progress=False)
    assert ok.status.name == "SUCCESS"
    assert ok.events[0].name == "impact:floor" and abs(ok.events[0].t - t_land) < 1e-12


def test_painleve_rod_jams_before_the_factor_vanishes() -> None:
    """Why a slipping contact does not run into the inconsistency (Génot & Brogliato 1999): as
    1 + μ s K → 0⁺ with N0 > 0, N = N0/(1 + μ s K) → ∞, and the friction impulse ∫μN dt
    diverges (logarithmically) while it decelerates the slip at a rate μ N a_t M̄⁻¹P a_tᵀ, so the
    slip stops first (dynamic jamming): the rod above the band 50.6°–73.0° where 1 − 1.5 K < 0,
    sliding with s = −1 (θ0 = 80°, end at −10 m/s, θ̇ = −4 rad/s, N0 > 0) approaches it twice
    (factor down to ≈ 0.15 and ≈ 0.08, N up to ≈ 57 and ≈ 92 N) and sticks at the second,
    with no PainleveError."""
    half, mu = 0.5, 1.5
    m = _rod(mu, half)
    q0, qd0 = _rod_state(math.radians(80.0), half, -10.0, omega=-4.0)
    tr = simulate(m, 0.56, q0, qd0, dt=1e-4, progress=False)
    assert tr.status.name == "SUCCESS"
    assert [e.name for e in tr.events] == ["stick:floor"]
    slipping = tr.t < tr.events[0].t
    th = tr.q[slipping, 2]
    factor = 1.0 - mu * 3 * np.sin(th) * np.cos(th) / (1 + 3 * np.cos(th) ** 2)  # s = −1
    assert np.all(factor > 0.0) and np.min(factor) < 0.1


@pytest.mark.parametrize("method", ["rk4", "dopri5"])
def test_pin_released_by_a_user_event_lets_the_pushed_block_slip(method: str) -> None:
    """A block on the floor (μ_f = 0.3) pushed by F = 5 N > μ_f m g and held by a pin, which a
    user Event releases at t = 0.3 s (Deactivate): the contact's mode is decided again with the
    push applied (slip, no tangential row after the event) and x = (F − μ_f m g)(t − 0.3)²/(2m)."""
    mu, F, t_rel = 0.3, 5.0, 0.3
    b = PlanarBuilder("pinned")
    b.point_mass("block", mass=1.0, points=["p"])
    b.contact("floor", ("ground", (0.0, 0.0)), "p", axis=(1.0, 0.0), friction=mu, active=True)
    b.revolute("pin", ("ground", (0.0, 0.0)), "p")
    b.force("push", "p", direction=(1.0, 0.0))
    m = b.build()
    ev = Event(lambda t, q, qd, fc: t - t_rel, direction=1, transition=Deactivate(["pin"]), name="release")
    tr = simulate(m, 1.0, [0.0, 0.0], [0.0, 0.0], events=[ev], controller=lambda t, q, qd, s, active=None: np.array([F]),
                  dt=1e-3, method=method, progress=False)  # fmt: skip
    rel = [e for e in tr.events if e.name == "release"]
    assert len(rel) == 1 and abs(rel[0].t - t_rel) < 1e-12
    assert rel[0].active_after == frozenset({"floor"})
    assert [e.name for e in tr.events if e.t > t_rel + 1e-9] == []
    s = np.clip(tr.t - t_rel, 0.0, None)
    assert np.max(np.abs(tr.q[:, 0] - 0.5 * (F - mu * G) * s**2)) < 1e-12


def _rod_on_floor_frictionless(half: float):  # type: ignore[no-untyped-def]
    b = PlanarBuilder("rod_floor")
    b.body("rod", mass=1.0, inertia=half**2 / 3.0, points={"end": (-half, 0.0)})
    b.point_on_line("floor", ("ground", (0.0, 0.0)), "end", axis=(1.0, 0.0), unilateral=True, active=True)
    return b.build()


@pytest.mark.parametrize("engine", ["engine", "python"])
def test_contact_pulling_from_the_start_is_released_at_once(engine: str) -> None:
    """A closed contact whose normal force is already tensile at t0 (no downward crossing of
    zero to see) is released at t0: the rod at 85°, its end sliding at −20 m/s, spinning at
    ω = −8 rad/s, frictionless: N = m (g − l sin θ ω²)/(1 + 3 cos² θ) = −21.6 N. It leaves the
    floor at t0 and flies: centre q0 + q̇0 t − (0, g t²/2, 0), θ = θ0 + ω t (both drivers)."""
    half, theta, omega = 0.5, math.radians(85.0), -8.0
    m = _rod_on_floor_frictionless(half)
    q0, qd0 = _rod_state(theta, half, -20.0, omega=omega)
    N = (G - half * math.sin(theta) * omega**2) / (1 + 3 * math.cos(theta) ** 2)
    assert N < -21.0
    t_eval = np.linspace(0.0, 0.05, 11)
    tr = simulate(m, 0.05, q0, qd0, dt=1e-4, t_eval=t_eval, engine=engine, progress=False)
    assert [e.name for e in tr.events] == ["release:floor"]
    assert tr.events[0].t == 0.0
    assert not tr.active_mask[-1].any()
    ref = q0[None, :] + np.outer(tr.t, qd0)
    ref[:, 1] -= 0.5 * G * tr.t**2
    np.testing.assert_allclose(tr.q[-1], ref[-1], rtol=0, atol=1e-10)
    keep = tr.t > 0.0
    np.testing.assert_allclose(tr.q[keep], ref[keep], rtol=0, atol=1e-10)


def test_frictional_contact_pulling_from_the_start_is_released_at_once() -> None:
    """The same rod with μ_f = 1.5 (N = −34.9 N slipping): released at t0, then ballistic."""
    half, theta, omega = 0.5, math.radians(85.0), -8.0
    m = _rod(1.5, half)
    q0, qd0 = _rod_state(theta, half, -20.0, omega=omega)
    tr = simulate(m, 0.05, q0, qd0, dt=1e-4, progress=False)
    assert tr.events and tr.events[0].t == 0.0 and tr.events[0].name == "release:floor"
    assert not tr.active_mask[-1].any()
    ref = q0 + 0.05 * qd0
    ref[1] -= 0.5 * G * 0.05**2
    np.testing.assert_allclose(tr.q[-1], ref, rtol=0, atol=1e-10)
