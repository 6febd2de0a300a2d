"""The energy bookkeeping a simulation records (issue #23): the work of Coulomb friction
(``Trajectory.friction_work``, integrated by the engine with each step's own quadrature) and the
energy lost at impacts (``Trajectory.impact_loss``), against closed forms — a block sliding up
and back down an incline (W_fr = −μ m g cos θ · path length), a spring–block stick–slip
oscillator (sinusoidal slip velocity, so the friction power is not polynomial), a ball bouncing
with restitution e (each impact takes (1 − e²)·½ m v²) — and the drift left in
``E − E₀ − W − W_fr + L_imp`` (:func:`nonmin.viz.energy_balance`)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from nonmin.model.planar import PlanarBuilder
from nonmin.sim import Trajectory, simulate
from nonmin.viz import energy_balance

G = 9.81


def _incline(theta: float, mu: float, mass: float = 1.0):  # type: ignore[no-untyped-def]
    b = PlanarBuilder("incline")
    b.point_mass("block", mass=mass, points=["p"])
    b.contact("slope", ("ground", (0.0, 0.0)), "p", axis=(math.cos(theta), math.sin(theta)), friction=mu, active=True)
    return b.build()


def _up_and_back(t: np.ndarray, theta: float, mu: float, v0: float) -> np.ndarray:
    """The path length of a block thrown up the incline at v0 that slides back (μ < tan θ)."""
    a_up = G * (math.sin(theta) + mu * math.cos(theta))
    a_dn = G * (math.sin(theta) - mu * math.cos(theta))
    t1 = v0 / a_up
    s1 = v0 * t1 - 0.5 * a_up * t1**2
    return np.where(t <= t1, v0 * t - 0.5 * a_up * t**2, s1 + 0.5 * a_dn * (t - t1) ** 2)


@pytest.mark.parametrize("method", ["rk4", "dopri5", "dop853", "midpoint"])
@pytest.mark.parametrize("sampled", [False, True])
def test_block_up_and_down_the_incline_friction_work_is_mu_m_g_cos_theta_times_path(method: str, sampled: bool) -> None:
    theta, mu, v0, mass = 0.5, 0.3, 2.0, 1.7
    m = _incline(theta, mu, mass)
    u = np.array([math.cos(theta), math.sin(theta)])
    t_eval = np.linspace(0.0, 1.0, 7) if sampled else None  # samples inside the steps too
    tr = simulate(m, 1.0, [0.0, 0.0], v0 * u, method=method, dt=1e-3, t_eval=t_eval, progress=False)
    assert [e.name for e in tr.events] == ["slip:slope"]
    ref = -mu * mass * G * math.cos(theta) * _up_and_back(tr.t, theta, mu, v0)
    assert np.max(np.abs(tr.friction_work - ref)) < 1e-9 * mass * G
    bal = energy_balance(tr, m)
    assert bal is not None and np.array_equal(bal.friction, tr.friction_work)
    assert np.max(np.abs(bal.balance)) < 1e-9  # E − E₀ − W_fr: drift only (E changes by 5 J)
    assert np.max(np.abs(tr.energy - tr.energy[0])) > 1.0


def _spring_block(mu: float, k: float, mass: float):  # type: ignore[no-untyped-def]
    b = PlanarBuilder("spring_block")
    b.point_mass("block", mass=mass, points=["p"])
    b.contact("floor", ("ground", (0.0, 0.0)), "p", axis=(1.0, 0.0), friction=mu, active=True)
    b.spring("spring", ("ground", (0.0, 0.0)), "p", stiffness=k)
    return b.build()


def _stick_slip_oscillator(t: np.ndarray, x0: float, mu: float, k: float, mass: float) -> tuple[np.ndarray, np.ndarray]:
    """x(t) and the path length of m ẍ = −k x − μ m g sign(ẋ) released at rest at x0: half
    oscillations about ±μ m g / k until |k x| ≤ μ m g at a stop."""
    w, c = math.sqrt(k / mass), mu * mass * G / k
    x = np.full(t.shape, np.nan)
    path = np.full(t.shape, np.nan)
    ts, xs, ps = 0.0, x0, 0.0
    while abs(k * xs) > mu * mass * G:
        centre = c if xs > 0 else -c  # friction opposes the motion towards the spring's rest
        te = ts + math.pi / w
        sel = (t >= ts) & (t <= te)
        xi = centre + (xs - centre) * np.cos(w * (t[sel] - ts))
        x[sel], path[sel] = xi, ps + np.abs(xi - xs)
        xe = 2 * centre - xs
        ts, ps, xs = te, ps + abs(xe - xs), xe
    sel = t >= ts
    x[sel], path[sel] = xs, ps
    return x, path


@pytest.mark.parametrize("method", ["rk4", "dopri5", "dop853"])
def test_spring_block_stick_slip_friction_work_and_drift(method: str) -> None:
    """Sinusoidal slip velocity: the friction power −μ m g |ẋ| is not a polynomial in t, so the
    per-step quadrature is tested at its order, not exactly."""
    mu, k, mass, x0 = 0.1, 10.0, 1.0, 0.3
    m = _spring_block(mu, k, mass)
    T = 2.5
    tr = simulate(m, T, [x0, 0.0], [0.0, 0.0], method=method, dt=1e-3, rtol=1e-11, atol=1e-12,
                  t_eval=np.linspace(0.0, T, 101), progress=False)  # fmt: skip
    x, path = _stick_slip_oscillator(tr.t, x0, mu, k, mass)
    names = [e.name for e in tr.events]
    assert names == ["slip:floor", "stick:floor"]  # the reversal, then it sticks (|k x| < μ m g)
    assert np.max(np.abs(tr.q[:, 0] - x)) < 1e-8
    ref = -mu * mass * G * path
    assert abs(ref[-1]) > 0.3  # the spring's 0.45 J go mostly to friction
    assert np.max(np.abs(tr.friction_work - ref)) < 1e-8
    bal = energy_balance(tr, m)
    assert bal is not None and np.max(np.abs(bal.balance)) < 1e-9
    assert abs(tr.energy[-1] - tr.energy[0] - tr.friction_work[-1]) < 1e-9


def _ball(e: float, mass: float = 0.8):  # type: ignore[no-untyped-def]
    b = PlanarBuilder("ball")
    b.point_mass("ball", mass=mass, points=["p"])
    b.point_on_line("floor", ("ground", (0.0, 0.0)), "p", axis=(1.0, 0.0), unilateral=True, active=False)
    return b.build()


@pytest.mark.parametrize(("method", "engine"), [("rk4", "auto"), ("dopri5", "auto"), ("rk4", "python")])
def test_bouncing_ball_loses_one_minus_e_squared_of_its_kinetic_energy_per_impact(method: str, engine: str) -> None:
    e, h, mass = 0.6, 1.0, 0.8
    m = _ball(e, mass)
    tr = simulate(m, 1.5, [0.0, h], [0.3, 0.0], method=method, dt=1e-3, restitution=e, engine=engine,
                  t_eval=np.linspace(0.0, 1.5, 31), progress=False)  # fmt: skip
    impacts = [ev for ev in tr.events if ev.name.startswith("impact:")]
    assert len(impacts) >= 2
    v = math.sqrt(2 * G * h)
    total = 0.0
    for i, ev in enumerate(impacts):
        loss = (1 - e**2) * 0.5 * mass * (v * e**i) ** 2  # the normal speed before impact i
        total += loss
        after = np.flatnonzero(tr.t == ev.t)[-1]
        assert tr.impact_loss[after] == pytest.approx(total, rel=1e-7)
        assert tr.impact_loss[after - 1] == pytest.approx(total - loss, rel=1e-7, abs=1e-12)
    bal = energy_balance(tr, m)
    assert bal is not None and np.max(np.abs(bal.balance)) < 1e-7 * mass * G * h
    assert np.max(np.abs(tr.energy - tr.energy[0])) > 0.5 * (1 - e**2) * mass * G * h


def test_friction_and_impacts_together_foot_demo() -> None:
    """The foot demo (impacts, slip, stick at heel and toe): the recorded terms close the
    balance to the integration error."""
    from nonmin import library

    mech = library.get("foot_friction")
    tr = simulate(mech, mech.t_final, dt=1e-3, restitution=0.2, progress=False)
    bal = energy_balance(tr, mech.model)
    assert bal is not None
    assert tr.friction_work[-1] < -0.5 and tr.impact_loss[-1] > 0.1
    assert np.all(np.diff(tr.friction_work) <= 1e-15)  # friction only dissipates
    scale = float(np.max(np.abs(tr.energy - tr.energy[0])))
    assert np.max(np.abs(bal.balance)) < 1e-6 * scale


def test_recorded_terms_are_saved_exported_and_old_files_load(tmp_path) -> None:  # type: ignore[no-untyped-def]
    import pandas as pd

    from nonmin.io import to_csv

    m = _incline(0.5, 0.3)
    tr = simulate(m, 0.5, [0.0, 0.0], [1.0, 0.5], dt=1e-3, t_eval=np.linspace(0, 0.5, 11), progress=False)
    assert np.any(tr.friction_work != 0.0)
    tr.save(tmp_path / "a.npz")
    back = Trajectory.load(tmp_path / "a.npz")
    assert np.array_equal(back.friction_work, tr.friction_work)
    assert np.array_equal(back.impact_loss, tr.impact_loss)
    to_csv(tr, tmp_path / "a.csv")
    df = pd.read_csv(tmp_path / "a.csv")
    assert np.allclose(df["friction_work"].to_numpy(), tr.friction_work, rtol=0, atol=0)
    assert "impact_loss" in df.columns
    # a file written before the arrays existed: loads with zeros
    with np.load(tmp_path / "a.npz") as d:
        old = {k: d[k] for k in d.files if k not in ("friction_work", "impact_loss")}
    np.savez(tmp_path / "old.npz", **old)
    o = Trajectory.load(tmp_path / "old.npz")
    assert o.friction_work.shape == (len(o),) and not o.friction_work.any() and not o.impact_loss.any()


@pytest.mark.parametrize("method", ["rk4", "dopri5"])
def test_user_reset_mid_slide_balance(method: str) -> None:
    """A user Reset in a friction run (the step located in Python on the engine's friction
    steps): the friction work over the whole slide is −μ m g x_end, the reset's energy jump
    ½ m (v⁻² − v1²) is counted as an event loss, and the balance closes."""
    from nonmin.sim import Event, Reset

    mu, v0, x1, v1 = 0.3, 3.0, 0.5, 2.0
    a = mu * G
    b = PlanarBuilder("floor")
    b.point_mass("block", mass=1.0, points=["p"])
    b.contact("floor", ("ground", (0.0, 0.0)), "p", axis=(1.0, 0.0), friction=mu, active=True)
    m = b.build()

    def kick(t, q, qd, active):  # type: ignore[no-untyped-def]
        qd = qd.copy()
        qd[0] = v1
        return q, qd, active

    ev = Event(lambda t, q, qd, fc: q[0] - x1, direction=1, transition=Reset(kick), name="kick")
    tr = simulate(m, 1.2, [0.0, 0.0], [v0, 0.0], events=[ev], method=method, dt=1e-3,
                  t_eval=np.linspace(0.0, 1.2, 25), progress=False)  # fmt: skip
    assert [e.name for e in tr.events] == ["kick", "stick:floor"]
    x_end = x1 + v1**2 / (2 * a)
    assert tr.friction_work[-1] == pytest.approx(-mu * G * x_end, rel=1e-10)
    v_minus = math.sqrt(v0**2 - 2 * a * x1)
    assert tr.impact_loss[-1] == pytest.approx(0.5 * (v_minus**2 - v1**2), rel=1e-10)
    bal = energy_balance(tr, m)
    assert bal is not None and np.max(np.abs(bal.balance)) < 1e-9


# ------------------------------------------------------------------ the work W of forces and controllers


def _driven_block(mass: float):  # type: ignore[no-untyped-def]
    """A block on a horizontal guide (a scleronomic row: its force does no work) pushed along it
    by a force input u."""
    b = PlanarBuilder("driven_block")
    b.point_mass("block", mass=mass, points=["p"])
    b.point_on_line("guide", ("ground", (0.0, 0.0)), "p", axis=(1.0, 0.0))
    b.force("push", "p", direction=(1.0, 0.0))
    return b.build()


@pytest.mark.parametrize("engine", ["engine", "python"])
@pytest.mark.parametrize(("method", "tol"), [("rk4", 1e-10), ("dopri5", 1e-8), ("dop853", 1e-8), ("midpoint", 1e-5)])
def test_work_of_a_sinusoidal_push_is_half_m_v_squared(engine: str, method: str, tol: float) -> None:
    """u = F sin ωt on a free block: v = F/(mω)(1 − cos ωt) and the work done is W = ½ m v²
    (closed form). Samples every 0.013 s fall inside the steps (the Hermite interpolant of W).
    Over 0.5 s, 0.4 of the push's period (1 s before; the Python driver's runs took most of
    the module's time)."""
    mass, F, w = 2.0, 3.0, 5.0
    m = _driven_block(mass)

    def push(t: float, q: np.ndarray, qd: np.ndarray, state: object = None, *, active: object = None) -> np.ndarray:
        return np.array([F * math.sin(w * t)])

    t_eval = np.arange(0.0, 0.5, 0.013)
    tr = simulate(m, 0.5, [0.0, 0.0], [0.0, 0.0], method=method, dt=1e-3, controller=push, t_eval=t_eval,
                  engine=engine, progress=False)  # fmt: skip
    v = F / (mass * w) * (1.0 - np.cos(w * tr.t))
    ref = 0.5 * mass * v**2
    assert np.all(np.isfinite(tr.work))
    assert np.max(np.abs(tr.work - ref)) < tol * max(1.0, float(np.max(ref)))
    bal = energy_balance(tr, m)
    assert bal is not None and np.array_equal(bal.work, tr.work)
    assert np.max(np.abs(bal.balance)) < tol


