"""Impact reactions (issue #22): each impact's impulse by constraint name, as force and torque
impulses on the bodies it joins, recorded with the event (both drivers), saved and exported.

References: closed forms (the lever rule of a bar on two points; a single-contact impact when a
resting contact reopens), an independent KKT solve of the impact with multipliers
(``[M −Aᵀ; A 0][v⁺; Λ] = [M v⁻; targets]`` over the rows at equality after the impact) and the
momentum balance ``Σ_I A_Iᵀ Λ_I = M (q̇⁺ − q̇⁻)``.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from conftest import G
from nonmin.analysis import impulses
from nonmin.model.planar import PlanarBuilder
from nonmin.sim import Trajectory, simulate

M_BAR, H0 = 1.0, 0.5
I_BAR = M_BAR * 4.0 / 12.0  # a bar of length 2 about its centre: k² = 1/3


def _bar(points: dict[str, float], name: str = "bar") -> object:
    """A bar (length 2, mass 1) above a floor y = 0, with unilateral contact points at x_i."""
    b = PlanarBuilder(name)
    b.body("bar", mass=M_BAR, inertia=I_BAR, points={k: (x, 0.0) for k, x in points.items()})
    for k in points:
        b.point_on_line(f"floor_{k}", ("ground", (0.0, 0.0)), k, axis=(1.0, 0.0), unilateral=True)
    return b.build()


def _kkt_impact(M, A_eq, qd_minus, rhs):  # type: ignore[no-untyped-def]
    """Independent reference: [M −Aᵀ; A 0][v; Λ] = [M v⁻; rhs] (A of full row rank)."""
    n, m = M.shape[0], A_eq.shape[0]
    K = np.block([[M, -A_eq.T], [A_eq, np.zeros((m, m))]])
    sol = np.linalg.solve(K, np.concatenate([M @ qd_minus, rhs]))
    return sol[:n], sol[n:]


@pytest.mark.parametrize("engine", ["python", "auto"])
def test_bar_on_two_points_impulses_follow_the_lever_rule(engine: str) -> None:
    """Flat at impact on points at x = −1 and 0.5, e = 0.4: it bounces at e·v without spin, and
    the impulses split m(1 + e)v by the lever rule, Λ₁ = m(1 + e)v/3, Λ₂ = 2Λ₁ (each on the bar,
    bar frame, no torque about its point; the ground gets the opposite)."""
    e = 0.4
    model = _bar({"l": -1.0, "r": 0.5})
    tr = simulate(model, 0.4, [0.0, H0, 0.0], [0.0, 0.0, 0.0], restitution=e, dt=1e-3, engine=engine,
                  progress=False)  # fmt: skip
    (ev,) = tr.events
    assert ev.name == "impact:floor_l+floor_r"
    v = np.sqrt(2 * G * H0)
    total = M_BAR * (1 + e) * v
    want = {"floor_l": total / 3, "floor_r": 2 * total / 3}
    assert set(ev.impulses) == set(want)
    for nm, lam in want.items():
        r = ev.impulses[nm]
        assert r.body_a == "ground" and r.body_b == "bar" and r.kind == "planar"
        np.testing.assert_allclose(r.force_b, [0.0, lam], atol=1e-10 * total)
        np.testing.assert_allclose(r.torque_b, [0.0], atol=1e-10 * total)
        np.testing.assert_allclose(r.force_a, [0.0, -lam], atol=1e-10 * total)  # on the ground, world axes
        np.testing.assert_allclose(r.multipliers, [lam], rtol=1e-10)
        assert r.determined_a.all() and r.determined_b.all()
    p = sum(r.generalized for r in ev.impulses.values())  # momentum balance
    np.testing.assert_allclose(p, M_BAR * 0 + model.mass_matrix(ev.q_before) @ (ev.qd_after - ev.qd_before),
                               atol=1e-12 * total)  # fmt: skip


@pytest.mark.parametrize("engine", ["python", "auto"])
def test_flat_bar_on_three_points_impulse_split_is_reported_undetermined(engine: str) -> None:
    """The issue's bar (e = 0.5, three points): ω = 0, the impulses sum to m(1 + e)v with no net
    moment, and each point's share is undetermined (rank 2 of 3): only the sum is physical."""
    model = _bar({"l": -1.0, "c": 0.0, "r": 1.0})
    tr = simulate(model, 0.4, [0.0, H0, 0.0], [0.0, 0.0, 0.0], restitution=0.5, dt=1e-3, engine=engine,
                  progress=False)  # fmt: skip
    (ev,) = tr.events
    assert abs(ev.qd_after[2]) < 1e-12
    v = np.sqrt(2 * G * H0)
    rs = ev.impulses
    assert set(rs) == {"floor_l", "floor_c", "floor_r"}
    fy = sum(r.force_b[1] for r in rs.values())
    assert abs(fy - M_BAR * 1.5 * v) < 1e-10
    moment = sum(x * rs[f"floor_{k}"].force_b[1] for k, x in (("l", -1.0), ("c", 0.0), ("r", 1.0)))
    assert abs(moment) < 1e-10
    for r in rs.values():
        assert not r.multipliers_determined.any()
        assert not r.determined_b[1]  # the normal force impulse: undetermined
        assert r.determined_b[0] and r.determined_b[2]  # no tangential impulse, no moment: decided


