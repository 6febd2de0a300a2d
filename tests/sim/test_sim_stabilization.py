"""Stabilization: residuals after projection; the crossed four-bar stays on its branch."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from conftest import (
    G,
    crossed_branch_point,
    crossed_initial_state,
    joint_C,
    make_crossed_four_bar,
    make_pendulum,
)
from nonmin.core import impact_map
from nonmin.errors import InputError
from nonmin.model import FunctionConstraint, FunctionModel
from nonmin.sim import Baumgarte, Projection, simulate

PHI_TOL = 1e-10


def test_projection_keeps_constraint_residuals_at_round_off() -> None:
    tr = simulate(make_pendulum(), (0.0, 2.0), [1.0, 0.0], dt=0.01)
    assert tr.phi_norm.max() <= PHI_TOL
    assert tr.velocity_residual_norm.max() <= PHI_TOL
    # without stabilization the same run drifts visibly
    tr0 = simulate(make_pendulum(), (0.0, 2.0), [1.0, 0.0], dt=0.01, stabilization="none")
    assert tr0.phi_norm.max() > 100 * PHI_TOL


def test_projection_corrects_an_inconsistent_initial_state() -> None:
    tr = simulate(make_pendulum(), (0.0, 0.1), [1.01, 0.02], [0.3, 0.5], dt=0.01)
    assert tr.phi_norm[0] <= 1e-12
    assert tr.velocity_residual_norm[0] <= 1e-12


def test_baumgarte_reduces_drift_compared_with_none() -> None:
    kw = {"dt": 0.01, "t_eval": np.linspace(0, 3, 31)}
    none = simulate(make_pendulum(), (0.0, 3.0), [1.0, 0.0], stabilization="none", **kw)
    bg = simulate(make_pendulum(), (0.0, 3.0), [1.0, 0.0], stabilization=Baumgarte(5.0, 5.0), **kw)
    assert bg.phi_norm.max() < none.phi_norm.max()


def _branch_error(q: np.ndarray) -> np.ndarray:
    C = joint_C(q)
    Cb = np.array([crossed_branch_point(a) for a in q[:, 0]])
    return np.linalg.norm(C - Cb, axis=1)


def _change_points(q: np.ndarray) -> int:
    """Crossings of the collinear configurations θ1 ≡ 0 (mod π)."""
    k = np.floor(np.unwrap(q[:, 0]) / np.pi)
    return int(np.count_nonzero(np.diff(k)))


def test_crossed_four_bar_stays_on_its_branch_through_change_points() -> None:
    model = make_crossed_four_bar()
    q0, qd0 = crossed_initial_state(rate=5.0)
    tr = simulate(model, (0.0, 1.5), q0, qd0, dt=1e-3, t_eval=np.linspace(0.0, 1.5, 301))
    assert tr.success
    assert _change_points(tr.q) >= 2  # θ1 = π and 2π
    assert _branch_error(tr.q).max() < 1e-8
    assert tr.phi_norm.max() <= PHI_TOL
    assert tr.energy_drift < 1e-5
    assert tr.rank.min() == 2  # the change points are passed without stopping at them


def test_euclidean_projection_drifts_more_in_energy_than_mass_metric() -> None:
    model = make_crossed_four_bar()
    q0, qd0 = crossed_initial_state(rate=5.0)
    kw = {"dt": 2e-3, "t_eval": np.linspace(0.0, 1.0, 11)}
    mass = simulate(model, (0.0, 1.0), q0, qd0, **kw)
    eucl = simulate(model, (0.0, 1.0), q0, qd0, stabilization=Projection(metric="euclidean"), **kw)
    assert 10 * mass.energy_drift < eucl.energy_drift


def test_crossed_four_bar_library_model_matches_reference() -> None:
    library = pytest.importorskip("nonmin.library")
    mech = library.get("crossed_four_bar")
    t_eval = np.linspace(0.0, 0.7, 8)  # through the first change point (θ = π at t ≈ 0.21 s)
    tr = simulate(mech, (0.0, 0.7), dt=1e-3, t_eval=t_eval)
    ref = library.crossed_four_bar_reference(t_eval)
    assert np.max(np.abs(tr.q - ref["q"])) < 1e-6
    assert tr.phi_norm.max() <= PHI_TOL


def test_stabilization_objects_validate() -> None:
    with pytest.raises(InputError, match="metric"):
        Projection(metric="manhattan")
    with pytest.raises(InputError, match="alpha"):
        Baumgarte(alpha=-1.0)


@given(
    th1=st.floats(0.2, 2.9),
    scale=st.floats(1e-6, 1e-2),
    seed=st.integers(0, 2**31 - 1),
)
def test_projection_is_the_mass_metric_projection(th1: float, scale: float, seed: int) -> None:
    """Velocity step == core.impact_map (plastic); position step lands on φ = 0 at round-off."""
    model = make_crossed_four_bar()
    q0, qd0 = crossed_initial_state(th1=th1, rate=2.0)
    rng = np.random.default_rng(seed)
    q = q0 + scale * rng.standard_normal(3)
    qd = qd0 + scale * rng.standard_normal(3)
    act = model.default_active
    q1, qd1 = Projection().project(model, 0.0, q, qd, act, None)
    ct = model.constraint_terms(0.0, q1, qd1, act)
    assert np.max(np.abs(ct.phi)) < 1e-13
    assert np.max(np.abs(ct.velocity)) < 1e-12
    expected = impact_map(model.mass_matrix(q), ct.A, qd)
    assert np.allclose(qd1, expected, rtol=1e-9, atol=1e-12)


def test_rheonomic_constraint_is_followed_and_projected() -> None:
    """x(t) = sin t imposed by a driving constraint; y falls freely."""
    drive = FunctionConstraint.rheonomic(
        "drive",
        phi=lambda t, q: [q[0] - np.sin(t)],
        jacobian=lambda t, q: [[1.0, 0.0]],
        phi_t=lambda t, q: [-np.cos(t)],
        gamma=lambda t, q, qd: [np.sin(t)],  # A qdd + γ = 0  ⇔  ẍ = −sin t
    )
    model = FunctionModel(
        name="driven", coordinate_names=("x", "y"), mass=lambda q: np.eye(2),
        coriolis=lambda q, qd: np.zeros((2, 2)), conservative=lambda q: [0.0, -G],
        potential=lambda q: G * q[1], constraints=(drive,),
    )
    tr = simulate(model, (0.0, 2.0), [0.0, 0.0], [0.5, 0.0], dt=0.01)  # qd0 inconsistent: projected
    assert np.allclose(tr.q[:, 0], np.sin(tr.t), atol=1e-12)
    assert np.allclose(tr.qd[:, 0], np.cos(tr.t), atol=1e-12)
    assert np.allclose(tr.q[:, 1], -0.5 * G * tr.t**2, atol=1e-9)
    assert tr.velocity_residual_norm.max() < 1e-12


def test_nonholonomic_knife_edge_drives_a_circle() -> None:
    """Knife edge (x, y, θ): no side slip; heading rate ω and speed v give a circle of radius v/ω."""
    skate = FunctionConstraint.nonholonomic(
        "no_slip",
        matrix=lambda q: [[-np.sin(q[2]), np.cos(q[2]), 0.0]],
        adot_qd=lambda q, qd: [-qd[2] * (np.cos(q[2]) * qd[0] + np.sin(q[2]) * qd[1])],
    )
    model = FunctionModel(
        name="knife", coordinate_names=("x", "y", "th"), mass=lambda q: np.diag([1.0, 1.0, 0.1]),
        coriolis=lambda q, qd: np.zeros((3, 3)), conservative=lambda q: np.zeros(3),
        potential=lambda q: 0.0, constraints=(skate,),
    )
    v, w = 2.0, 1.0
    tr = simulate(model, (0.0, 3.0), [0.0, 0.0, 0.0], [v, 0.0, w], dt=0.01)
    centre = np.array([0.0, v / w])
    assert np.allclose(np.linalg.norm(tr.q[:, :2] - centre, axis=1), v / w, atol=1e-8)
    assert tr.velocity_residual_norm.max() < 1e-12
    assert tr.energy_drift < 1e-10
    assert np.all(tr.phi_norm == 0.0)  # no position-level rows


def _a02_state_on_the_mode(n: int, t: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact A02 state at time t (parallelogram mode, 1-DOF reduction): cranks then couplers."""
    from nonmin.validation._references import a02_parallelogram_reference

    th_all, om_all = a02_parallelogram_reference(n, np.array([0.0, t]))
    th, om = float(th_all[-1]), float(om_all[-1])
    c, s = np.cos(th), np.sin(th)
    q = np.zeros(3 * (2 * n + 1))
    qd = np.zeros_like(q)
    for i in range(n + 1):
        q[3 * i:3 * i + 3] = [i + 0.5 * c, 0.5 * s, th]
        qd[3 * i:3 * i + 3] = [-0.5 * om * s, 0.5 * om * c, om]
    for j in range(1, n + 1):
        b = 3 * (n + j)
        q[b:b + 3] = [j - 0.5 + c, s, 0.0]
        qd[b:b + 3] = [-om * s, om * c, 0.0]
    return q, qd


