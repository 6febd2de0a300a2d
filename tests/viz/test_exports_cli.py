"""Exports load in one line (CSV with a plain header, Parquet, xarray/NetCDF with units), and
the command line's verbs agree with each other and with the API (issue 23)."""

from __future__ import annotations

import json

import numpy as np
import pytest

import nonmin
from nonmin import library
from nonmin.cli import DEMO_SCENARIOS, main
from nonmin.io import columns, to_csv


@pytest.fixture(scope="module")
def slider_traj():
    mech = library.get("slider_crank")
    return mech.model, nonmin.simulate(mech, (0.0, 0.2), dt=1e-2, progress=False)


def test_csv_loads_with_pandas_and_numpy(tmp_path, slider_traj):
    pd = pytest.importorskip("pandas")
    model, traj = slider_traj
    path = to_csv(traj, tmp_path / "t.csv", model)
    df = pd.read_csv(path)
    cols = columns(traj, model)
    assert list(df.columns) == list(cols)
    assert len(df) == len(traj)
    assert np.array_equal(df["t"].to_numpy(), traj.t)
    assert np.array_equal(df[f"q_{model.coordinate_names[0]}"].to_numpy(), traj.q[:, 0])
    data = np.loadtxt(path, delimiter=",", skiprows=1)
    assert data.shape == (len(traj), len(cols))
    side = json.loads((tmp_path / "t.csv.json").read_text())
    assert side["columns"]["t"] == "s"
    assert side["columns"]["q_crank.theta"] == "rad" and side["columns"]["qd_crank.x"] == "m/s"
    assert side["columns"]["fc_crank.theta"] == "N*m"
    assert side["metadata"]["coordinate_names"] == list(model.coordinate_names)
    # Trajectory.to_csv writes the same file
    traj.to_csv(tmp_path / "u.csv")
    assert (tmp_path / "u.csv").read_text().splitlines()[0].startswith("t,q_")


def test_parquet_and_xarray_carry_units(tmp_path, slider_traj):
    pd = pytest.importorskip("pandas")
    pq = pytest.importorskip("pyarrow.parquet")
    pytest.importorskip("xarray")
    from nonmin.io import to_netcdf, to_parquet, to_xarray

    model, traj = slider_traj
    path = to_parquet(traj, tmp_path / "t.parquet", model)
    df = pd.read_parquet(path)
    assert np.array_equal(df["t"].to_numpy(), traj.t)
    schema = pq.read_schema(path)
    assert schema.field("q_crank.theta").metadata[b"unit"] == b"rad"
    assert json.loads(schema.metadata[b"nonmin"])["coordinate_names"] == list(model.coordinate_names)
    ds = to_xarray(traj, model)
    assert ds["q"].shape == traj.q.shape and ds["t"].attrs["units"] == "s"
    assert list(ds["coordinate_unit"].values[:3]) == ["m", "m", "rad"]
    nc = to_netcdf(traj, tmp_path / "t.nc", model)
    assert nc.stat().st_size > 1000


def test_list_names_match_the_api_and_describe(capsys):
    assert main(["list"]) == 0
    out = capsys.readouterr().out
    assert "force_control" in out and "ForceControl" in out and "Switched" in out
    line = next(ln for ln in out.splitlines() if ln.strip().startswith("slider_crank"))
    assert len(line.split()) > 2  # a description follows the name
    assert ":class:" not in out and "``" not in out  # plain text, not reST
    for name in DEMO_SCENARIOS:
        assert name in out


def test_view_verb_serves_a_saved_trajectory(tmp_path, capsys, monkeypatch):
    pytest.importorskip("viser")
    mech = library.get("slider_crank")
    traj = nonmin.simulate(mech, (0.0, 0.1), dt=1e-2, progress=False)
    traj.save(tmp_path / "t.npz")
    monkeypatch.setenv("NONMIN_NO_BROWSER", "1")
    assert main(["view", str(tmp_path / "t.npz"), "--model", "slider_crank", "--port", "0",
                 "--seconds", "0.5"]) == 0
    assert "nonmin view: http://127.0.0.1:" in capsys.readouterr().out
    # a trajectory of another model is refused before anything is served
    assert main(["view", str(tmp_path / "t.npz"), "--model", "crossed_four_bar", "--port", "0",
                 "--seconds", "0.1"]) == 2
