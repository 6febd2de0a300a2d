"""simulate_batch: k runs in the engine at once, each equal to simulate() of that run."""

from __future__ import annotations

import math

import numpy as np
import pytest

from nonmin import library
from nonmin.errors import InputError, NonFiniteError, ShapeError
from nonmin.library._planar import _cfb_coordinates
from nonmin.sim import BatchTrajectory, Status, Trajectory, simulate, simulate_batch


def _states(k: int, seed: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """k consistent states of the crossed four-bar on its anti-parallelogram branch."""
    rng = np.random.default_rng(seed)
    th = rng.uniform(0.0, 2 * math.pi, k)
    om = rng.uniform(6.0, 9.0, k) * rng.choice([-1.0, 1.0], k)
    return _cfb_coordinates(th, om)


@pytest.fixture(scope="module")
def bar():
    return library.get("crossed_four_bar")


T_EVAL = np.linspace(0.0, 0.3, 31)


def test_each_run_equals_simulate_bitwise(bar):
    Q, V = _states(5)
    bt = simulate_batch(bar.model, 0.3, Q, V, dt=1e-3, t_eval=T_EVAL, record=("q", "qd", "qdd", "f_c"))
    assert isinstance(bt, BatchTrajectory) and len(bt) == 5
    assert bt.q.shape == (5, 31, 9) and bt.energy.shape == (5, 31)
    assert bt.engine == ("batch",) * 5
    for i in range(5):
        ref = simulate(bar.model, 0.3, Q[i], V[i], dt=1e-3, t_eval=T_EVAL)
        assert ref.metadata["engine"] == "engine"
        tr = bt[i]
        assert isinstance(tr, Trajectory) and tr.status is Status.SUCCESS
        for key in ("t", "q", "qd", "qdd", "f_c", "energy", "phi_norm", "rank", "cond", "mu"):
            np.testing.assert_array_equal(getattr(tr, key), getattr(ref, key), err_msg=key)
        assert (tr.n_steps, tr.n_rhs) == (ref.n_steps, ref.n_rhs)
        np.testing.assert_array_equal(bt.q[i], ref.q)


def test_threads_do_not_change_results(bar):
    Q, V = _states(9, seed=2)
    one = simulate_batch(bar.model, 0.2, Q, V, t_eval=T_EVAL[:21], threads=1)
    two = simulate_batch(bar.model, 0.2, Q, V, t_eval=T_EVAL[:21], threads=2)
    np.testing.assert_array_equal(one.q, two.q)
    np.testing.assert_array_equal(one.energy, two.energy)
    np.testing.assert_array_equal(one.n_steps, two.n_steps)


def test_stays_on_branch_and_matches_the_exact_reference(bar):
    # the 1-DOF reduction along the branch (independent reference), from the library's state
    t = np.linspace(0.0, 1.0, 11)
    ref = library.crossed_four_bar_reference(t)
    st = bar.state
    bt = simulate_batch(bar.model, 1.0, np.stack([st.q, st.q]), np.stack([st.qd, st.qd]), t_eval=t)
    assert np.max(np.abs(bt.q[:, :, 2] - ref["theta"])) < 1e-5
    assert np.all(bt.closure < 1e-12)


# Two of sweep_bench.py's 1000 random runs (seed 2026) that left the anti-parallelogram branch
# at dt = 1e-3 through a change point (run 828 at t ≈ 0.58 s; run 882 failed at t ≈ 0.89 s with
# a non-finite Ȧq̇), on both drivers, until RK4 took its passage steps at its order (3b46bcf,
# 79eabe6: projected stages next to a passage, a passage step at least PASSAGE_SIGMA wide).
BRANCH_LEAVERS = [(5.5718870706804555, -6.483511434888186), (5.416978601798854, -7.4216265699471204)]


def test_change_point_runs_stay_on_their_branch(bar):
    th0 = np.array([s[0] for s in BRANCH_LEAVERS])
    om0 = np.array([s[1] for s in BRANCH_LEAVERS])
    Q, V = _cfb_coordinates(th0, om0)
    t = np.linspace(0.0, 2.0, 201)
    bt = simulate_batch(bar.model, 2.0, Q, V, dt=1e-3, t_eval=t)
    assert bt.engine == ("batch", "batch") and all(s is Status.SUCCESS for s in bt.status)
    for i, (th, om) in enumerate(BRANCH_LEAVERS):
        ref = library.crossed_four_bar_reference(t, theta0=th, omega0=om)
        # every coordinate on the exact reduction along the branch (measured 9.2e-9 m/rad)
        assert np.max(np.abs(bt.q[i] - ref["q"])) < 1e-6
        one = simulate(bar.model, 2.0, Q[i], V[i], dt=1e-3, t_eval=t)
        np.testing.assert_array_equal(bt.q[i], one.q)


@pytest.mark.slow
def test_change_point_runs_stay_on_their_branch_python_driver(bar):
    t = np.linspace(0.0, 2.0, 201)
    for th, om in BRANCH_LEAVERS:
        Q, V = _cfb_coordinates(np.array([th]), np.array([om]))
        tr = simulate(bar.model, 2.0, Q[0], V[0], dt=1e-3, t_eval=t, engine="python")
        ref = library.crossed_four_bar_reference(t, theta0=th, omega0=om)
        assert np.max(np.abs(tr.q - ref["q"])) < 1e-6


def test_params_vary_the_model_without_rebuilding_by_hand(bar):
    Q, V = _states(3, seed=3)
    grav = [(0.0, -9.81), (0.0, -1.62), (0.0, -9.81)]
    bt = simulate_batch(bar.model, 0.2, Q, V, params={"gravity": grav}, t_eval=T_EVAL[:21])
    for i, g in enumerate(grav):
        ref = simulate(bar.model.replace(gravity=g), 0.2, Q[i], V[i], t_eval=T_EVAL[:21])
        np.testing.assert_array_equal(bt.q[i], ref.q)
    assert not np.array_equal(bt.q[0], bt.q[1])


def test_shared_rows_broadcast_and_slicing(bar):
    st = bar.state
    bt = simulate_batch(bar, 0.1, np.stack([st.q] * 4), t_eval=np.linspace(0, 0.1, 6))  # qd0: the mechanism's
    assert len(bt) == 4
    sub = bt[1:3]
    assert isinstance(sub, BatchTrajectory) and len(sub) == 2
    np.testing.assert_array_equal(sub.q, bt.q[1:3])
    assert [tr.status for tr in bt] == [Status.SUCCESS] * 4
    assert bt[-1].t.shape == (6,)
    with pytest.raises(IndexError):
        bt[4]


def test_default_grid_is_every_fixed_step(bar):
    st = bar.state
    bt = simulate_batch(bar, 0.01, st.q, st.qd, dt=1e-3)
    ref = simulate(bar, 0.01, dt=1e-3)
    np.testing.assert_allclose(bt.t, ref.t, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(bt.q[0], ref.q)


def test_a_failed_run_keeps_its_status_and_does_not_stop_the_batch(bar):
    Q, V = _states(3, seed=4)
    V[1] *= 1e160  # the velocity-squared terms overflow: the engine hands over, simulate fails
    with np.errstate(all="ignore"):
        bt = simulate_batch(bar.model, 0.2, Q, V, t_eval=T_EVAL[:21])
        ref = simulate(bar.model, 0.2, Q[1], V[1], t_eval=T_EVAL[:21], throw=False)
    assert ref.status is Status.FAILED
    assert bt.status == (Status.SUCCESS, Status.FAILED, Status.SUCCESS)
    assert bt.message[1] == ref.message and "not finite" in ref.message.replace("must be finite", "not finite")
    assert bt.engine == ("batch", "batch, then simulate", "batch")
    assert len(bt[1]) == len(ref)
    assert np.isnan(bt.q[1, -1]).all()  # not reached
    assert not np.isnan(bt.q[[0, 2]]).any()


def test_step_budget_is_checked_before_the_runs(bar):
    Q, V = _states(2, seed=4)
    with pytest.raises(InputError, match="max_steps"):
        simulate_batch(bar.model, 0.2, Q, V, t_eval=T_EVAL[:21], max_steps=50)


def test_runs_with_contact_are_batched_and_engine_python_goes_through_simulate():
    # (contact with impacts and releases: tests/sweep/test_batch_events.py)
    arm = library.get("arm2r_wall")
    st = arm.state
    t = np.linspace(0, 0.3, 7)
    bt = simulate_batch(arm, 0.3, np.stack([st.q, st.q]), np.stack([st.qd, st.qd + 0.5]), t_eval=t)
    assert bt.engine == ("batch", "batch")
    ref = simulate(arm, 0.3, st.q, st.qd + 0.5, t_eval=t)
    np.testing.assert_allclose(bt[1].q, ref.q, rtol=0, atol=1e-12)
    py = simulate_batch(arm, 0.3, np.stack([st.q, st.q]), np.stack([st.qd, st.qd + 0.5]), t_eval=t, engine="python")
    assert py.engine == ("simulate", "simulate")
    np.testing.assert_array_equal(py[1].q, simulate(arm, 0.3, st.q, st.qd + 0.5, t_eval=t, engine="python").q)


def test_bad_arguments_are_typed_errors(bar):
    st = bar.state
    with pytest.raises(ShapeError, match="q0"):
        simulate_batch(bar, 0.1, np.zeros((3, 8)))
    with pytest.raises(ShapeError, match="run counts"):
        simulate_batch(bar, 0.1, np.stack([st.q] * 3), np.stack([st.qd] * 2))
    with pytest.raises(NonFiniteError, match="run 1"):
        simulate_batch(bar, 0.1, np.stack([st.q, st.q * np.nan]))
    with pytest.raises(InputError, match="adaptive"):
        simulate_batch(bar, 0.1, st.q, method="dopri5")
    with pytest.raises(InputError, match="throw"):
        simulate_batch(bar, 0.1, st.q, throw=False)
    with pytest.raises(InputError, match="record"):
        simulate_batch(bar, 0.1, st.q, record=("q", "lambda"))
    with pytest.raises(InputError, match="threads"):
        simulate_batch(bar, 0.1, st.q, threads=0)
    # complex and text initial states ran (NumPy's casts: a ComplexWarning, or parsed strings)
    with pytest.raises(InputError, match="q0 must be real numbers, got complex"):
        simulate_batch(bar, 0.1, np.stack([st.q] * 2) + 1j)
    with pytest.raises(ShapeError, match="qd0 must be an array of shape"):
        simulate_batch(bar, 0.1, st.q, st.qd.astype(str))


def test_adaptive_runs_with_t_eval_match_simulate(bar):
    Q, V = _states(2, seed=5)
    t = np.linspace(0, 0.2, 5)
    bt = simulate_batch(bar.model, 0.2, Q, V, method="dopri5", rtol=1e-8, t_eval=t)
    for i in range(2):
        ref = simulate(bar.model, 0.2, Q[i], V[i], method="dopri5", rtol=1e-8, t_eval=t)
        np.testing.assert_array_equal(bt.q[i], ref.q)
        assert bt.n_steps[i] == ref.n_steps


def test_option_values_as_for_simulate(bar):
    from nonmin.sim import Output, Solver

    Q, V = _states(2, seed=6)
    t = np.linspace(0, 0.1, 6)
    bt = simulate_batch(bar.model, 0.1, Q, V, solver=Solver("rk4", dt=5e-4), output=Output(t_eval=t))
    ref = simulate(bar.model, 0.1, Q[1], V[1], solver=Solver("rk4", dt=5e-4), output=Output(t_eval=t))
    np.testing.assert_array_equal(bt.q[1], ref.q)
    assert bt.n_steps[1] == ref.n_steps == 200
    with pytest.raises(InputError, match="output"):
        simulate_batch(bar.model, 0.1, Q, V, output=Output(t_eval=t, throw=False))
    with pytest.raises(InputError, match="unknown keyword"):
        simulate_batch(bar.model, 0.1, Q, V, t_eval=t, nonsense=1)