@pytest.mark.parametrize("engine", ["python", "engine"])
@pytest.mark.parametrize(("dt", "gap", "e_tol"), [(2e-3, 1e-6, 1e-4), (2e-3, -1e-6, 1e-4),
                                                   (1e-3, 1e-6, 1e-7)])  # fmt: skip
def test_step_ending_next_to_a_singular_configuration_keeps_the_energy(
    engine: str, dt: float, gap: float, e_tol: float
) -> None:
    # A02 (N = 2): at the horizontal configurations the rank of A drops 14 -> 12. An RK4 step
    # that ends 1e-6 s from one sees two singular values ~1e-6 relative, and the components of
    # φ along them are round-off. A full-rank Gauss–Newton projection divided that noise by
    # them, moved q along the branch-switching directions, tilted the projected velocity and
    # kicked the energy in the next step (measured: 7.7e-3 / 7.0e-3 / 4.6e-4 J for the three
    # cases; 3.3e3 J and then NaN at 1e-7 s, dt = 2e-3). With the cutoff of the first
    # Gauss–Newton steps (POSITION_CUT_RTOL): 4.0e-6 / 4.0e-6 / 7.7e-10 J.
    from nonmin.library import get
    from nonmin.validation._suite import _a02_horizontal_times

    n = 2
    mech = get("A02_n_four_bar", N=n)
    t_c = float(_a02_horizontal_times(n, 1.0)[0])
    t0 = t_c + gap - 3 * dt  # the third step ends `gap` after the horizontal configuration
    q0, qd0 = _a02_state_on_the_mode(n, t0)
    tr = simulate(mech, (t0, t0 + 6 * dt), q0, qd0, method="rk4", dt=dt,
                  stabilization="projection", progress=False, engine=engine)  # fmt: skip
    assert tr.success
    assert tr.metadata["engine"] == engine
    e = np.asarray(tr.energy)
    assert np.max(np.abs(e - e[0])) <= e_tol
    q = np.asarray(tr.q)
    cranks = q[:, [3 * i + 2 for i in range(n + 1)]]
    couplers = q[:, [3 * (n + 1 + i) + 2 for i in range(n)]]
    assert np.max(np.abs(cranks - cranks[:, :1])) <= 1e-9  # still in the parallelogram mode
    assert np.max(np.abs(couplers)) <= 1e-9


