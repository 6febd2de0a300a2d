"""nonmin.sweep: axes, the labeled result, the Zarr store (commit, resume), failures, CLI, plot."""

from __future__ import annotations

import math
import pickle
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from nonmin import library, sweep
from nonmin.errors import InputError
from nonmin.sim import simulate
from nonmin.sweeps import Grid, SweepSpec, Uniform, open_sweep, parse_vary, run_block


@pytest.fixture(autouse=True)
def _sweep_extras() -> None:
    """Skips without the sweep extra; imported by the tests that run, not at collection (every
    xdist worker collects every module: xarray and zarr took 3.5 s of CPU to import)."""
    pytest.importorskip("xarray")
    pytest.importorskip("zarr")

SCENARIO = """
name = "crossed four-bar sweep"
[model]
library = "crossed_four_bar"
[simulate]
t_final = 0.1
method = "rk4"
dt = 1e-3
output_dt = 0.01
"""


@pytest.fixture()
def scenario(tmp_path: Path) -> Path:
    p = tmp_path / "cfb.toml"
    p.write_text(SCENARIO, encoding="utf-8")
    return p


def test_parse_vary():
    assert parse_vary("model.params.omega0=6:8:3") == ("model.params.omega0", Grid(6.0, 8.0, 3))
    assert parse_vary("simulate.dt=1e-3:2e-3") == ("simulate.dt", Uniform(1e-3, 2e-3))
    assert parse_vary("simulate.method=rk4,midpoint") == ("simulate.method", ["rk4", "midpoint"])
    for bad in ("omega0", "k=1:2:0", "k=a:b:3", "k=1:2:3:4", "=1"):
        with pytest.raises(InputError):
            parse_vary(bad)


def test_grid_crossed_random_seeded():
    bar = library.get("crossed_four_bar")
    spec = SweepSpec(bar, (("params.gravity", [(0.0, -9.81), (0.0, -1.62)]), ("qd0.crank.theta", Grid(1, 2, 3))))
    rows = spec.table()
    assert len(rows) == 6 and rows[1] == {"params.gravity": (0.0, -9.81), "qd0.crank.theta": 1.5}
    r1 = SweepSpec(bar, (("t_final", Uniform(0.1, 0.2)),), samples=4, seed=7).table()
    r2 = SweepSpec(bar, (("t_final", Uniform(0.1, 0.2)),), samples=4, seed=7).table()
    assert r1 == r2 and len({r["t_final"] for r in r1}) == 4
    with pytest.raises(InputError, match="samples"):
        SweepSpec(bar, (("t_final", Uniform(0.1, 0.2)),)).table()


def test_scenario_sweep_in_memory_matches_simulate(scenario: Path):
    res = sweep(scenario, {"model.params.omega0": [6.5, 7.0, 7.5]}, chunk=2, workers=2, progress=False)
    ds = res.dataset
    assert dict(ds.sizes) == {"run": 3, "time": 11, "coordinate": 9}
    assert list(ds["status"].values) == ["success"] * 3
    np.testing.assert_array_equal(ds["model.params.omega0"].values, [6.5, 7.0, 7.5])
    ref = simulate(library.get("crossed_four_bar", omega0=7.0), 0.1, dt=1e-3, t_eval=np.linspace(0, 0.1, 11))
    np.testing.assert_array_equal(ds["q"].values[1], ref.q)
    assert float(ds["energy_drift"].values[1]) == pytest.approx(ref.energy_drift, rel=0, abs=0)
    assert np.all(ds["closure"].values < 1e-12)
    assert res.computed == 3 and res.skipped == 0 and res.failed == 0


def test_a_run_that_cannot_start_fails_alone(scenario: Path):
    # omega0 = 0.1 is refused by the model source (too slow for full turns): that run fails
    res = sweep(scenario, {"model.params.omega0": [7.0, 0.1, 6.8]}, progress=False)
    st = list(res.dataset["status"].values)
    assert st == ["success", "failed", "success"]
    assert "omega0" in str(res.dataset["message"].values[1])
    assert res.failed == 1