def test_damped_spring_work_is_the_energy_the_damper_took() -> None:
    """A spring–damper oscillator: W (the damper's work, the spring is in V) equals E − E₀ up to
    the integration error, and W < 0."""
    b = PlanarBuilder("damped")
    b.point_mass("block", mass=1.5, points=["p"])
    b.point_on_line("guide", ("ground", (0.0, 0.0)), "p", axis=(1.0, 0.0))
    b.spring("spring", ("ground", (0.0, 0.0)), "p", stiffness=40.0, damping=0.8)
    m = b.build()
    tr = simulate(m, 2.0, [0.3, 0.0], [0.0, 0.0], method="rk4", dt=1e-3, t_eval=np.linspace(0, 2, 41), progress=False)
    assert tr.work[-1] < -0.5 * (tr.energy[0] - tr.energy[-1]) < 0.0
    assert np.max(np.abs(tr.energy - tr.energy[0] - tr.work)) < 1e-9


def _arm_wall(dt: float, method: str = "rk4"):  # type: ignore[no-untyped-def]
    import copy
    import dataclasses
    from pathlib import Path

    import nonmin
    from nonmin.io import load_scenario, run_scenario

    sc = load_scenario(Path(nonmin.__file__).parent / "data" / "scenarios" / "arm_wall.toml")
    data = copy.deepcopy(dict(sc.data))
    data["simulate"] = {**data["simulate"], "dt": dt, "method": method}
    r = run_scenario(dataclasses.replace(sc, data=data), write=False, progress=False)
    return r.trajectory, r.model