@pytest.mark.parametrize("size", [1e-8, 1e-6, 1e-4])
def test_simplified_steps_land_where_gauss_newton_does(size: float) -> None:
    """The projection's chord steps (A of the last linearization) converge to the point full
    Gauss–Newton reaches, to round-off, from the perturbations a step leaves."""
    from nonmin import library
    from nonmin.core import position_correction

    mech = library.get("crossed_four_bar")
    model, act = mech.model, frozenset(mech.model.constraint_names)
    rng = np.random.default_rng(11)
    for _ in range(5):
        q0 = mech.state.q + size * rng.standard_normal(mech.model.n)
        qd0 = mech.state.qd.copy()
        q, _qd = Projection().project(model, 0.0, q0.copy(), qd0, act, None)
        ref = q0.copy()
        M = model.mass_matrix(q0)
        for _it in range(20):  # full Gauss–Newton, A taken afresh at every step
            ct = model.constraint_terms(0.0, ref, qd0, act)
            if np.max(np.abs(ct.phi)) < 1e-15:
                break
            ref = ref + position_correction(M, ct.A, ct.phi)
        assert np.max(np.abs(model.constraint_terms(0.0, q, qd0, act).phi)) < 1e-14
        assert np.max(np.abs(q - ref)) < 1e-12 + 1e-3 * size**2, (size, np.max(np.abs(q - ref)))