def test_store_commits_blocks_and_resumes(scenario: Path, tmp_path: Path):
    store = tmp_path / "s.zarr"
    vary = {"model.params.omega0": list(np.linspace(6.5, 8.0, 7))}
    seen: list[int] = []

    def stop_after_two(b: int, lo: int, hi: int) -> None:
        seen.append(b)
        if len(seen) == 2:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        sweep(scenario, vary, store=store, chunk=2, workers=1, progress=False, on_block=stop_after_two)
    part = open_sweep(store)
    done = part["status"].values != "pending"
    assert int(done.sum()) == 4  # two committed blocks of 2 runs
    res = sweep(scenario, vary, store=store, chunk=2, workers=1, progress=False)
    assert (res.computed, res.skipped) == (3, 4)
    full = sweep(scenario, vary, chunk=3, progress=False).dataset
    np.testing.assert_array_equal(res.dataset["q"].values, full["q"].values)
    assert list(res.dataset["status"].values) == ["success"] * 7
    again = sweep(scenario, vary, store=store, chunk=2, progress=False)
    assert (again.computed, again.skipped) == (0, 7)
    with pytest.raises(InputError, match="different sweep"):
        sweep(scenario, {"model.params.omega0": [7.0]}, store=store, progress=False)


def test_model_base_keys_and_pickling():
    bar = library.get("crossed_four_bar")
    spec = SweepSpec(bar, (("qd0.crank.theta", [0.5, 1.0]), ("params.gravity", [(0.0, -1.0)])), t_span=0.05,
                     options={"dt": 1e-3, "t_eval": np.linspace(0, 0.05, 6)})  # fmt: skip
    back = pickle.loads(pickle.dumps(spec))
    rows = spec.table()
    a = run_block(spec, rows, 9, 6)
    b = run_block(back, rows, 9, 6)
    np.testing.assert_array_equal(a["q"], b["q"])
    assert a["status"] == ["success", "success"]
    q0 = bar.state.q
    qd0 = bar.state.qd.copy()
    qd0[2] = 1.0
    ref = simulate(bar.model.replace(gravity=(0.0, -1.0)), 0.05, q0, qd0, dt=1e-3, t_eval=np.linspace(0, 0.05, 6))
    np.testing.assert_array_equal(a["q"][1], ref.q)



def test_dask_task_spec_is_sent_without_axes_and_unpickled_once_per_worker():
    """The Dask path ships the spec once pickled, without its axes (a task gets its rows), and a
    worker unpickles it once: its blocks share one model (and engine program); same results."""
    pytest.importorskip("cloudpickle")
    from nonmin.sweeps import _run

    bar = library.get("crossed_four_bar")
    states = [(bar.state.q, bar.state.qd * s) for s in np.linspace(0.5, 1.5, 40)]
    spec = SweepSpec(bar.model, ((("q0", "qd0"), states),), t_span=0.02,
                     options={"dt": 1e-3, "t_eval": np.linspace(0, 0.02, 3)})  # fmt: skip
    token, blob = _run._pack(spec)
    assert pickle.loads(blob).axes == () and len(blob) < len(pickle.dumps(spec)) - 40 * 72  # (40 qd0 arrays)
    assert _run._pack(spec)[0] == token
    rows = spec.table()
    _run._SPECS.pop(token, None)
    a = _run._remote_block(token, blob, rows[:3], 9, 3)
    held = _run._SPECS[token]
    b = _run._remote_block(token, blob, rows[3:6], 9, 3)
    assert _run._SPECS[token] is held and held.axes == ()
    np.testing.assert_array_equal(a["q"], run_block(spec, rows[:3], 9, 3)["q"])
    np.testing.assert_array_equal(b["q"], run_block(spec, rows[3:6], 9, 3)["q"])

