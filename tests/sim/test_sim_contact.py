"""Unilateral contact: impacts located to 1e-10 s, classical impact law, release, Zeno guard."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from conftest import XW, G, arm_tip_x, make_arm_wall, make_ball
from nonmin.errors import ZenoError
from nonmin.sim import Status, simulate

EVENT_TOL = 1e-10
Q0 = np.array([0.9, 0.6])
TAU0, OMEGA = -20.0, 1.5


def _torque(t: float, q: np.ndarray, qd: np.ndarray, state: object = None, *, active: object = None) -> np.ndarray:
    return np.array([TAU0 * np.cos(OMEGA * t)])


def _free_impact_time() -> float:
    """First wall contact of the free arm, from an independent DOP853 run (scipy event)."""
    model = make_arm_wall()

    def f(t: float, y: np.ndarray) -> np.ndarray:
        q, qd = y[:2], y[2:]
        M = model.mass_matrix(q)
        rhs = model.conservative_force(q) - model.coriolis_matrix(q, qd) @ qd + model.input_matrix(q) @ _torque(t, q, qd)
        return np.concatenate((qd, np.linalg.solve(M, rhs)))

    def gap(t: float, y: np.ndarray) -> float:
        return float(XW - arm_tip_x(y[:2]))

    gap.terminal = True  # type: ignore[attr-defined]
    gap.direction = -1  # type: ignore[attr-defined]
    sol = solve_ivp(f, (0.0, 2.0), np.r_[Q0, 0.0, 0.0], method="DOP853", rtol=1e-13, atol=1e-13, events=gap)
    return float(sol.t_events[0][0])


def _kkt_lambda(model, t: float, q: np.ndarray, qd: np.ndarray) -> float:  # type: ignore[no-untyped-def]
    """Contact multiplier of the KKT system (independent cross-check; compressive > 0)."""
    M = model.mass_matrix(q)
    ct = model.constraint_terms(t, q, qd, {"wall"})
    f = model.conservative_force(q) - model.coriolis_matrix(q, qd) @ qd + model.input_matrix(q) @ _torque(t, q, qd)
    K = np.block([[M, -ct.A.T], [ct.A, np.zeros((1, 1))]])
    sol = np.linalg.solve(K, np.concatenate((f, -ct.gamma)))
    return float(sol[2])


def _classical_impact(M: np.ndarray, a: np.ndarray, v: np.ndarray, e: float) -> np.ndarray:
    Minv_a = np.linalg.solve(M, a)
    return v - (1.0 + e) * Minv_a * (a @ v) / (a @ Minv_a)


@pytest.fixture(scope="module")
def arm_run():  # type: ignore[no-untyped-def]
    model = make_arm_wall()
    tr = simulate(model, (0.0, 1.4), Q0, controller=_torque, method="dopri5", rtol=1e-12, atol=1e-14)
    return model, tr


def test_arm_impact_time_located_to_1e_10(arm_run) -> None:  # type: ignore[no-untyped-def]
    _, tr = arm_run
    impacts = [e for e in tr.events if e.name == "impact:wall"]
    assert len(impacts) == 1
    assert abs(impacts[0].t - _free_impact_time()) < EVENT_TOL


def test_arm_post_impact_velocity_is_the_classical_impact_law(arm_run) -> None:  # type: ignore[no-untyped-def]
    model, tr = arm_run
    ev = next(e for e in tr.events if e.name == "impact:wall")
    M = model.mass_matrix(ev.q_before)
    a = model.constraint_terms(ev.t, ev.q_before, ev.qd_before, {"wall"}).A[0]
    assert np.allclose(ev.qd_after, _classical_impact(M, a, ev.qd_before, 0.0), atol=1e-10)
    assert abs(a @ ev.qd_after) < 1e-10
    assert ev.active_after == frozenset({"wall"})
    loss = 0.5 * (ev.qd_before - ev.qd_after) @ M @ (ev.qd_before - ev.qd_after)
    T = lambda v: 0.5 * v @ M @ v  # noqa: E731
    assert np.isclose(T(ev.qd_before) - T(ev.qd_after), loss, rtol=1e-10)  # Carnot


def test_arm_contact_released_when_force_becomes_tensile(arm_run) -> None:  # type: ignore[no-untyped-def]
    model, tr = arm_run
    imp = next(e for e in tr.events if e.name == "impact:wall")
    rel = next(e for e in tr.events if e.name == "release:wall")
    assert rel.t > imp.t
    assert rel.active_after == frozenset()
    # while in contact the KKT multiplier is compressive; at release it is zero
    inside = (tr.t > imp.t) & (tr.t < rel.t)
    lam = [_kkt_lambda(model, t, q, qd) for t, q, qd in zip(tr.t[inside], tr.q[inside], tr.qd[inside], strict=True)]
    assert min(lam) > 0
    assert abs(_kkt_lambda(model, rel.t, rel.q_before, rel.qd_before)) < 1e-8 * max(lam)
    gap = XW - arm_tip_x(tr.q)
    assert gap.min() > -1e-10
    assert np.all(gap[inside] < 1e-10)
    after = tr.t > rel.t + 0.05
    assert np.all(gap[after] > 0)  # it leaves the wall, no chattering
    assert len(tr.events) == 2


def test_arm_impact_with_restitution() -> None:
    model = make_arm_wall()
    tr = simulate(model, (0.0, 1.1), Q0, controller=_torque, dt=5e-4, restitution=0.5)
    ev = tr.events[0]
    M = model.mass_matrix(ev.q_before)
    a = model.constraint_terms(ev.t, ev.q_before, ev.qd_before, {"wall"}).A[0]
    assert np.allclose(ev.qd_after, _classical_impact(M, a, ev.qd_before, 0.5), atol=1e-10)
    assert ev.active_after == frozenset()  # it bounces off


def _ball_accumulation_time(h: float, e: float) -> float:
    t1 = np.sqrt(2 * h / G)
    return float(t1 + 2 * e * np.sqrt(2 * G * h) / (G * (1 - e)))


@pytest.mark.parametrize(
    ("kw", "tol"),
    [({"dt": 1e-3}, 1e-2), ({"method": "dopri5", "rtol": 1e-10, "atol": 1e-12}, 1e-5)],
    ids=["rk4", "dopri5"],
)
def test_bouncing_ball_zeno_accumulation_is_handled(kw: dict, tol: float) -> None:
    tr = simulate(make_ball(), (0.0, 2.0), [0.0, 1.0], [0.1, 0.0], restitution=0.5, **kw)
    assert tr.status is Status.SUCCESS
    t_inf = _ball_accumulation_time(1.0, 0.5)
    impacts = [e for e in tr.events if e.name == "impact:floor"]
    assert 5 <= len(impacts) <= 40
    # bounce k: rebound speed = e × impact speed (Newton's law), until contact persists
    for ev in impacts[:4]:
        assert np.isclose(ev.qd_after[1], -0.5 * ev.qd_before[1], rtol=1e-9)
    assert abs(impacts[-1].t - t_inf) < tol
    assert tr.active[-1] == frozenset({"floor"})
    assert tr.q[:, 1].min() > -1e-10
    assert np.allclose(tr.q[-1, 1], 0.0, atol=1e-12) and np.allclose(tr.qd[-1, 1], 0.0, atol=1e-12)
    assert np.isclose(tr.qd[-1, 0], 0.1)  # frictionless: x-velocity untouched


def test_zeno_guard_raises_or_returns_failed_status() -> None:
    kw = {"method": "dopri5", "restitution": 0.5, "impact_velocity_threshold": 0.0}
    with pytest.raises(ZenoError):
        simulate(make_ball(), (0.0, 2.0), [0.0, 1.0], **kw)
    tr = simulate(make_ball(), (0.0, 2.0), [0.0, 1.0], throw=False, **kw)
    assert tr.status is Status.FAILED
    assert "Zeno" in tr.message
    assert tr.t[-1] < 1.36


def test_contact_false_ignores_unilateral_constraints() -> None:
    tr = simulate(make_ball(), (0.0, 0.6), [0.0, 1.0], dt=1e-3, contact=False)
    assert tr.events == ()
    assert tr.q[-1, 1] < 0  # falls through the floor


def test_library_arm2r_wall_impact_and_release() -> None:
    """The same checks on H3's planar arm2r_wall (absolute coordinates, 4 joint rows + wall)."""
    library = pytest.importorskip("nonmin.library")
    mech = library.get("arm2r_wall")
    model = mech.model
    u_amp = np.array([10.0, -6.0])

    def ctrl(t, q, qd, state=None, *, active=None):  # type: ignore[no-untyped-def]
        return u_amp * np.cos(2.0 * t)

    tr = simulate(mech, (0.0, 0.45), dt=1e-3, controller=ctrl, t_eval=np.linspace(0.0, 0.45, 46))
    names = [e.name for e in tr.events]
    assert names == ["impact:wall", "release:wall"]
    imp, rel = tr.events
    # impact: the classical (KKT) impact law with every constraint active after the impact
    M = model.mass_matrix(imp.q_before)
    A = model.constraint_terms(imp.t, imp.q_before, imp.qd_before, imp.active_after).A
    MiAt = np.linalg.solve(M, A.T)
    expected = imp.qd_before - MiAt @ np.linalg.solve(A @ MiAt, A @ imp.qd_before)
    assert np.allclose(imp.qd_after, expected, atol=1e-10)

    # release: the wall multiplier of the KKT system crosses zero there
    def wall_lambda(t: float, q: np.ndarray, qd: np.ndarray) -> float:
        terms = model.evaluate(t, q, qd, imp.active_after)
        ct = terms.constraints
        m = ct.A.shape[0]
        K = np.block([[terms.M, -ct.A.T], [ct.A, np.zeros((m, m))]])
        f = terms.h + terms.f_passive + terms.B @ ctrl(t, q, qd)
        lam = np.linalg.solve(K, np.concatenate((f, -ct.gamma)))[model.n :]
        return float(lam[model.row_slices(imp.active_after)["wall"]][0])

    inside = (tr.t > imp.t) & (tr.t < rel.t)
    lam = np.array([wall_lambda(t, q, qd) for t, q, qd in zip(tr.t[inside], tr.q[inside], tr.qd[inside], strict=True)])
    assert np.all(np.sign(lam) == np.sign(lam[0])) and abs(lam[0]) > 0
    assert abs(wall_lambda(rel.t, rel.q_before, rel.qd_before)) < 1e-7 * np.max(np.abs(lam))
    gap = tr.outputs(model)["gap"].ravel()
    assert gap.min() > -1e-10
    assert tr.phi_norm.max() < 1e-10
