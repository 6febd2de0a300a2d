"""Named mechanisms: registry, consistent initial states, outputs, and short reference runs."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import nonmin.library as lib
from nonmin.core import forward_dynamics, nullspace_projector
from nonmin.errors import InputError, UnknownNameError
from nonmin.model import Model, assembly_residual, consistent

DATA = Path("/work/shared/benchmarks/data")
REQUIRED = {
    "A01_pendulum",
    "A02_n_four_bar",
    "A03_andrews",
    "crossed_four_bar",
    "slider_crank",
    "five_bar",
    "arm2r_wall",
    "dual_arm_grasp",
}
#: agreement of a short free run (solve_ivp DOP853 at 1e-11) with an exact reference
RUN_TOL = 1e-8


def _simulate(model: Model, q0, qd0, t_end: float, t_eval=None, active=None):
    n = model.n

    def rhs(t, y):
        e = model.evaluate(t, y[:n], y[n:], active)
        c = e.constraints
        return np.concatenate([y[n:], forward_dynamics(e.M, e.h, c.A, c.gamma, e.f_passive)])

    return solve_ivp(rhs, (0.0, t_end), np.concatenate([q0, qd0]), method="DOP853",
                     rtol=1e-11, atol=1e-11, t_eval=t_eval)


# ------------------------------------------------------------------ registry
def test_registry_names_and_errors():
    assert REQUIRED <= set(lib.names())
    with pytest.raises(UnknownNameError, match="unknown mechanism"):
        lib.get("no_such_mechanism")
    with pytest.raises(InputError, match="unknown parameter"):
        lib.get("A02_n_four_bar", M=3)
    with pytest.raises(InputError):
        lib.get("A02_n_four_bar", N=0)


@pytest.mark.parametrize("name", lib.names())
def test_every_mechanism_is_consistent_and_documented(name):
    mech = lib.get(name)
    assert mech.name == name
    assert isinstance(mech.model, Model)
    assert mech.t_final > 0 and mech.description and mech.reference
    fn = lib.__dict__[name.lower()] if name.lower() in lib.__dict__ else None
    doc = (fn or lib._registry._REGISTRY[name]).__doc__ or ""
    assert "Source" in doc or "source" in doc
    res = assembly_residual(mech.model, mech.state)
    assert res.position < 1e-12 and res.velocity < 1e-12 and res.penetration == 0.0
    assert consistent(mech.model, mech.state)
    out = mech.model.outputs(0.0, mech.state.q, mech.state.qd)
    assert out and all(np.isfinite(v).all() for v in out.values())
    e = mech.model.evaluate(0.0, mech.state.q, mech.state.qd)
    qdd = forward_dynamics(e.M, e.h, e.constraints.A, e.constraints.gamma, e.f_passive)
    assert np.isfinite(qdd).all()


# ------------------------------------------------------------------ A01
def test_a01_matches_exact_solution_for_half_a_second():
    mech = lib.a01_pendulum()
    data = np.loadtxt(DATA / "A01_pendulum_exact_0-10s.csv", delimiter=",", comments="#")[:51]
    sol = _simulate(mech.model, mech.state.q, mech.state.qd, 0.5, t_eval=data[:, 0])
    np.testing.assert_allclose(sol.y[:2].T, data[:, 1:3], atol=RUN_TOL)
    np.testing.assert_allclose(sol.y[2:].T, data[:, 3:5], atol=RUN_TOL)
    out = mech.model.outputs(0.0, sol.y[:2, -1], sol.y[2:, -1])
    np.testing.assert_allclose(out["P1.position"], data[-1, 1:3], atol=RUN_TOL)
    assert lib.a01_pendulum(mirror=True).state.q[0] == -1.0


# ------------------------------------------------------------------ A02
def test_a02_energy_against_reduced_model():
    N = 3
    mech = lib.a02_n_four_bar(N=N)
    ref = lib.n_four_bar_reference([0.0, 0.4, 1.1], N=N)
    inertia, c = (N + 1) / 3 + N, (N + 1) / 2 + N
    for q, qd, th, om in zip(ref["q"], ref["qd"], ref["theta"], ref["omega"]):
        assert mech.model.kinetic_energy(q, qd) == pytest.approx(0.5 * inertia * om**2, rel=1e-13)
        assert mech.model.potential_energy(q) == pytest.approx(9.81 * c * math.sin(th), rel=1e-12, abs=1e-12)
        assert consistent(mech.model, mech.model.state(q, qd))


def test_a02_n2_short_run_matches_exact_reduction():
    mech = lib.a02_n_four_bar(N=2)
    t = np.linspace(0.0, 0.3, 4)
    ref = lib.n_four_bar_reference(t, N=2)
    sol = _simulate(mech.model, mech.state.q, mech.state.qd, 0.3, t_eval=t)
    np.testing.assert_allclose(sol.y[:15].T, ref["q"], atol=RUN_TOL)
    np.testing.assert_allclose(sol.y[15:].T, ref["qd"], atol=RUN_TOL)
    data = np.loadtxt(DATA / "A02_NfourBar_N2_exact_0-20s.csv", delimiter=",", comments="#")
    ref10 = lib.n_four_bar_reference([10.0], N=2)
    np.testing.assert_allclose(ref10["B0.position"][0], data[data[:, 0] == 10.0][0, 1:3], atol=1e-9)
    np.testing.assert_allclose(ref10["B0.position"][0], [0.3284581115, 0.9445185382], atol=1e-9)


def test_a02_n40_builds_and_loses_n_ranks_when_horizontal():
    N = 40
    mech = lib.a02_n_four_bar(N=N)
    m = mech.model
    assert m.n == 3 * (2 * N + 1) and m.num_rows() == 6 * N + 2
    assert mech.t_final == 20.0
    assert np.linalg.matrix_rank(m.constraint_jacobian(0.0, mech.state.q)) == 6 * N + 2
    ref = lib.n_four_bar_reference([0.0], N=N)
    q_flat = ref["q"][0].copy()
    for i in range(N + 1):  # all links horizontal: cranks at θ = 0
        q_flat[3 * i : 3 * i + 3] = [i + 0.5, 0.0, 0.0]
    for i in range(1, N + 1):
        k = 3 * (N + i)
        q_flat[k : k + 3] = [i + 0.5, 0.0, 0.0]
    assert np.abs(m.constraint_residual(0.0, q_flat)).max() < 1e-14
    _, rank = nullspace_projector(m.constraint_jacobian(0.0, q_flat))
    assert int(rank) == 6 * N + 2 - N


# ------------------------------------------------------------------ crossed four-bar
def test_crossed_four_bar_reference_and_short_run():
    mech = lib.crossed_four_bar()
    ref = lib.crossed_four_bar_reference([0.0, 0.05, 0.1, 0.15])
    np.testing.assert_allclose(ref["q"][0], mech.state.q, atol=1e-14)
    np.testing.assert_allclose(ref["qd"][0], mech.state.qd, atol=1e-14)
    sol = _simulate(mech.model, mech.state.q, mech.state.qd, 0.15, t_eval=[0.0, 0.05, 0.1, 0.15])
    np.testing.assert_allclose(sol.y[:9].T, ref["q"], atol=RUN_TOL)
    np.testing.assert_allclose(sol.y[9:].T, ref["qd"], atol=1e-7)
    # reference states lie on the branch, with conserved energy and the model's own energy
    for q, qd, en in zip(ref["q"], ref["qd"], ref["energy"]):
        out = mech.model.outputs(0.0, q, qd)
        assert abs(float(out["anti_branch_residual"])) < 1e-12
        assert 0.6 - 1e-12 <= float(out["branch_indicator"]) <= 1.0
        assert mech.model.energy(q, qd) == pytest.approx(en, rel=1e-12)
        assert consistent(mech.model, mech.model.state(q, qd), tol=1e-12)


def test_crossed_four_bar_reference_passes_change_points_with_conserved_energy():
    t = np.linspace(0.0, 3.0, 301)
    ref = lib.crossed_four_bar_reference(t)
    assert np.ptp(ref["energy"]) < 1e-8
    # the crank makes full turns (monotone angle), crossing θ = π, 2π, ... (change points)
    assert np.all(np.diff(ref["theta"]) > 0) and ref["theta"][-1] > 3 * math.pi
    # all coordinates are continuous in time (angles are not wrapped)
    assert np.abs(np.diff(ref["q"], axis=0)).max() < 0.5
    np.testing.assert_allclose(np.diff(ref["q"], axis=0), 0.01 * 0.5 * (ref["qd"][1:] + ref["qd"][:-1]), atol=2e-3)
    # at a change point the model's A loses one rank
    mech = lib.crossed_four_bar()
    q_cp = lib._planar._cfb_coordinates(math.pi, 1.0)[0]
    _, rank = nullspace_projector(mech.model.constraint_jacobian(0.0, q_cp))
    assert int(rank) == 7
    with pytest.raises(InputError, match="too small"):
        lib.crossed_four_bar(omega0=0.1)


# ------------------------------------------------------------------ A03 Andrews
def test_a03_consistent_initial_values_and_testset_accelerations():
    from nonmin.library._andrews import ANDREWS_LAMBDA0, ANDREWS_QDD0

    mech = lib.a03_andrews()
    m = mech.model
    q, qd = mech.state.q, mech.state.qd
    assert np.abs(m.constraint_residual(0.0, q)).max() < 1e-15
    e = m.evaluate(0.0, q, qd)
    A = e.constraints.A
    qdd = forward_dynamics(e.M, e.h, A, e.constraints.gamma)
    # Test Set y'(0): accelerations 14222.44..., -10666.83..., 0, ... (relative 1e-12)
    np.testing.assert_allclose(qdd, ANDREWS_QDD0, rtol=0, atol=1e-12 * np.abs(ANDREWS_QDD0).max())
    # multipliers of the Test Set: M q̈ = f − Gᵀλ, i.e. f_c = −Gᵀλ0
    f_c = e.M @ qdd - e.h
    np.testing.assert_allclose(f_c, -A.T @ ANDREWS_LAMBDA0, atol=1e-9)
    assert int(nullspace_projector(A, rtol=1e-10)[1]) == 6


def test_a03_christoffel_matches_testset_velocity_terms_and_is_skew():
    m = lib.a03_andrews().model
    rng = np.random.default_rng(1)
    for _ in range(3):
        q = rng.uniform(-2, 2, 7)
        qd = 100 * rng.standard_normal(7)
        static = m.testset_force(q, np.zeros(7))
        np.testing.assert_allclose(m.coriolis_force(q, qd), -(m.testset_force(q, qd) - static), rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(m.conservative_force(q), static, rtol=1e-12, atol=1e-15)
        # ∂M/∂q (analytic) against central differences, then dM/dt − 2C skew
        h = 1e-7
        Mdot_fd = (m.mass_matrix(q + h * qd) - m.mass_matrix(q - h * qd)) / (2 * h)
        Mdot = np.einsum("kij,k->ij", m.mass_matrix_derivative(q), qd)
        np.testing.assert_allclose(Mdot, Mdot_fd, atol=1e-6 * np.abs(Mdot).max())
        S = Mdot - 2 * m.coriolis_matrix(q, qd)
        np.testing.assert_allclose(S, -S.T, atol=1e-14 * np.abs(Mdot).max())
        # f_g = −∂V/∂q
        fd = np.array([-(m.potential_energy(q + h * ei) - m.potential_energy(q - h * ei)) / (2 * h)
                       for ei in np.eye(7)])
        np.testing.assert_allclose(m.conservative_force(q), fd, rtol=1e-6, atol=1e-9)
        # γ = d(A qd)/dt and Ȧ exact
        t = 0.0
        Ad = m.constraint_jacobian_dot(t, q, qd)
        Ap, Am = m.constraint_jacobian(t, q + h * qd), m.constraint_jacobian(t, q - h * qd)
        np.testing.assert_allclose(Ad, (Ap - Am) / (2 * h), atol=1e-6 * np.abs(Ad).max())
        np.testing.assert_allclose(m.constraint_bias(t, q, qd), Ad @ qd, rtol=1e-12, atol=1e-12)


@pytest.mark.slow
def test_a03_reaches_testset_reference_at_0_03():
    ref = np.loadtxt(DATA / "A03_andrews_testset_reference_t0.03.csv", delimiter=",", comments="#",
                     skiprows=4, usecols=2)
    mech = lib.a03_andrews()
    n = 7
    m = mech.model

    def rhs(t, y):
        e = m.evaluate(t, y[:n], y[n:])
        return np.concatenate([y[n:], forward_dynamics(e.M, e.h, e.constraints.A, e.constraints.gamma)])

    sol = solve_ivp(rhs, (0.0, 0.03), np.concatenate([mech.state.q, mech.state.qd]), method="DOP853",
                    rtol=1e-10, atol=1e-10)
    y = sol.y[:, -1]
    scd = np.min(-np.log10(np.abs(y[:7] - ref[:7]) / (1.0 + np.abs(ref[:7]))))
    assert scd > 9.5  # Test Set accuracy measure (atol/rtol = 1)


# ------------------------------------------------------------------ robots and switching
def _rank_PB(model, q, active=None):
    A = model.constraint_jacobian(0.0, q, active)
    P, rank = nullspace_projector(A)
    return int(np.linalg.matrix_rank(P @ model.input_matrix(q), tol=1e-9)), model.n - int(rank)


def test_arm2r_wall_contact_and_actuation():
    mech = lib.arm2r_wall()
    m = mech.model
    assert m.default_active == frozenset({"shoulder", "elbow"})
    out = m.outputs(0.0, mech.state.q, mech.state.qd)
    np.testing.assert_allclose(out["tip.position"], [1.0, 0.0], atol=1e-12)
    gap = m.constraint_terms(0.0, mech.state.q, mech.state.qd, ["wall"]).phi
    assert float(gap[0]) == pytest.approx(0.5) == float(out["gap"])
    np.testing.assert_allclose(out["joint_angles"], [-math.pi / 3, 2 * math.pi / 3])
    assert _rank_PB(m, mech.state.q) == (2, 2)
    # with the wall active: 1 DOF, still actuated
    assert _rank_PB(m, mech.state.q, ["shoulder", "elbow", "wall"]) == (1, 1)


def test_five_bar_loses_actuation_at_its_parallel_singularity():
    mech = lib.five_bar()
    assert _rank_PB(mech.model, mech.state.q) == (2, 2)
    sing = lib.five_bar(end_effector=(0.0, math.sqrt(3) / 2))
    assert consistent(sing.model, sing.state)
    assert _rank_PB(sing.model, sing.state.q) == (1, 2)
    near = lib.five_bar(end_effector=(0.0, 0.87))
    assert _rank_PB(near.model, near.state.q) == (2, 2)


def test_dual_arm_grasp_degrees_of_freedom():
    open_ = lib.dual_arm_grasp()
    m = open_.model
    names = set(m.constraint_names)
    assert {"grasp_L", "grasp_R"} <= names and not {"grasp_L", "grasp_R"} & m.default_active
    closed = names
    for grasp, dof in (("pin", 3), ("weld", 1)):
        mech = lib.dual_arm_grasp(grasp=grasp, grasped=True)
        assert consistent(mech.model, mech.state)
        assert _rank_PB(mech.model, mech.state.q, closed) == (dof, dof)
    assert _rank_PB(m, open_.state.q) == (4, 7)  # the free object is not actuated


def test_slider_crank_driver_and_change_point_variant():
    mech = lib.slider_crank()
    m = mech.model
    all_active = m.default_active | {"drive"}
    # the declared driver is consistent with the initial state (θ0, ω0)
    res = assembly_residual(m, m.state(mech.state.q, mech.state.qd, active=all_active))
    assert res.position < 1e-12 and res.velocity < 1e-12
    # driven: the slider acceleration is prescribed by the kinematics (0 DOF left)
    _, dof = _rank_PB(m, mech.state.q, all_active)
    assert dof == 0
    iso = lib.slider_crank(rod=0.5, theta0=0.3)
    q = iso.state.q.copy()
    from nonmin.library._planar import _link_coords

    # isosceles slider-crank at θ = π/2: slider at the pivot, A loses a rank
    P = np.array([0.0, 0.5])
    q[:6] = _link_coords(np.zeros(2), P) + _link_coords(P, np.zeros(2))
    q[6:9] = 0.0
    _, rank = nullspace_projector(iso.model.constraint_jacobian(0.0, q))
    assert int(rank) == 7


@pytest.mark.parametrize("name", sorted(REQUIRED))
def test_mechanisms_are_picklable_values(name):
    import pickle

    mech = lib.get(name)
    back = pickle.loads(pickle.dumps(mech))
    q, qd = mech.state.q, mech.state.qd
    np.testing.assert_array_equal(back.model.constraint_jacobian(0.0, q), mech.model.constraint_jacobian(0.0, q))
    assert back.model.outputs(0.0, q, qd).keys() == mech.model.outputs(0.0, q, qd).keys()