def _tilted_bar_state(b: float) -> tuple[list[float], list[float]]:
    """Left end (x = −1 on the bar) on the floor at the origin, tilted by 0.3 rad."""
    th = 0.3
    return [np.cos(th), np.sin(th), th], [0.0, 0.0, 0.0]


@pytest.mark.parametrize("engine", ["python", "auto"])
def test_impact_reopens_the_resting_contact_when_the_lever_lifts_it(engine: str) -> None:
    """A bar resting on its left end (active contact) rotates down until a point at x = b = 0.2
    hits the floor (e = 0.5). Since a·b < k² (1 · 0.2 < 1/3) the impact lifts the left end: the
    single-contact impact Λ = −(1 + e) u / (1/m + b²/I) is the answer, the left contact reopens
    (inactive after, zero impulse) — an equality row would have pulled the end down."""
    e, bb = 0.5, 0.2
    model = _bar({"l": -1.0, "r": bb})
    q0, qd0 = _tilted_bar_state(bb)
    tr = simulate(model, 1.0, q0, qd0, active={"floor_l"}, restitution=e, dt=1e-3, engine=engine,
                  progress=False)  # fmt: skip
    ev = next(x for x in tr.events if x.name == "impact:floor_r")
    assert "floor_l" in ev.active_before
    vx, vy, w = ev.qd_before
    u = vy + bb * w
    assert abs(vy - w) < 1e-9 and u < 0  # the left end rested, the point approaches
    lam = -(1 + e) * u / (1 / M_BAR + bb * bb / I_BAR)
    want = np.array([vx, vy + lam / M_BAR, w + bb * lam / I_BAR])
    assert want[1] - want[2] > 0.1  # premise: the left end leaves the floor
    np.testing.assert_allclose(ev.qd_after, want, atol=1e-9)
    assert ev.active_after == frozenset()
    assert set(ev.impulses) == {"floor_l", "floor_r"}
    np.testing.assert_allclose(ev.impulses["floor_r"].multipliers, [lam], rtol=1e-9)
    np.testing.assert_allclose(ev.impulses["floor_l"].multipliers, [0.0], atol=1e-9 * lam)


