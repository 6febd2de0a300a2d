"""A04 Bricard (spatial source): exactly one redundant constraint along the motion, handled by
nonmin with no special treatment; cross-checked against a least-squares KKT solve."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from nonmin.core import range_basis, solve_dynamics
from nonmin.library.bricard import NAME, bricard_model, bricard_state

#: Constraint and energy drift allowed in a 0.6 s solve_ivp run at rtol 1e-10 (no stabilization).
DRIFT_TOL = 1e-9

#: Rank tolerance for the *integration* (not for the on-manifold rank checks, which use the
#: default 1e-10). Off the constraint manifold, at the stages of an explicit Runge–Kutta step,
#: the redundant row is no longer exactly dependent: its singular value is of the order of the
#: stage's distance from the manifold (1e-9 .. 1e-6 relative). With the default cutoff the rank
#: then flips to m and qdd jumps (DOP853 blows up; RK45 needs 23k evaluations for 0.6 s); a
#: cutoff above that drift noise (ERRATA, "rank tolerance") gives 98 evaluations.
INTEGRATION_RTOL = 1e-6


def _rhs(model):
    def f(t, y):
        n = model.n
        ev = model.evaluate(t, y[:n], y[n:])
        c = ev.constraints
        qdd = solve_dynamics(ev.M, ev.h, c.A, c.gamma, rtol=INTEGRATION_RTOL).qdd
        return np.concatenate((y[n:], qdd))

    return f


@pytest.fixture(scope="module")
def motion():
    model = bricard_model()
    s = bricard_state(model)
    ts = np.linspace(0.0, 0.6, 7)
    sol = solve_ivp(
        _rhs(model),
        (0.0, ts[-1]),
        np.concatenate((s.q, s.qd)),
        method="DOP853",
        t_eval=ts,
        rtol=1e-10,
        atol=1e-12,
    )
    assert sol.success
    return model, sol


def test_sizes_and_initial_state() -> None:
    model = bricard_model()
    s = bricard_state(model)
    assert model.name == NAME
    assert model.n == 35 and model.num_rows() == 35
    ct = model.constraint_terms(0.0, s.q, s.qd)
    np.testing.assert_allclose(ct.phi, 0.0, atol=1e-15)
    np.testing.assert_allclose(model.outputs(0.0, s.q, s.qd)["P3.position"], [1.0, -1.0, 0.0], atol=1e-15)


def test_exactly_one_redundant_constraint_along_the_motion(motion) -> None:
    model, sol = motion
    n = model.n
    m = model.num_rows()
    p3 = []
    for y in sol.y.T:
        q, qd = y[:n], y[n:]
        A = model.constraint_jacobian(0.0, q)
        sv = np.linalg.svd(A, compute_uv=False)
        # one singular value at round-off level, the next one far from it
        assert sv[-1] < 1e-12 * sv[0]
        assert sv[-2] > 1e-2 * sv[0]
        assert int(range_basis(A).rank) == m - 1
        p3.append(model.outputs(0.0, q, qd)["P3.position"])
    # it really moves (mobility 1), converting potential into kinetic energy
    assert np.linalg.norm(p3[-1] - p3[0]) > 0.1
    q_end, qd_end = sol.y[:n, -1], sol.y[n:, -1]
    assert model.kinetic_energy(q_end, qd_end) > 0.1


def test_constraints_and_energy_conserved(motion) -> None:
    model, sol = motion
    n = model.n
    e0 = model.energy(sol.y[:n, 0], sol.y[n:, 0])
    for y in sol.y.T:
        ct = model.constraint_terms(0.0, y[:n], y[n:])
        assert np.abs(ct.phi).max() < DRIFT_TOL
        assert np.abs(ct.velocity).max() < DRIFT_TOL
        assert abs(model.energy(y[:n], y[n:]) - e0) < DRIFT_TOL


def test_acceleration_matches_least_squares_kkt(motion) -> None:
    """nonmin's qdd equals the (minimum-norm) KKT solution, whose multipliers are not unique."""
    model, sol = motion
    n = model.n
    for y in sol.y.T[::3]:
        ev = model.evaluate(0.0, y[:n], y[n:])
        A, g = ev.constraints.A, ev.constraints.gamma
        m = A.shape[0]
        K = np.block([[ev.M, A.T], [A, np.zeros((m, m))]])
        x = np.linalg.lstsq(K, np.concatenate((ev.h, -g)), rcond=1e-12)[0]
        res = solve_dynamics(ev.M, ev.h, A, g)
        assert int(res.rank) == m - 1
        np.testing.assert_allclose(res.qdd, x[:n], atol=1e-9)
        np.testing.assert_allclose(A @ res.qdd + g, 0.0, atol=1e-10)


def test_registered_in_library() -> None:
    import nonmin.library as lib
    from nonmin.model import consistent

    mech = lib.get("A04_bricard", t_final=1.0)
    assert mech.name == "A04_bricard" and mech.t_final == 1.0
    assert consistent(mech.model, mech.state)
    assert set(mech.model.outputs(0.0, mech.state.q, mech.state.qd)) == {"P3.position", "P3.velocity"}
    assert "IFToMM" in mech.reference


def _simulate(t_final: float):
    import nonmin.library as lib
    from nonmin.sim import simulate

    mech = lib.get("A04_bricard", t_final=t_final)
    traj = simulate(
        mech, (0.0, t_final), method="dopri5", rtol=1e-9, atol=1e-11, rank_rtol=INTEGRATION_RTOL
    )
    return mech, traj


def test_simulate_short() -> None:
    """nonmin's own simulator (dopri5 + mass-metric projection) with the redundant row in place."""
    mech, traj = _simulate(0.5)
    assert traj.success
    assert np.max(traj.phi_norm) < 1e-10
    assert abs(traj.energy_drift) < 1e-8
    assert int(np.min(traj.rank)) == int(np.max(traj.rank)) == mech.model.num_rows() - 1


@pytest.mark.slow
def test_simulate_full_benchmark_horizon() -> None:
    """The benchmark's 10 s: closure and energy conserved, rank m − 1 throughout."""
    mech, traj = _simulate(10.0)
    assert traj.success
    assert np.max(traj.phi_norm) < 1e-9
    assert abs(traj.energy_drift) < 1e-7
    assert int(np.min(traj.rank)) == int(np.max(traj.rank)) == mech.model.num_rows() - 1