def test_import_nonmin_does_not_import_the_sweep_extras():
    code = "import sys, nonmin; print(sorted(m for m in ('xarray', 'zarr', 'dask', 'distributed') if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


def test_cli_sweep_then_plot(scenario: Path, tmp_path: Path):
    pytest.importorskip("matplotlib")
    from nonmin.cli import main

    store = tmp_path / "cli.zarr"
    argv = ["sweep", str(scenario), "--vary", "model.params.omega0=6.5:7.5:3", "--vary", "simulate.dt=1e-3,5e-4",
            "--out", str(store), "--no-progress"]  # fmt: skip
    assert main(argv) == 0
    ds = open_sweep(store)
    assert ds.sizes["run"] == 6 and set(ds["status"].values) == {"success"}
    assert main(argv) == 0  # resumes: nothing left
    png = tmp_path / "drift.png"
    assert main(["plot", str(store), "-o", str(png), "--metric", "energy_drift"]) == 0
    assert png.stat().st_size > 1000
    assert main(["plot", str(store), "-o", str(png), "--metric", "nope"]) == 2
    # per-run variables that are not numbers: a usage error (exit 2), was a ValueError (exit 4)
    assert main(["plot", str(store), "-o", str(png), "--metric", "status"]) == 2
    assert main(["plot", str(store), "-o", str(png), "--metric", "message"]) == 2
    assert main(["sweep", str(scenario), "--vary", "omega0", "--out", str(store)]) == 2


def test_plot_sweep_refuses_non_numeric_metric_and_keys(scenario: Path):
    pytest.importorskip("matplotlib")
    from nonmin.sweeps import plot_sweep

    ds = sweep(scenario, {"simulate.method": ["rk4", "midpoint"]}, progress=False).dataset
    with pytest.raises(InputError, match=r"'status'.*not a number"):
        plot_sweep(ds, "status", ["simulate.method"])
    with pytest.raises(InputError, match=r"'simulate\.method'.*known: \[\]"):
        plot_sweep(ds, "energy_drift", ["simulate.method"])


def test_random_samples_cli_seed(scenario: Path, tmp_path: Path):
    from nonmin.cli import main

    a, b = tmp_path / "a.zarr", tmp_path / "b.zarr"
    for st in (a, b):
        assert main(["sweep", str(scenario), "--vary", "model.params.omega0=6.5:8", "--samples", "3",
                     "--seed", "11", "--out", str(st), "--no-progress"]) == 0  # fmt: skip
    va = open_sweep(a)["model.params.omega0"].values
    np.testing.assert_array_equal(va, open_sweep(b)["model.params.omega0"].values)
    assert va.shape == (3,) and np.all((va >= 6.5) & (va < 8.0))
    assert math.isfinite(float(open_sweep(a)["energy_drift"].values[0]))


@pytest.mark.slow  # a subprocess importing nonmin and matplotlib: 28 s under load 20
def test_the_basins_script_runs(tmp_path: Path):
    pytest.importorskip("matplotlib")
    script = Path(__file__).resolve().parents[2] / "docs" / "make_basins.py"
    out = tmp_path / "b.png"
    res = subprocess.run([sys.executable, str(script), "--n", "3", "--t", "0.05", "--out", str(out)],
                         capture_output=True, text=True, timeout=300)  # fmt: skip
    assert res.returncode == 0, res.stderr
    assert "9 runs" in res.stdout and " 0 failed" in res.stdout
    assert out.stat().st_size > 1000


def test_progress_shows_runs_failures_and_eta(scenario: Path, capsys: pytest.CaptureFixture[str]):
    sweep(scenario, {"model.params.omega0": [7.0, 0.1]}, chunk=1, workers=1, progress=True)
    err = capsys.readouterr().err
    last = err.replace("\r", "\n").strip().splitlines()[-1]
    assert "sweep: 2/2 runs (0 from the store), 1 failed" in last and "ETA 0 s" in last
