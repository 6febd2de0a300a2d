"""Every CLI verb end to end on shipped scenarios, into a temporary folder."""

import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from nonmin.cli import DEMO_SCENARIOS, EXIT_FAILED, EXIT_OK, EXIT_USAGE, main
from nonmin.sim import load_trajectory

SCENARIOS = Path(__file__).resolve().parents[2] / "src" / "nonmin" / "data" / "scenarios"


def _png_ok(path: Path) -> None:
    from PIL import Image

    assert path.exists() and path.stat().st_size > 5000
    with Image.open(path) as im:
        arr = np.asarray(im.convert("L"), dtype=float)
    assert arr.std() > 5.0, f"{path} looks blank"


def _main_printed(argv: list[str]) -> tuple[int, str]:
    import contextlib
    import io

    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        code = main(argv)
    return code, buf.getvalue()


@pytest.fixture(scope="module")
def crossed_run(tmp_path_factory):
    """One `nonmin run` of the crossed four-bar (0.4 s), shared by the tests that read it."""
    out = tmp_path_factory.mktemp("crossed") / "run"
    code, printed = _main_printed(["run", str(SCENARIOS / "crossed_four_bar.toml"), "--out", str(out),
                                   "--t-final", "0.4", "--no-progress"])
    return code, printed, out


@pytest.fixture(scope="module")
def demo_run(tmp_path_factory):
    """One `nonmin demo` (0.3 s of each scenario), shared by the tests that read it."""
    out = tmp_path_factory.mktemp("demo")
    code, printed = _main_printed(["demo", "--out", str(out), "--t-final", "0.3", "--no-progress"])
    return code, printed, out


def test_run_writes_all_outputs(crossed_run, tmp_path):
    code, printed, out = crossed_run
    assert code == EXIT_OK
    traj = load_trajectory(out / "trajectory.npz")
    assert traj.t[-1] == pytest.approx(0.4)
    assert traj.q.shape[1] == 9 and np.isfinite(traj.q).all()
    assert np.max(traj.phi_norm) < 1e-10
    assert traj.metadata["source"]["library"] == "crossed_four_bar"
    csv = np.loadtxt(out / "trajectory.csv", delimiter=",", skiprows=1)
    assert csv.shape[0] == len(traj)
    assert np.allclose(csv[:, 0], traj.t)
    _png_ok(out / "trajectory.png")
    gif = out / "animation.gif"
    assert gif.exists() and gif.stat().st_size > 10_000
    assert "crossed four-bar" in printed and "success" in printed

    # plot and animate read the saved result
    assert main(["plot", str(out / "trajectory.npz"), "-o", str(tmp_path / "p.png")]) == EXIT_OK
    _png_ok(tmp_path / "p.png")
    assert main(["animate", str(out / "trajectory.npz"), "-o", str(tmp_path / "a.gif"), "--fps", "10",
                 "--model", "crossed_four_bar"]) == EXIT_OK
    assert (tmp_path / "a.gif").stat().st_size > 10_000


def test_run_and_animate_make_the_same_frames_and_default_paths(crossed_run, tmp_path):
    """(Moved from tests/viz/test_exports_cli.py, where it made a run of its own.)"""
    from PIL import Image

    code, printed, out = crossed_run
    assert code == EXIT_OK
    assert "sim[s]" in printed and "render[s]" in printed and "wall" not in printed
    with Image.open(out / "animation.gif") as im:
        run_frames = im.n_frames
    result = tmp_path / "trajectory.npz"
    shutil.copy(out / "trajectory.npz", result)
    # animate without -o writes RESULT.gif, with the run's frame rate
    assert main(["animate", str(result), "--model", "crossed_four_bar", "--no-progress"]) == EXIT_OK
    with Image.open(tmp_path / "trajectory.gif") as im:
        assert im.n_frames == run_frames
    # plot without -o writes RESULT.png; export without -o writes RESULT.csv and its sidecar
    assert main(["plot", str(result)]) == EXIT_OK
    assert (tmp_path / "trajectory.png").stat().st_size > 10_000
    assert main(["export", str(result)]) == EXIT_OK
    assert (tmp_path / "trajectory.csv").exists() and (tmp_path / "trajectory.csv.json").exists()


def test_demo_quick(demo_run):
    code, printed, out = demo_run
    assert code == EXIT_OK
    for name in DEMO_SCENARIOS:
        assert (out / name / "trajectory.npz").exists()
        _png_ok(out / name / "trajectory.png")
        assert name in printed
    summary = (out / "summary.txt").read_text()
    assert summary.count("success") + summary.count("event_terminated") == len(DEMO_SCENARIOS)


def test_demo_summary_separates_simulation_from_rendering(demo_run):
    """(Moved from tests/viz/test_exports_cli.py, where it ran `demo --only arm_wall` again.)"""
    code, printed, out = demo_run
    assert code == EXIT_OK
    head = (out / "summary.txt").read_text().splitlines()[0]
    assert "sim[s]" in head and "render[s]" in head and "wall" not in head.lower()
    assert "drift[J]" in head and "W_fr[J]" in head and "L_imp[J]" in head
    assert "simulated 0.3 s in" in printed and "in all" in printed


def test_demo_only_runs_the_named_scenarios(tmp_path, capsys, monkeypatch):
    """`demo --only NAME ...` runs those scenarios alone (their files: test_demo_quick)."""
    import nonmin.io

    monkeypatch.setattr(nonmin.io, "write_outputs", lambda res, out, progress=None: {})
    assert main(["demo", "--out", str(tmp_path), "--t-final", "0.05", "--no-progress",
                 "--only", "arm_wall"]) == EXIT_OK
    printed = capsys.readouterr().out
    assert "simulated 0.05 s in" in printed
    first = [ln.split()[0] for ln in (tmp_path / "summary.txt").read_text().splitlines() if ln.strip()]
    assert [w for w in first if w in DEMO_SCENARIOS] == ["arm_wall"]
    assert "[nonmin demo]" in printed and printed.count("[nonmin demo]") == 1


