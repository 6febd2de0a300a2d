"""A sweep on a real Dask cluster (scheduler and two workers as separate processes on
localhost): a worker SIGKILLed mid-way loses nothing and duplicates nothing; a client SIGKILLed
mid-way loses no committed block, and the rerun computes only what was missing."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("xarray")
pytest.importorskip("zarr")
distributed = pytest.importorskip("distributed")

pytestmark = pytest.mark.slow

def _scenario_text() -> str:
    """The crossed four-bar from the library's state, written out (the model is built once per
    worker; the runs vary the crank's initial rate, projected onto the closure at the start)."""
    from nonmin import library

    st = library.get("crossed_four_bar").state
    return (
        '[model]\nlibrary = "crossed_four_bar"\n'
        f"[initial]\nq = {[float(v) for v in st.q]}\nqd = {[float(v) for v in st.qd]}\n"
        '[simulate]\nt_final = 0.4\nmethod = "rk4"\ndt = 1e-3\noutput_dt = 0.02\n'
    )


VARY = {"initial.qd[2]": [float(v) for v in np.linspace(5.0, 8.0, 200)]}
CHUNK = 10  # 20 tasks
#: A killed worker is noticed in seconds, not after the default 30 s connect timeouts.
FAST_FAIL = {"OPENBLAS_NUM_THREADS": "1", "DASK_DISTRIBUTED__COMM__TIMEOUTS__CONNECT": "3s"}


def _port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _commits(store: Path) -> list[dict]:
    """The store's commit records (the writer may be live: each record is whole or absent)."""
    out: list[dict] = []
    import zarr

    try:
        arr = zarr.open_array(str(store / "commit"), mode="r")
    except Exception:  # not created yet
        return out
    for text in (str(x) for x in np.asarray(arr[:]).tolist()):
        if text:
            out.append(json.loads(text))
    return out


def _exactly_once(store: Path, runs: int) -> None:
    recs = _commits(store)
    covered = np.zeros(runs, dtype=int)
    for r in recs:
        lo, hi = r["runs"]
        covered[lo:hi] += 1
    assert np.all(covered == 1), f"runs committed {set(covered.tolist())} times"
    assert len(recs) == runs // CHUNK


@pytest.fixture()
def cluster(tmp_path: Path):
    bindir = Path(sys.executable).parent
    port = _port()
    addr = f"tcp://127.0.0.1:{port}"
    env = {**os.environ, **FAST_FAIL}
    procs = [subprocess.Popen([str(bindir / "dask"), "scheduler", "--host", "127.0.0.1", "--port", str(port),
                               "--no-dashboard"], cwd=tmp_path, env=env,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)]  # fmt: skip
    for i in range(2):
        procs.append(subprocess.Popen([str(bindir / "dask"), "worker", addr, "--nthreads", "1", "--no-nanny",
                                       "--no-dashboard", "--name", f"w{i}", "--local-directory", str(tmp_path / f"w{i}")],
                                      cwd=tmp_path, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))  # fmt: skip
    try:
        yield addr, procs
    finally:
        for p in procs:
            if p.poll() is None:
                p.terminate()
        for p in procs:
            try:
                p.wait(3)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait(3)


def test_worker_killed_midway_then_client_killed_and_resumed(cluster, tmp_path: Path):
    import dask
    from distributed import Client

    from nonmin import sweep
    from nonmin.sweeps import open_sweep

    addr, procs = cluster
    scen = tmp_path / "cfb.toml"
    scen.write_text(_scenario_text(), encoding="utf-8")
    dask.config.set({"distributed.comm.timeouts.connect": "3s"})
    client = Client(addr, timeout=60)
    try:
        client.wait_for_workers(2, timeout=60)
        victim = procs[1].pid  # worker w0 (no nanny: the process is the worker)
        # -------- 1. SIGKILL a worker after 3 committed blocks
        store = tmp_path / "one.zarr"
        committed: list[int] = []

        def kill_after_three(b: int, lo: int, hi: int) -> None:
            committed.append(b)
            if len(committed) == 3:
                os.kill(victim, signal.SIGKILL)

        res = sweep(scen, VARY, store=store, scheduler=client, chunk=CHUNK, progress=False, on_block=kill_after_three)
        assert procs[1].poll() == -signal.SIGKILL  # the victim is gone
        assert (res.runs, res.computed, res.failed) == (200, 200, 0)
        ds = open_sweep(store)
        assert list(ds["status"].values) == ["success"] * 200
        _exactly_once(store, 200)
        local = sweep(scen, {"initial.qd[2]": VARY["initial.qd[2]"][:30]}, chunk=CHUNK, progress=False)
        np.testing.assert_array_equal(ds["q"].values[:30], local.dataset["q"].values)
    finally:
        client.close()
    # -------- 2. SIGKILL the client mid-way (one worker left), rerun: only the missing blocks
    store2 = tmp_path / "two.zarr"
    code = (
        "import json, sys; from nonmin import sweep; "
        f"sweep({str(scen)!r}, json.loads(sys.argv[1]), store={str(store2)!r}, scheduler={addr!r}, "
        f"chunk={CHUNK}, progress=False)"
    )
    cl = subprocess.Popen([sys.executable, "-c", code, json.dumps(VARY)], env={**os.environ, **FAST_FAIL})
    t_end = time.monotonic() + 120

    def n_commits() -> int:
        return len(_commits(store2))

    while cl.poll() is None and time.monotonic() < t_end and n_commits() < 3:
        time.sleep(0.02)
    cl.send_signal(signal.SIGKILL)
    cl.wait(10)
    before = len(_commits(store2))
    assert 3 <= before < 20, f"{before} blocks committed when the client was killed"
    client = Client(addr, timeout=60)
    try:
        res = sweep(scen, VARY, store=store2, scheduler=client, chunk=CHUNK, progress=False)
    finally:
        client.close()
    assert res.skipped == before * CHUNK and res.computed == 200 - before * CHUNK
    _exactly_once(store2, 200)
    ds2 = open_sweep(store2)
    assert list(ds2["status"].values) == ["success"] * 200
    np.testing.assert_array_equal(ds2["q"].values, open_sweep(tmp_path / "one.zarr")["q"].values)
