"""Planar builder: exact A, Ȧ, γ against finite differences for every joint type; forces,
energies, input matrix, outputs, geometry and typed errors."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from nonmin.errors import InputError, ModelError, UnknownNameError
from nonmin.model.planar import PlanarBuilder

FD_STEP = 1e-6
#: relative agreement of exact derivatives with central differences
FD_RTOL = 1e-6


def _profile(t: float) -> tuple[float, float, float]:
    return 0.3 + 0.7 * math.sin(2.0 * t), 1.4 * math.cos(2.0 * t), -2.8 * math.sin(2.0 * t)


def every_joint_model():
    """A model that uses every joint type (positions need not be consistent)."""
    b = PlanarBuilder("every_joint", gravity=(0.3, -9.81))
    b.body("b1", mass=1.2, inertia=0.1, points={"P1": (0.4, -0.1)})
    b.body("b2", mass=0.7, inertia=0.05, points={"P2": (-0.3, 0.2)})
    b.body("b3", mass=2.0, inertia=0.3)
    b.point_mass("pm", mass=0.5, points=["PM"])
    b.ground_point("O", (0.1, -0.2))
    b.revolute("rev", "O", ("b1", (-0.5, 0.05)))
    b.revolute("rev2", ("b1", (0.5, 0.0)), ("b2", (-0.4, 0.1)))
    b.revolute("rev_pm", ("b3", (0.1, -0.3)), "PM")
    b.weld("weld", ("b2", (0.2, 0.3)), ("b3", (-0.1, 0.4)), angle=0.4)
    b.prismatic("pris", ("b1", (0.1, 0.2)), ("b3", (0.3, -0.2)), axis=(0.6, 0.8), angle=-0.2)
    b.point_on_line("pol", ("b2", (0.05, -0.1)), "PM", axis=(1.0, 2.0))
    b.point_on_line("wall", ("ground", (1.5, 0.0)), "P2", axis=(0.0, 1.0), unilateral=True)
    b.rod("rod", ("b3", (0.2, 0.1)), "PM", length=0.9)
    b.rod("rope", "P1", ("ground", (-1.0, 1.0)), length=2.0, unilateral=True)
    b.rod("rod_pm_ground", "PM", ("ground", (0.0, 0.0)), length=1.3)
    b.gear("gear", "b1", "b2", ratio=2.5, offset=0.1, carrier="b3")
    b.gear("gear_ground", "b1", "b3", ratio=-0.5)
    b.drive_angle("drive", "b2", body_a="b1", profile=_profile)
    b.drive_angle("drive_const", "b3", start=0.2, speed=1.7)
    b.spring("spring", "P1", "PM", stiffness=30.0, rest_length=0.4, damping=0.7)
    b.rotational_spring("tspring", "b1", "b2", stiffness=5.0, rest_angle=0.3, damping=0.2)
    b.actuator("tau", "rev2")
    b.actuator("push", "pris")
    b.torque("tau_free", "b3", body_a="b1")
    b.force("fx", "P2", direction=(1.0, 1.0))
    b.output("P1", "PM")
    return b.build()


MODEL = every_joint_model()
ALL = MODEL.constraint_names


def _random_state(seed: int):
    rng = np.random.default_rng(seed)
    return rng.uniform(-1.0, 1.0), rng.standard_normal(MODEL.n), rng.standard_normal(MODEL.n)


def _close(a, b, rtol=FD_RTOL):
    scale = max(1.0, float(np.max(np.abs(b))))
    np.testing.assert_allclose(a, b, rtol=0, atol=rtol * scale)


def test_model_sizes_and_kinds():
    assert MODEL.n == 3 * 3 + 2
    kinds = {c.name: c.kind for c in MODEL.constraints}
    assert kinds["wall"] == kinds["rope"] == "unilateral"
    assert kinds["drive"] == "rheonomic"
    assert MODEL.default_active == frozenset(ALL) - {"wall", "rope"}
    assert MODEL.num_rows(ALL) == 2 + 2 + 2 + 3 + 2 + 1 + 1 + 1 + 1 + 1 + 1 + 1 + 1 + 1


@pytest.mark.parametrize("seed", range(6))
def test_jacobian_is_dphi_dq(seed):
    t, q, _ = _random_state(seed)
    A = MODEL.constraint_jacobian(t, q, ALL)
    fd = np.zeros_like(A)
    for j in range(MODEL.n):
        e = np.zeros(MODEL.n)
        e[j] = FD_STEP
        fd[:, j] = (MODEL.constraint_residual(t, q + e, ALL) - MODEL.constraint_residual(t, q - e, ALL)) / (
            2 * FD_STEP
        )
    _close(A, fd)


@pytest.mark.parametrize("seed", range(6))
def test_velocity_gamma_and_adot_against_finite_differences(seed):
    t, q, qd = _random_state(seed)
    h = FD_STEP
    ct = MODEL.constraint_terms(t, q, qd, ALL)
    # velocity residual = dφ/dt along (q + s qd, t + s)
    dphi = (MODEL.constraint_residual(t + h, q + h * qd, ALL) - MODEL.constraint_residual(t - h, q - h * qd, ALL)) / (
        2 * h
    )
    _close(ct.velocity, dphi)
    # γ = d/dt (A qd + φ_t) at fixed qd: then A qdd + γ = φ̈
    vp = MODEL.constraint_terms(t + h, q + h * qd, qd, ALL).velocity
    vm = MODEL.constraint_terms(t - h, q - h * qd, qd, ALL).velocity
    _close(ct.gamma, (vp - vm) / (2 * h))
    # the matrix Ȧ = dA/dt along qd
    Ad = MODEL.constraint_jacobian_dot(t, q, qd, ALL)
    Ap = MODEL.constraint_jacobian(t + h, q + h * qd, ALL)
    Am = MODEL.constraint_jacobian(t - h, q - h * qd, ALL)
    _close(Ad, (Ap - Am) / (2 * h))
    # scleronomic rows: γ = Ȧ qd exactly
    rows = MODEL.row_slices(ALL)
    for name, sl in rows.items():
        if MODEL.constraint(name).kind != "rheonomic":
            np.testing.assert_allclose(ct.gamma[sl], Ad[sl] @ qd, rtol=1e-12, atol=1e-12)


def test_second_derivative_of_phi_along_a_trajectory():
    """φ̈ = A q̈ + γ along q(s) = q + s qd + s² a / 2 (the acceleration-level constraint)."""
    t, q, qd = _random_state(11)
    a = np.random.default_rng(3).standard_normal(MODEL.n)
    h = 1e-4

    def phi(s):
        return MODEL.constraint_residual(t + s, q + s * qd + 0.5 * s * s * a, ALL)

    fd2 = (phi(h) - 2 * phi(0.0) + phi(-h)) / (h * h)
    ct = MODEL.constraint_terms(t, q, qd, ALL)
    np.testing.assert_allclose(ct.A @ a + ct.gamma, fd2, atol=1e-5 * max(1.0, np.max(np.abs(fd2))))


def test_mass_matrix_constant_and_coriolis_zero():
    _, q, qd = _random_state(1)
    M = MODEL.mass_matrix(q)
    np.testing.assert_array_equal(M, MODEL.mass_matrix(q + 1.0))
    np.testing.assert_array_equal(np.diag(M)[:3], [1.2, 1.2, 0.1])
    np.testing.assert_array_equal(np.diag(M)[-2:], [0.5, 0.5])
    C = MODEL.coriolis_matrix(q, qd)
    assert not C.any()
    # dM/dt − 2C skew (trivially zero)
    S = -2 * C
    np.testing.assert_array_equal(S, -S.T)


@pytest.mark.parametrize("seed", range(4))
def test_conservative_force_is_minus_grad_potential(seed):
    _, q, _ = _random_state(seed)
    f = MODEL.conservative_force(q)
    fd = np.zeros(MODEL.n)
    for j in range(MODEL.n):
        e = np.zeros(MODEL.n)
        e[j] = FD_STEP
        fd[j] = -(MODEL.potential_energy(q + e) - MODEL.potential_energy(q - e)) / (2 * FD_STEP)
    _close(f, fd)


def test_damper_power_is_dissipative_and_matches_rates():
    _, q, qd = _random_state(5)
    fp = MODEL.passive_force(0.0, q, qd)
    # independent: ℓ̇ of the spring from point velocities, and the relative rotation rate
    p1, pm = MODEL.point_position("P1", q), MODEL.point_position("PM", q)
    v1, vm = MODEL.point_velocity("P1", q, qd), MODEL.point_velocity("PM", q, qd)
    ell_dot = (pm - p1) @ (vm - v1) / np.linalg.norm(pm - p1)
    rel = qd[MODEL.body_slice("b2")][2] - qd[MODEL.body_slice("b1")][2]
    expected_power = -0.7 * ell_dot**2 - 0.2 * rel**2
    assert fp @ qd == pytest.approx(expected_power, rel=1e-12)
    assert fp @ qd <= 0.0


def test_energies_against_centre_of_mass_kinematics():
    _, q, qd = _random_state(7)
    T = 0.0
    V = 0.0
    g = np.array([0.3, -9.81])
    for body in MODEL.bodies:
        sl = MODEL.body_slice(body.name)
        v = qd[sl][:2]
        T += 0.5 * body.mass * v @ v
        V -= body.mass * g @ q[sl][:2]
        if body.inertia is not None:
            T += 0.5 * body.inertia * qd[sl][2] ** 2
    p1, pm = MODEL.point_position("P1", q), MODEL.point_position("PM", q)
    V += 0.5 * 30.0 * (np.linalg.norm(pm - p1) - 0.4) ** 2
    V += 0.5 * 5.0 * (q[MODEL.body_slice("b2")][2] - q[MODEL.body_slice("b1")][2] - 0.3) ** 2
    assert MODEL.kinetic_energy(q, qd) == pytest.approx(T, rel=1e-13)
    assert MODEL.potential_energy(q) == pytest.approx(V, rel=1e-13)
    assert MODEL.energy(q, qd) == pytest.approx(T + V, rel=1e-13)


def test_input_matrix_virtual_power():
    _, q, qd = _random_state(2)
    B = MODEL.input_matrix(q)
    assert B.shape == (MODEL.n, 4)
    th = {b: q[MODEL.body_slice(b)][2] for b in ("b1", "b2", "b3")}
    om = {b: qd[MODEL.body_slice(b)][2] for b in ("b1", "b2", "b3")}
    # revolute torque: power = u (ω2 − ω1)
    assert B[:, 0] @ qd == pytest.approx(om["b2"] - om["b1"], rel=1e-12)
    # free torque between b1 and b3
    assert B[:, 2] @ qd == pytest.approx(om["b3"] - om["b1"], rel=1e-12)
    # point force along (1, 1)/√2 at P2: power = direction · v_P2
    d = np.array([1.0, 1.0]) / math.sqrt(2)
    assert B[:, 3] @ qd == pytest.approx(d @ MODEL.point_velocity("P2", q, qd), rel=1e-12)
    # prismatic force: power = u · (relative velocity of b's point w.r.t. a's body at that point)
    jt = MODEL.joint("pris")
    kin = MODEL._kin(q, qd)
    _, rate = jt.slide(kin)
    # when the slider constraint holds (θ3 − θ1 fixed, point on line) the power is u·ṡ; in general
    # it equals u·(v_b − v_a at p_b): compute that independently
    u = np.array([[math.cos(th["b1"]), -math.sin(th["b1"])], [math.sin(th["b1"]), math.cos(th["b1"])]]) @ np.array(
        [0.6, 0.8]
    )
    pb = kin.point(jt.b)[0]
    vb = kin.point(jt.b)[2]
    r1 = q[MODEL.body_slice("b1")][:2]
    v1 = qd[MODEL.body_slice("b1")][:2]
    va_at_pb = v1 + om["b1"] * np.array([-(pb - r1)[1], (pb - r1)[0]])
    assert B[:, 1] @ qd == pytest.approx(u @ (vb - va_at_pb), rel=1e-12)
    assert np.isfinite(rate)


def test_outputs_and_geometry():
    _, q, qd = _random_state(4)
    out = MODEL.outputs(0.0, q, qd)
    assert set(out) == {"P1.position", "P1.velocity", "PM.position", "PM.velocity"}
    np.testing.assert_allclose(out["PM.position"], q[-2:])
    np.testing.assert_allclose(out["PM.velocity"], qd[-2:])
    J = MODEL.point_jacobian("P1", q)
    np.testing.assert_allclose(J @ qd, out["P1.velocity"], rtol=1e-13)
    geo = MODEL.geometry(q)
    assert geo.dim == 2 and geo.segments.shape[1:] == (2, 2) and geo.segments.shape[0] >= 3
    assert geo.labels == ("P1", "P2", "PM", "O")


@given(st.floats(-3, 3), st.floats(-3, 3), st.floats(-10, 10), st.floats(-5, 5))
def test_revolute_residual_is_point_difference(x, y, th, om):
    """Property: φ of a ground pin is the ground point minus the body point."""
    b = PlanarBuilder("pin")
    b.body("bar", mass=1.0, inertia=0.1)
    b.revolute("pin", ("ground", (0.2, -0.1)), ("bar", (-0.5, 0.25)))
    m = b.build()
    q = np.array([x, y, th])
    p = np.array([x - 0.5 * math.cos(th) - 0.25 * math.sin(th), y - 0.5 * math.sin(th) + 0.25 * math.cos(th)])
    np.testing.assert_allclose(m.constraint_residual(0.0, q), np.array([0.2, -0.1]) - p, atol=1e-12)
    qd = np.array([0.0, 0.0, om])
    rs = p - q[:2]
    np.testing.assert_allclose(m.constraint_bias(0.0, q, qd), om * om * rs, atol=1e-9)


def test_replace_gives_a_parameter_variant():
    m2 = MODEL.replace(gravity=(0.0, 0.0))
    assert m2.gravity == (0.0, 0.0)
    assert MODEL.gravity == (0.3, -9.81)
    with pytest.raises(InputError):
        MODEL.replace(not_a_field=1)


# ------------------------------------------------------------------ bad input
def test_unknown_body_and_point_names():
    b = PlanarBuilder("bad")
    b.body("bar", mass=1.0, inertia=0.1)
    with pytest.raises(UnknownNameError, match="unknown body 'nope'"):
        b.revolute("j", ("ground", (0, 0)), ("nope", (0, 0)))
    with pytest.raises(UnknownNameError, match="unknown point"):
        b.revolute("j", "missing", ("bar", (0, 0)))
    with pytest.raises(UnknownNameError):
        b.actuator("u", "no_such_joint")
    b.revolute("j", ("ground", (0, 0)), ("bar", (0, 0)))
    m = b.build()
    with pytest.raises(UnknownNameError):
        m.point_position("nope", np.zeros(3))
    with pytest.raises(UnknownNameError):
        m.constraint_terms(0.0, np.zeros(3), np.zeros(3), active=["j", "nope"])
    with pytest.raises(KeyError):  # UnknownNameError is also a KeyError
        m.body_slice("nope")


def test_zero_axis_and_nonphysical_inertia():
    b = PlanarBuilder("bad")
    with pytest.raises(ModelError, match="mass must be > 0"):
        b.body("a", mass=0.0, inertia=1.0)
    with pytest.raises(ModelError, match="inertia"):
        b.body("a", mass=1.0, inertia=-1.0)
    with pytest.raises(ModelError, match="inertia"):
        b.body("a", mass=1.0, inertia=0.0)
    with pytest.raises(ModelError):
        b.point_mass("pm", mass=-2.0)
    b.body("a", mass=1.0, inertia=1.0)
    with pytest.raises(ModelError, match="non-zero direction"):
        b.prismatic("p", ("ground", (0, 0)), ("a", (0, 0)), axis=(0.0, 0.0))
    with pytest.raises(ModelError, match="non-zero direction"):
        b.point_on_line("l", ("ground", (0, 0)), ("a", (0, 0)), axis=(0.0, 0.0))
    with pytest.raises(ModelError):
        b.rod("r", ("ground", (0, 0)), ("a", (0, 0)), length=0.0)


def test_duplicate_names_and_point_mass_rotation():
    b = PlanarBuilder("bad")
    b.body("a", mass=1.0, inertia=1.0)
    with pytest.raises(ModelError, match="duplicate body"):
        b.body("a", mass=1.0, inertia=1.0)
    b.point_mass("pm", mass=1.0, points=["P"])
    with pytest.raises(ModelError, match="duplicate point"):
        b.point("P", "a", (0, 0))
    b.revolute("j", ("ground", (0, 0)), ("a", (0, 0)))
    with pytest.raises(ModelError, match="duplicate joint"):
        b.revolute("j", ("ground", (1, 0)), ("a", (1, 0)))
    with pytest.raises(ModelError, match="point mass"):
        b.weld("w", ("a", (0, 0)), "P")
    with pytest.raises(ModelError, match="point mass"):
        b.drive_angle("d", "pm")
    with pytest.raises(InputError):
        b.body("ground", mass=1.0, inertia=1.0)
    with pytest.raises(InputError):
        PlanarBuilder("g", gravity=(0.0, float("nan")))


def test_replace_gravity_with_text_is_named() -> None:
    """model.replace(gravity="down") was a raw ValueError (could not convert string to float)."""
    from nonmin import library
    from nonmin.errors import InputError

    with pytest.raises(InputError, match="gravity must be a finite 2-vector, got 'down'"):
        library.get("crossed_four_bar").model.replace(gravity="down")
