"""simulate's per-call path (issue 18, target 4): the engine's chunks, the kick check's
shortcut and the typed error of a state past the range of finite arithmetic."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from nonmin import library, simulate
from nonmin.errors import SimulationError
from nonmin.sim import _engine, _simulate

FIELDS = ("t", "q", "qd", "qdd", "f_c", "energy", "cond", "work", "phi_norm", "velocity_residual_norm")


@pytest.mark.parametrize("t_eval", [None, np.linspace(0.0, 0.5, 26)])
@pytest.mark.parametrize("cfg", [{"method": "rk4", "dt": 2e-3}, {"method": "dopri5", "rtol": 1e-6}])
def test_the_first_chunk_does_not_change_the_run(monkeypatch, cfg, t_eval):
    """One chunk (sized from the start's time) or chunks of 16 steps: bitwise the same run."""
    mech = library.get("crossed_four_bar")
    one = simulate(mech, 0.5, t_eval=t_eval, progress=False, **cfg)
    monkeypatch.setattr(_engine, "START_STEP_RATIO", 1e12)  # the first chunk: 16 steps
    assert _engine._first_chunk(1e-6) == 16
    many = simulate(mech, 0.5, t_eval=t_eval, progress=False, **cfg)
    assert one.metadata["engine"] == many.metadata["engine"] == "engine"
    assert (one.n_steps, one.n_rhs, one.n_rejected) == (many.n_steps, many.n_rhs, many.n_rejected)
    for f in FIELDS:
        assert np.array_equal(getattr(one, f), getattr(many, f), equal_nan=True), f


def test_first_chunk_bounds():
    assert _engine._first_chunk(1.0) == 16
    assert _engine._first_chunk(0.0) == 1 << 20
    assert 16 < _engine._first_chunk(2e-5) < 1 << 20


def test_kick_check_shortcut_keeps_the_verdict():
    """A smooth run passes through the shortcut; a velocity jump is still found (the median)."""
    tr = simulate(library.get("crossed_four_bar"), 0.2, method="rk4", dt=1e-3, progress=False)
    assert _simulate._kick_check(tr) is tr
    qd = tr.qd.copy()
    qd[50:] += 40.0 * np.max(np.abs(tr.qdd)) * 1e-3  # a jump of 40 steps' velocity change
    from dataclasses import replace

    with pytest.warns(RuntimeWarning, match="velocity jumped"):
        bad = _simulate._kick_check(replace(tr, qd=qd))
    assert bad.metadata["velocity_kicks"] == [float(tr.t[49])]


@pytest.mark.parametrize("engine", ["auto", "python"])
def test_a_huge_step_ends_in_a_typed_error_without_warnings(engine):
    """Crossed four-bar, RK4 dt 0.3: the state reaches ~1e202–1e292 (after the engine's
    handover with engine="auto"); the run ends with SimulationError, no overflow warning. (dt
    0.14 ended so while every coarse step projected its RK4 stages; since they are projected
    near the singular instants only, that run ends, 2.9 off the branch, 60 J off in energy:
    four steps per change-point period.)"""
    mech = library.get("crossed_four_bar")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(SimulationError, match="range of finite arithmetic"):
            simulate(mech, 10.0, method="rk4", dt=0.3, progress=False, engine=engine)