def test_arm_wall_balance_converges_at_fourth_order() -> None:
    """The demo's arm_wall (2R arm, force controller, wall impact, output every 10 ms, RK4 steps
    of dt): E − E₀ − W − W_fr + L_imp with W the engine's quadrature shrinks 16× per halving of
    dt (measured: 1.2e-4, 4.9e-6, 3.0e-7, 1.8e-8, 1.1e-9 J at dt = 4, 2, 1, 0.5, 0.25 ms; with
    W by Simpson on the 10 ms samples it was 4.0e-2 J at 2 ms)."""
    drift = []
    for dt in (2e-3, 1e-3, 5e-4):
        tr, model = _arm_wall(dt)
        assert len(tr.events) == 1 and np.all(np.isfinite(tr.work))
        bal = energy_balance(tr, model)
        assert bal is not None and np.array_equal(bal.work, tr.work)
        drift.append(float(np.max(np.abs(bal.balance))))
    assert drift[0] < 1e-5
    assert drift[0] / drift[1] > 12.0 and drift[1] / drift[2] > 12.0, drift


def test_work_is_saved_exported_and_old_files_mark_it_unknown(tmp_path) -> None:  # type: ignore[no-untyped-def]
    import pandas as pd

    from nonmin.io import to_csv

    tr, model = _arm_wall(2e-3)
    tr.save(tmp_path / "a.npz")
    back = Trajectory.load(tmp_path / "a.npz")
    assert np.array_equal(back.work, tr.work)
    to_csv(tr, tmp_path / "a.csv")
    assert np.allclose(pd.read_csv(tmp_path / "a.csv")["work"].to_numpy(), tr.work, rtol=1e-15, atol=0)
    with np.load(tmp_path / "a.npz") as d:
        old = {k: d[k] for k in d.files if k != "work"}
    np.savez(tmp_path / "old.npz", **old)
    o = Trajectory.load(tmp_path / "old.npz")
    assert o.work.shape == (len(o),) and np.all(np.isnan(o.work))  # the marker: not recorded
    bal = energy_balance(o, model)  # W recomputed from the samples (Simpson): coarser
    assert bal is not None and bal.known and np.all(np.isfinite(bal.work))
    assert abs(bal.work[-1] - tr.work[-1]) < 1e-1


