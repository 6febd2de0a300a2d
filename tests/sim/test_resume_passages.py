"""A resumed run continues the singular-passage step placement of the run it resumes.

The placement (``SingularPassages``) extrapolates σ_min(A) from the last step ends; a resumed
run that started its history afresh placed its steps differently near a change point, so it
no longer equalled the uninterrupted run (the reliability corpus' "Ctrl-C, then --resume"
case). The history is now seeded from the resumed trajectory's last step ends.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from nonmin import library, simulate
from nonmin.sim import _simulate


def _prefix(tr, k):  # type: ignore[no-untyped-def]
    kw = {}
    for f in dataclasses.fields(tr):
        v = getattr(tr, f.name)
        if isinstance(v, np.ndarray) and v.ndim >= 1 and v.shape[0] == len(tr):
            v = v[:k]
        kw[f.name] = v
    kw["events"] = tuple(e for e in tr.events if e.t <= tr.t[k - 1])
    return type(tr)(**kw)


# the samples after which a fresh history placed the next steps differently (crossed
# four-bar, RK4 dt 1e-2, both drivers; found by cutting at every third sample)
CUTS = (20, 242)


@pytest.mark.parametrize("engine", ["auto", "python"])
def test_resumed_run_is_bitwise_the_uninterrupted_run(engine: str, monkeypatch: pytest.MonkeyPatch) -> None:
    m = library.get("crossed_four_bar")
    full = simulate(m, (0.0, 2.5), dt=1e-2, engine=engine, progress=False)
    for k in CUTS:
        res = simulate(m, (0.0, 2.5), dt=1e-2, engine=engine, resume=_prefix(full, k), progress=False)
        assert len(res) == len(full) and np.array_equal(res.q, full.q) and np.array_equal(res.qd, full.qd)
    # the check of the check: without the history the placement differs at these cuts
    monkeypatch.setattr(_simulate, "PASSAGE_HISTORY", 0)
    differs = []
    for k in CUTS:
        res = simulate(m, (0.0, 2.5), dt=1e-2, engine=engine, resume=_prefix(full, k), progress=False)
        differs.append(len(res) != len(full) or not np.array_equal(res.q, full.q))
    assert any(differs)
