"""Nothing lost, per run: a local sweep with ``chunk=1`` (every run its own block, its own
commit) SIGKILLed mid-way keeps every run it had committed, exactly once, with its data; the
rerun computes only the runs that were missing."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("xarray")
zarr = pytest.importorskip("zarr")

from nonmin import sweep  # noqa: E402
from nonmin.sweeps import open_sweep  # noqa: E402

pytestmark = pytest.mark.slow

RUNS = 60
KEY = "initial.qd[2]"
VARY = {KEY: [float(v) for v in np.linspace(5.0, 8.0, RUNS)]}


def _scenario_text() -> str:
    """The crossed four-bar from the library's state (one model for every run; the runs vary
    the crank's initial rate, projected onto the closure at the start)."""
    from nonmin import library

    st = library.get("crossed_four_bar").state
    return (
        '[model]\nlibrary = "crossed_four_bar"\n'
        f"[initial]\nq = {[float(v) for v in st.q]}\nqd = {[float(v) for v in st.qd]}\n"
        '[simulate]\nt_final = 0.3\nmethod = "rk4"\ndt = 1e-3\noutput_dt = 0.02\n'
    )


def _commits(store: Path) -> list[dict]:
    """The store's commit records (the writer may have died mid-write: each record is whole or
    absent)."""
    try:
        arr = zarr.open_array(str(store / "commit"), mode="r")
    except Exception:  # not created yet
        return []
    return [json.loads(x) for x in (str(v) for v in np.asarray(arr[:]).tolist()) if x]


def _covered(store: Path) -> np.ndarray:
    covered = np.zeros(RUNS, dtype=int)
    for r in _commits(store):
        lo, hi = r["runs"]
        assert hi - lo == 1, "chunk=1: one run per commit"
        covered[lo:hi] += 1
    return covered


def test_local_sweep_killed_midway_with_chunk_1_loses_and_repeats_no_run(tmp_path: Path) -> None:
    scen = tmp_path / "cfb.toml"
    scen.write_text(_scenario_text(), encoding="utf-8")
    store = tmp_path / "s.zarr"
    code = (
        "import json, sys; from nonmin import sweep; "
        f"sweep({str(scen)!r}, json.loads(sys.argv[1]), store={str(store)!r}, chunk=1, workers=1, progress=False)"
    )
    proc = subprocess.Popen([sys.executable, "-c", code, json.dumps(VARY)],
                            env={**os.environ, "OPENBLAS_NUM_THREADS": "1"})  # fmt: skip
    t_end = time.monotonic() + 120
    while proc.poll() is None and time.monotonic() < t_end and len(_commits(store)) < 5:
        time.sleep(0.01)
    proc.send_signal(signal.SIGKILL)
    proc.wait(10)
    assert proc.returncode == -signal.SIGKILL, "the sweep finished before it could be killed"
    covered = _covered(store)
    before = int(covered.sum())
    assert np.all(covered <= 1) and 5 <= before < RUNS, f"{before} runs committed when the sweep was killed"
    # every committed run is in the store with its data; the others are pending
    part = open_sweep(store)
    status = part["status"].values
    assert list(status[covered == 1]) == ["success"] * before
    # at most the one run in flight has its data written without its record (killed between
    # the two): not done, the rerun computes it again
    assert int(np.count_nonzero(status[covered == 0] != "pending")) <= 1
    done = np.flatnonzero(covered == 1)
    ref = sweep(scen, {KEY: [VARY[KEY][i] for i in done]}, chunk=8,
                progress=False).dataset  # fmt: skip
    np.testing.assert_array_equal(part["q"].values[done], ref["q"].values)
    # the rerun computes exactly the missing runs
    res = sweep(scen, VARY, store=store, chunk=1, workers=1, progress=False)
    assert (res.skipped, res.computed, res.failed) == (before, RUNS - before, 0)
    assert np.all(_covered(store) == 1)
    full = open_sweep(store)
    assert list(full["status"].values) == ["success"] * RUNS
    np.testing.assert_array_equal(full["q"].values[done], ref["q"].values)


def test_ctrl_c_on_the_cli_sweep_says_what_is_kept_and_exits_130(tmp_path: Path) -> None:
    """nonmin sweep stopped by Ctrl-C (SIGINT) printed only 'nonmin: interrupted'; it now says
    how many runs the store holds and that the same command resumes, and exits 130."""
    scen = tmp_path / "cfb.toml"
    scen.write_text(_scenario_text(), encoding="utf-8")
    store = tmp_path / "c.zarr"
    argv = [sys.executable, "-m", "nonmin.cli", "sweep", str(scen), "--vary", f"{KEY}=5:8:{RUNS}",
            "--chunk", "1", "--workers", "1", "--out", str(store), "--no-progress"]  # fmt: skip
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env={**os.environ, "OPENBLAS_NUM_THREADS": "1"})  # fmt: skip
    t_end = time.monotonic() + 120
    while proc.poll() is None and time.monotonic() < t_end and len(_commits(store)) < 2:
        time.sleep(0.01)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    kept = int(_covered(store).sum())
    assert 2 <= kept < RUNS
    assert f"{kept} of {RUNS} runs committed" in err and "the same command resumes" in err, err
