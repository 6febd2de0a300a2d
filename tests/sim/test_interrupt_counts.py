"""Ctrl-C inside an engine run keeps the run's counts (review of 2026-11-27: a trajectory
interrupted in the engine loop said ``n_steps=0`` and ``n_rhs=0`` beside its hundreds of
samples, so a resumed run counted only its own steps)."""

from __future__ import annotations

import numpy as np
import pytest

from nonmin import library, simulate
from nonmin.sim import Status


@pytest.mark.parametrize("engine", ["engine", "python"])
def test_interrupted_run_counts_its_steps(engine: str) -> None:
    mech = library.get("crossed_four_bar")

    def ctrl(t: float, q: np.ndarray, qd: np.ndarray, state: object, active: object = None) -> np.ndarray:
        if t > 0.25:  # Ctrl-C while the loop runs (raised from the callback the loop makes)
            raise KeyboardInterrupt
        return np.zeros(0)

    tr = simulate(mech, (0, 1.0), method="rk4", dt=1e-3, controller=ctrl, progress=False, t_eval=None,
                  engine=engine)  # fmt: skip
    assert tr.status is Status.INTERRUPTED
    assert tr.metadata["engine"] == engine
    # every sample but the first is a step end; RK4 makes 4 evaluations per step (+ projections)
    assert tr.n_steps == len(tr.t) - 1
    assert tr.n_steps >= 240
    assert tr.n_rhs >= 4 * tr.n_steps