@pytest.mark.parametrize(("method", "engine"), [("rk4", "auto"), ("dopri5", "auto"), ("rk4", "python"),
                                                ("dopri5", "python")])  # fmt: skip
def test_work_across_impacts_pushed_bouncing_ball(method: str, engine: str) -> None:
    """A ball bouncing on the floor (e = 0.6) while pushed sideways by u = F sin ωt: the
    frictionless impacts leave the horizontal motion alone, so W = ½ m v_x² (closed form) across
    the events (the event samples carry the located partial step's own quadrature), and the
    balance E − E₀ − W + L_imp closes (engine event layer and general driver)."""
    mass, F, w = 0.8, 2.0, 4.0
    b = PlanarBuilder("pushed_ball")
    b.point_mass("ball", mass=mass, points=["p"])
    b.point_on_line("floor", ("ground", (0.0, 0.0)), "p", axis=(1.0, 0.0), unilateral=True, active=False)
    b.force("push", "p", direction=(1.0, 0.0))
    m = b.build()

    def push(t: float, q: np.ndarray, qd: np.ndarray, state: object = None, *, active: object = None) -> np.ndarray:
        return np.array([F * math.sin(w * t)])

    tr = simulate(m, 1.5, [0.0, 0.5], [0.0, 0.0], method=method, dt=1e-3, controller=push, restitution=0.6,
                  t_eval=np.linspace(0.0, 1.5, 31), engine=engine, progress=False)  # fmt: skip
    assert len(tr.events) >= 2 and np.all(np.isfinite(tr.work))
    vx = F / (mass * w) * (1.0 - np.cos(w * tr.t))
    assert np.max(np.abs(tr.work - 0.5 * mass * vx**2)) < 1e-8
    bal = energy_balance(tr, m)
    assert bal is not None and np.max(np.abs(tr.impact_loss)) > 0.5
    assert np.max(np.abs(bal.balance)) < 1e-7