@pytest.mark.parametrize("engine", ["python", "auto"])
def test_impact_keeps_the_resting_contact_closed_against_a_kkt_solve(engine: str) -> None:
    """The same bar with the point at b = 1 (a·b > k²): the resting end stays on the floor
    (its normal velocity 0, Λ_l > 0) while the right end bounces at −e u; the velocities and both
    impulses equal a KKT solve with multipliers on the two rows at equality."""
    e, bb = 0.5, 1.0
    model = _bar({"l": -1.0, "r": bb})
    q0, qd0 = _tilted_bar_state(bb)
    tr = simulate(model, 1.0, q0, qd0, active={"floor_l"}, restitution=e, dt=1e-3, engine=engine,
                  progress=False)  # fmt: skip
    ev = next(x for x in tr.events if x.name == "impact:floor_r")
    M = model.mass_matrix(ev.q_before)
    A = np.array([[0.0, 1.0, -1.0], [0.0, 1.0, bb]])  # gap rows of the two points at θ = 0
    u = A @ ev.qd_before
    v_ref, lam_ref = _kkt_impact(M, A, ev.qd_before, np.array([0.0, -e * u[1]]))
    assert (lam_ref > 0).all()  # premise: both rows push
    np.testing.assert_allclose(ev.qd_after, v_ref, atol=1e-9)
    got = [ev.impulses[f"floor_{k}"].multipliers[0] for k in "lr"]
    np.testing.assert_allclose(got, lam_ref, rtol=1e-8)


@pytest.mark.parametrize("engine", ["python", "engine"])
def test_joint_limit_impulse_is_the_joint_torque_impulse(tmp_path: Path, engine: str) -> None:
    """URDF arm into its +0.5 rad stop with e = 0.5: the limit's impulse multiplier is the joint's
    angular impulse I(1 + e)ω⁻ (I = 0.1 + 1·0.5² about the axis)."""
    pytest.importorskip("pinocchio")
    from nonmin.model.robots import RobotModel

    here = Path(__file__).resolve().parents[1] / "robots"
    import sys

    sys.path.insert(0, str(here))
    try:
        from test_robot_joint_limits import ARM
    finally:
        sys.path.remove(str(here))
    p = tmp_path / "arm.urdf"
    p.write_text(ARM.format(extra=""))
    model = RobotModel.from_urdf(p)
    e = 0.5
    tr = simulate(model, (0.0, 0.6), [0.0], [0.0], dt=1e-3, restitution={"shoulder.upper": e}, engine=engine)
    ev = next(x for x in tr.events if x.name == "impact:shoulder.upper")
    r = ev.impulses["shoulder.upper"]
    assert r.kind == "generalized"
    np.testing.assert_allclose(r.multipliers, [0.35 * (1 + e) * ev.qd_before[0]], rtol=1e-9)
    np.testing.assert_allclose(r.generalized, [-0.35 * (1 + e) * ev.qd_before[0]], rtol=1e-9)


def test_impulses_are_saved_and_exported(tmp_path: Path) -> None:
    model = _bar({"l": -1.0, "r": 0.5})
    tr = simulate(model, 0.4, [0.0, H0, 0.0], [0.0, 0.0, 0.0], restitution=0.4, dt=1e-3, progress=False)
    tr.save(tmp_path / "run.npz")
    back = Trajectory.load(tmp_path / "run.npz")
    for nm, r in tr.events[0].impulses.items():
        b = back.events[0].impulses[nm]
        assert (b.body_a, b.body_b, b.kind) == (r.body_a, r.body_b, r.kind)
        np.testing.assert_array_equal(b.force_b, r.force_b)
        np.testing.assert_array_equal(b.determined_b, r.determined_b)
        assert b.determined_b.dtype == bool
    tr.to_csv(tmp_path / "run.csv")
    side = json.loads((tmp_path / "run.csv.json").read_text())
    rec = side["metadata"]["events"][0]["impulses"]
    assert {x["name"] for x in rec} == {"floor_l", "floor_r"}
    assert all(len(x["force_b"]) == 2 for x in rec)


