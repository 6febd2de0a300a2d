"""The batch's lock-step lanes (engine/src/lanes.hpp): every run bitwise equal to simulate() and
to the scalar batch (NONMIN_LANES=0), also when the lanes' decisions differ (a run's kernel call
then made alone) and when calls are forced out of the lanes (NONMIN_LANES_SCALAR_EVERY)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from nonmin import library
from nonmin.library._planar import _cfb_coordinates
from nonmin.sim import _engine, simulate, simulate_batch

KEYS = ("t", "q", "qd", "qdd", "f_c", "energy", "phi_norm", "rank", "cond", "mu")


def _stats() -> dict:
    return dict(_engine._engine().lanes_stats())


def _cfb_states(k: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    th = rng.uniform(0.0, 2 * math.pi, k)
    om = rng.uniform(5.0, 9.0, k) * rng.choice([-1.0, 1.0], k)
    return _cfb_coordinates(th, om)


def _batch(model, t1, Q, V, t_eval, monkeypatch, **env):
    for key in ("NONMIN_LANES", "NONMIN_LANES_SCALAR_EVERY"):
        monkeypatch.delenv(key, raising=False)
    for key, value in env.items():
        monkeypatch.setenv(key, value)
    bt = simulate_batch(model, t1, Q, V, dt=1e-3, t_eval=t_eval, record=("q", "qd", "qdd", "f_c"), threads=1)
    for key in env:
        monkeypatch.delenv(key)
    return bt


def _same(a, b, i, j=None):
    j = i if j is None else j
    for key in KEYS:
        np.testing.assert_array_equal(getattr(a[i], key), getattr(b[j], key), err_msg=key)
    assert (a[i].n_steps, a[i].n_rhs) == (b[j].n_steps, b[j].n_rhs)


@pytest.fixture(scope="module")
def bar():
    return library.get("crossed_four_bar")


def test_lanes_equal_scalar_batch_and_simulate_crossed_four_bar(bar, monkeypatch):
    # 11 runs (not a multiple of the width: the last group has spare lanes), 0.6 s at dt 1e-3,
    # through the passages of the branch (certificates the bound does not prove: those calls
    # leave the lanes)
    Q, V = _cfb_states(11, seed=2026)
    t = np.linspace(0.0, 0.6, 61)
    before = _stats()
    lanes = _batch(bar.model, 0.6, Q, V, t, monkeypatch)
    after = _stats()
    scalar = _batch(bar.model, 0.6, Q, V, t, monkeypatch, NONMIN_LANES="0")
    assert _stats() == after  # the scalar batch used no lane
    if after["available"]:
        assert after["lane_calls"] - before["lane_calls"] > 1000
        assert after["lane_groups"] > before["lane_groups"]
    for i in range(11):
        _same(lanes, scalar, i)
    for i in (0, 5, 10):
        ref = simulate(bar.model, 0.6, Q[i], V[i], dt=1e-3, t_eval=t)
        assert ref.metadata["engine"] == "engine"
        for key in KEYS:
            np.testing.assert_array_equal(getattr(lanes[i], key), getattr(ref, key), err_msg=key)


def test_calls_forced_out_of_the_lanes_mid_run(bar, monkeypatch):
    Q, V = _cfb_states(8, seed=5)
    t = np.linspace(0.0, 0.3, 31)
    scalar = _batch(bar.model, 0.3, Q, V, t, monkeypatch, NONMIN_LANES="0")
    for every in ("2", "3", "7"):
        before = _stats()
        mixed = _batch(bar.model, 0.3, Q, V, t, monkeypatch, NONMIN_LANES_SCALAR_EVERY=every)
        after = _stats()
        if after["available"]:  # some calls in lanes, others alone
            assert after["lane_calls"] > before["lane_calls"]
            assert after["scalar_calls"] > before["scalar_calls"]
        for i in range(8):
            _same(mixed, scalar, i)


def test_sse2_lanes_equal_the_scalar_batch(bar, monkeypatch):
    # NONMIN_LANES=2: two lanes per call (the build's SSE2 form, used where AVX2 is missing)
    Q, V = _cfb_states(7, seed=9)
    t = np.linspace(0.0, 0.3, 31)
    before = _stats()
    two = _batch(bar.model, 0.3, Q, V, t, monkeypatch, NONMIN_LANES="2")
    after = _stats()
    if after["available"]:
        assert after["lane_calls"] > before["lane_calls"]
    scalar = _batch(bar.model, 0.3, Q, V, t, monkeypatch, NONMIN_LANES="0")
    for i in range(7):
        _same(two, scalar, i)


@pytest.mark.filterwarnings("ignore::RuntimeWarning")  # (the failed run, made again by simulate())
def test_a_failed_run_among_lanes_leaves_its_neighbours_unchanged(bar, monkeypatch):
    Q, V = _cfb_states(6, seed=3)
    V[2] *= 1e300  # fails at once (non-finite), through simulate(), the others run on in lanes
    t = np.linspace(0.0, 0.2, 21)
    lanes = _batch(bar.model, 0.2, Q, V, t, monkeypatch)
    scalar = _batch(bar.model, 0.2, Q, V, t, monkeypatch, NONMIN_LANES="0")
    assert lanes[2].status == scalar[2].status and lanes[2].status.name != "SUCCESS"
    for i in (0, 1, 3, 4, 5):
        _same(lanes, scalar, i)


def test_lanes_equal_simulate_slider_crank(monkeypatch):
    mechs = [library.get("slider_crank", theta0=th, omega0=om)
             for th, om in [(0.3, 5.0), (1.1, -4.0), (2.0, 7.5), (2.9, 3.0), (4.0, -6.0), (5.5, 2.5)]]  # fmt: skip
    model = mechs[0].model
    Q = np.stack([m.state.q for m in mechs])
    V = np.stack([m.state.qd for m in mechs])
    t = np.linspace(0.0, 0.5, 51)
    before = _stats()
    lanes = _batch(model, 0.5, Q, V, t, monkeypatch)
    after = _stats()
    if after["available"]:
        assert after["lane_calls"] > before["lane_calls"]
    scalar = _batch(model, 0.5, Q, V, t, monkeypatch, NONMIN_LANES="0")
    for i in range(6):
        _same(lanes, scalar, i)
        ref = simulate(model, 0.5, Q[i], V[i], dt=1e-3, t_eval=t)
        for key in KEYS:
            np.testing.assert_array_equal(getattr(lanes[i], key), getattr(ref, key), err_msg=key)


def test_sweep_path_uses_the_lanes(tmp_path, monkeypatch):
    pytest.importorskip("xarray")
    pytest.importorskip("zarr")
    from nonmin import sweep

    p = tmp_path / "cfb.toml"
    p.write_text('name = "cfb"\n[model]\nlibrary = "crossed_four_bar"\n[simulate]\nt_final = 0.1\n'
                 'method = "rk4"\ndt = 1e-3\noutput_dt = 0.01\n', encoding="utf-8")  # fmt: skip
    monkeypatch.delenv("NONMIN_LANES", raising=False)
    before = _stats()
    res = sweep(p, {"model.params.omega0": [6.5, 7.0, 7.5, 8.0, 8.5]}, workers=1, progress=False)
    after = _stats()
    if after["available"]:
        assert after["lane_calls"] > before["lane_calls"]
    ref = simulate(library.get("crossed_four_bar", omega0=8.0), 0.1, dt=1e-3, t_eval=np.linspace(0, 0.1, 11))
    np.testing.assert_array_equal(res.dataset["q"].values[3], ref.q)