def test_midpoint_work_of_a_halved_step_sums_its_sub_steps() -> None:
    """The general driver's midpoint quadrature when ImplicitMidpoint halves a step (the
    fixed-point iteration fails for the full step; max_iter = 2 forces it here): the work is
    Σ width × power at each sub-step's converged middle, read back from the evaluations' times
    (_midpoint_work) — against the sub-steps taken one by one."""
    from nonmin.sim._integrators import ImplicitMidpoint
    from nonmin.sim._simulate import _step_work

    lam = 30.0
    calls: list[tuple[float, float]] = []

    def fun(t: float, y: np.ndarray) -> np.ndarray:
        calls.append((t, float(y[0] ** 2 + t)))  # a "power" known at each evaluation
        return np.array([-lam * y[0] + math.sin(t)])

    integ = ImplicitMidpoint(dt=0.1, max_iter=6, xtol=1e-13)
    t0, h, y0 = 0.2, 0.1, np.array([1.0])
    y1 = integ.advance(fun, t0, y0, None, h)
    got = _step_work(integ, [p for _, p in calls], None, h, times=[t for t, _ in calls], t0=t0)
    # the same sub-steps one by one: each sub-step's last evaluation is its converged middle
    subs: list[tuple[float, float]] = []

    def walk(t: float, y: np.ndarray, hh: float, depth: int) -> np.ndarray:
        calls.clear()
        r = integ._solve(fun, t, y, None, hh)
        if r is not None:
            subs.append((hh, calls[-1][1]))
            return r
        ym = walk(t, y, 0.5 * hh, depth - 1)
        return walk(t + 0.5 * hh, ym, 0.5 * hh, depth - 1)

    y1b = walk(t0, y0, h, integ.max_halvings)
    assert len(subs) > 1  # the step was halved
    assert np.allclose(y1, y1b, rtol=0, atol=1e-14)
    assert got == pytest.approx(sum(w * p for w, p in subs), rel=1e-14)