def test_check_library_model(capsys):
    assert main(["check", "crossed_four_bar", "--duration", "0.3", "--samples", "80"]) == EXIT_OK
    out = capsys.readouterr().out
    assert "PASSED" in out and "rank of A drops at t =" in out


def test_list(capsys):
    assert main(["list"]) == EXIT_OK
    out = capsys.readouterr().out
    for word in ("crossed_four_bar", "rk4", "projection", "regulator"):
        assert word in out


def test_usage_errors(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text('[model]\nlibrary = "crossed_four_bar"\n[simulate]\ndt = "x"\n')
    assert main(["run", str(bad)]) == EXIT_USAGE
    assert "simulate.dt" in capsys.readouterr().err
    unknown = tmp_path / "unknown.toml"
    unknown.write_text('[model]\nlibrary = "no_such_model"\n')
    assert main(["run", str(unknown)]) == EXIT_USAGE
    assert "no_such_model" in capsys.readouterr().err
    assert main(["check", "no_such_model"]) == EXIT_USAGE


def test_failed_simulation_exit_code(tmp_path, capsys):
    sc = tmp_path / "fail.toml"
    sc.write_text(
        '[model]\nlibrary = "crossed_four_bar"\n[simulate]\nt_final = 0.5\nmethod = "rk4"\ndt = 0.5\n'
        '[output]\nplots = false\nanimation = false\n'
    )
    code = main(["run", str(sc), "--out", str(tmp_path / "o")])
    # one huge step either fails (exit 1) or succeeds; it must never crash (exit 4)
    assert code in (EXIT_OK, EXIT_FAILED)


def test_console_script_entry_point():
    exe = shutil.which("nonmin")
    cmd = [exe] if exe else [sys.executable, "-m", "nonmin.cli"]
    res = subprocess.run([*cmd, "--version"], capture_output=True, text=True, timeout=60)
    assert res.returncode == 0 and "nonmin" in res.stdout


def test_validate_quick_writes_report(tmp_path, capsys):
    report = tmp_path / "validation.md"
    code = main(["validate", "--report", str(report)])
    out = capsys.readouterr().out
    assert code == EXIT_OK, out
    assert "A01" in out and "crossed four-bar" in out
    text = report.read_text()
    assert "# Validation report" in text and "pass" in text


def test_entry_point_model_and_events(tmp_path, monkeypatch, capsys):
    pkg = tmp_path / "mymodels.py"
    pkg.write_text(
        "from nonmin import library\n"
        "def build(name='crossed_four_bar'):\n"
        "    return library.get(name)\n"
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    sc = tmp_path / "ep.toml"
    sc.write_text(
        'name = "entry point + events"\n'
        '[model]\nentry_point = "mymodels:build"\n[model.params]\nname = "crossed_four_bar"\n'
        '[simulate]\nt_final = 0.3\nmethod = "rk4"\ndt = 1e-3\noutput_dt = 0.01\n'
        '[[events]]\nname = "cut D"\nat_time = 0.1\ntransition = "deactivate"\nconstraints = ["D"]\n'
        '[output]\nplots = false\nanimation = false\n'
    )
    code = main(["run", str(sc), "--out", str(tmp_path / "o")])
    assert code == EXIT_USAGE and "--allow-code" in capsys.readouterr().err  # code needs opt-in
    code = main(["run", str(sc), "--out", str(tmp_path / "o"), "--allow-code"])
    assert code == EXIT_OK, capsys.readouterr().err
    traj = load_trajectory(tmp_path / "o" / "trajectory.npz")
    assert [e.name for e in traj.events] == ["cut D"]
    assert traj.events[0].t == pytest.approx(0.1, abs=1e-10)
    assert "D" in traj.active[0] and "D" not in traj.active[-1]
    assert traj.rank[0] == 8 and traj.rank[-1] == 6  # the loop opened: two rows fewer


def test_bad_entry_point(tmp_path, capsys):
    sc = tmp_path / "bad.toml"
    sc.write_text('[model]\nentry_point = "no_such_module_xyz:build"\n')
    assert main(["run", str(sc), "--allow-code"]) == EXIT_USAGE
    err = capsys.readouterr().err
    assert "model.entry_point" in err and "no_such_module_xyz" in err


def test_run_prints_every_file_the_same_way(tmp_path, monkeypatch, capsys):
    """With a relative --out, the trajectory and animation were printed as absolute paths and
    the CSV and plot as relative ones; every file line is now absolute."""
    scen = tmp_path / "s.toml"
    scen.write_text('[model]\nlibrary = "crossed_four_bar"\n[simulate]\nt_final = 0.05\noutput_dt = 0.01\n'
                    '[output]\nanimation = false\n')  # fmt: skip
    monkeypatch.chdir(tmp_path)
    assert main(["run", str(scen), "--out", "rel", "--no-progress"]) == EXIT_OK
    lines = [ln.split(None, 1) for ln in capsys.readouterr().out.splitlines()]
    files = {ln[0]: ln[1] for ln in lines if len(ln) == 2 and ln[0] in ("trajectory", "csv", "plot")}
    assert set(files) == {"trajectory", "csv", "plot"}
    for kind, path in files.items():
        assert Path(path).is_absolute() and Path(path).parent == (tmp_path / "rel").resolve(), (kind, path)