def test_impulses_function_checks_shapes() -> None:
    from nonmin.errors import ShapeError

    model = _bar({"l": -1.0})
    with pytest.raises(ShapeError, match="qd_after"):
        impulses(model, np.zeros(3), np.zeros(3), np.zeros(2))


@pytest.mark.parametrize("engine", ["python", "auto"])
def test_planar_angle_limit_stops_the_pendulum_with_its_couple(engine: str) -> None:
    """Builder joint limits: a bar (length 1.2) pinned at its end, released horizontal, limited
    to θ ≥ −0.5 rad (``angle_limit``), e = 0.5. It reaches the stop with ω⁻ from the energy,
    ``½ I_O ω² = m g l sin 0.5``, leaves it at −e ω⁻, never passes it, and the limit's impulse is
    the couple ``I_O (1 + e)|ω⁻|`` (the pin's force has no moment about O)."""
    m, L, e = 2.0, 1.2, 0.5
    l, I_O = L / 2, m * L * L / 3
    b = PlanarBuilder("limited")
    b.body("bar", mass=m, inertia=m * L * L / 12, points={"end": (-l, 0.0)})
    b.revolute("pivot", ("ground", (0.0, 0.0)), "end")
    assert b.angle_limit("stop", "bar", lower=-0.5, upper=0.5) == ("stop.lower", "stop.upper")
    model = b.build()
    assert model.engine_program() is not None
    tr = simulate(model, 2.0, [l, 0.0, 0.0], [0.0, 0.0, 0.0], restitution={"stop.lower": e, "stop.upper": e},
                  dt=1e-3, engine=engine, progress=False)  # fmt: skip
    th = tr.q[:, 2]
    assert th.min() >= -0.5 - 1e-9 and th.max() <= 0.5 + 1e-9
    ev = tr.events[0]
    assert ev.name == "impact:stop.lower"
    w = -np.sqrt(2 * m * G * l * np.sin(0.5) / I_O)
    assert abs(ev.qd_before[2] - w) < 1e-6 * abs(w)
    assert abs(ev.qd_after[2] + e * ev.qd_before[2]) < 1e-9
    lam = ev.impulses["stop.lower"].multipliers[0]
    assert abs(lam - I_O * (1 + e) * abs(ev.qd_before[2])) < 1e-9
    assert ev.impulses["stop.lower"].determined.all() and ev.impulses["pivot"].determined.all()


@pytest.mark.parametrize("engine", ["python", "engine"])
def test_robot_end_effector_impact_impulse_is_the_single_contact_law(engine: str) -> None:
    """The 4-dof arm's end effector falls onto the floor (frame contact, e = 0.3, joint limits
    not reached): the impulse is Λ = (1 + e)(−a q̇⁻)/(a M⁻¹ aᵀ) (one contact, a its gap row), on
    the end-effector frame as the world force Λ n (n = +z), rotated into the frame's axes."""
    pytest.importorskip("pinocchio")
    from nonmin.model.robots import serial_arm

    model, state = serial_arm()
    q0 = np.array(state.q, dtype=float)
    q0[1] -= 0.05  # lift the end effector
    e = 0.3
    tr = simulate(model, (0.0, 0.6), q0, np.zeros(model.n), dt=1e-3, restitution=e, engine=engine, progress=False)
    ev = tr.events[0]
    assert ev.name == "impact:ee_contact"
    a = model.constraint_jacobian(ev.t, ev.q_before, {"ee_contact"})[0]
    M = model.mass_matrix(ev.q_before)
    lam = (1 + e) * (-a @ ev.qd_before) / (a @ np.linalg.solve(M, a))
    r = ev.impulses["ee_contact"]
    assert r.kind == "frame"
    np.testing.assert_allclose(r.multipliers, [lam], rtol=1e-9)
    R = model.frame_placement(ev.q_before, "ee_contact:b")[:3, :3]
    np.testing.assert_allclose(r.force_b, R.T @ [0.0, 0.0, lam], atol=1e-9 * lam)