def _projection_cutoffs(
    monkeypatch: pytest.MonkeyPatch, t: float, size: float, seed: int = 3
) -> tuple[list[float | None], float, float]:
    """Rank tolerances of the position steps of one projection of the A02 (N = 2) exact state
    at ``t`` perturbed by ``size``, and the residuals ‖φ‖∞, ‖A qd‖∞ it leaves."""
    from nonmin.library import get
    from nonmin.sim import _stabilization as stab_mod

    n = 2
    mech = get("A02_n_four_bar", N=n)
    q, qd = _a02_state_on_the_mode(n, t)
    rng = np.random.default_rng(seed)
    q = q + size * rng.standard_normal(q.shape[0])
    calls: list[float | None] = []
    orig = stab_mod._correction

    def spy(
        M: np.ndarray, A: np.ndarray, r: np.ndarray, rtol: float | None, ranks: list[int] | None = None
    ) -> np.ndarray:
        calls.append(rtol)
        return orig(M, A, r, rtol, ranks)

    monkeypatch.setattr(stab_mod, "_correction", spy)
    active = frozenset(mech.state.active)
    q1, qd1 = stab_mod.Projection().project(mech.model, t, q, qd, active, None)
    ct = mech.model.constraint_terms(t, q1, qd1, active)
    return calls[:-1], float(np.max(np.abs(ct.phi))), float(np.max(np.abs(ct.A @ qd1)))


def test_a_real_residual_at_a_regular_configuration_takes_the_full_rank(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # A02 (N = 2) at t = 0.71 s: σ_min/σ_max of the equilibrated A ~ 4e-3, between
    # SINGULAR_CUT_RTOL and POSITION_CUT_RTOL. An error of 1e-8 is a real residual (≫ its
    # round-off floor), partly along that direction: the first Gauss–Newton step keeps every
    # direction (it used to cut it, stall in the chord step and linearize again at the full
    # rank), and the chord steps converge on that one linearization.
    from nonmin.sim import _stabilization as stab_mod

    pos, phi, vel = _projection_cutoffs(monkeypatch, 0.71, 1e-8)
    assert pos and all(c == stab_mod.SINGULAR_CUT_RTOL for c in pos), pos
    assert len(pos) <= 3
    assert phi < 1e-14 and vel < 1e-12


def test_a_roundoff_residual_at_a_regular_configuration_takes_the_full_rank(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # The same state with an error of 1e-15 (a residual at its round-off floor): the first step
    # keeps the direction of σ_min/σ_max ~ 4e-3 too. Before, a round-off residual was cut at
    # POSITION_CUT_RTOL = 1e-2, which on A02 N = 40 (σ_min/σ_max ≤ 0.024 everywhere) failed the
    # certified LQ and cost a 242 × 243 SVD per projection; next to a singular configuration
    # (σ below SINGULAR_CUT_RTOL) the cut stays (the next test).
    from nonmin.sim import _stabilization as stab_mod

    pos, phi, vel = _projection_cutoffs(monkeypatch, 0.71, 1e-15)
    assert pos == [stab_mod.SINGULAR_CUT_RTOL], pos
    assert phi < 1e-14 and vel < 1e-12


def test_a_real_residual_next_to_a_singular_configuration_keeps_the_cut(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # 1e-6 s after a horizontal configuration two singular values are ~1e-6 relative (below
    # SINGULAR_CUT_RTOL): even with a real residual the first step cuts them; they are left
    # to the later steps only if the cut steps stall (then at the full rank).
    from nonmin.sim import _stabilization as stab_mod
    from nonmin.validation._suite import _a02_horizontal_times

    t_c = float(_a02_horizontal_times(2, 1.0)[0])
    pos, phi, vel = _projection_cutoffs(monkeypatch, t_c + 1e-6, 1e-8)
    # the step at SINGULAR_CUT_RTOL is taken and dropped (it was not of full rank), then the cut
    assert pos[:2] == [stab_mod.SINGULAR_CUT_RTOL, stab_mod.POSITION_CUT_RTOL], pos
    assert phi < 1e-14 and vel < 1e-12
