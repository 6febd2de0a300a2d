"""The README's quick start runs, and .ci/run runs the README's test command."""

import re
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]


def _python_blocks(text: str) -> list[str]:
    return re.findall(r"```python\n(.*?)```", text, flags=re.S)


def _shown_output(text: str) -> str:
    """The ```text block right after the first python block (what the quick start prints)."""
    m = re.search(r"```python\n.*?```\s*```text\n(.*?)```", text, flags=re.S)
    assert m, "the quick start shows no output block"
    return m.group(1).strip()


def test_quick_start_executes(capsys):
    blocks = _python_blocks((ROOT / "README.md").read_text())
    assert blocks, "README has no python block"
    ns: dict = {}
    exec(compile(blocks[0], "README-quickstart", "exec"), ns)
    assert np.allclose(ns["qdd"], [-1.0, -9.81])
    traj = ns["traj"]
    assert traj.status.value == "success"
    # the printed numbers in the README must be what the code prints
    printed = capsys.readouterr().out.strip().splitlines()[-1]
    claimed = _shown_output((ROOT / "README.md").read_text()).splitlines()[-1]
    # qdd and status verbatim; energy drift to the two printed digits; closure at round-off
    (p_arr, p_rest), (c_arr, c_rest) = (x.split("]", 1) for x in (printed, claimed))
    assert p_arr.split() == c_arr.split(), (printed, claimed)
    p_tok, c_tok = p_rest.split(), c_rest.split()
    assert p_tok[0] == c_tok[0], (printed, claimed)
    assert float(p_tok[1]) == pytest.approx(float(c_tok[1]), rel=0.1), (printed, claimed)
    assert float(p_tok[3]) < 1e-13 and float(c_tok[3]) < 1e-13


def test_ci_runs_readme_test_command():
    readme = (ROOT / "README.md").read_text()
    cmds = re.findall(r"```bash\n(.*?)```", readme, flags=re.S)
    test_cmd = next(c.strip() for c in cmds if "pytest" in c and "pip install" in c)
    # .ci/run runs the command's parts ("install && test") as lines in this order; it may wait
    # between them (for the Chromium it installs in the background)
    lines = [ln.strip() for ln in (ROOT / ".ci" / "run").read_text().splitlines()]
    parts = [p.strip() for p in test_cmd.split("&&")]
    at = [lines.index(p) if p in lines else -1 for p in parts]
    assert -1 not in at and at == sorted(at), (parts, at)
    assert lines[-1] == parts[-1], "the test run is .ci/run's last step"


def test_readme_shows_what_its_code_prints(tmp_path):
    """docs/refresh_tutorials.py --check on the README: every output block is current."""
    import os
    import subprocess
    import sys

    env = dict(os.environ, MPLBACKEND="Agg", NONMIN_NO_BROWSER="1")
    proc = subprocess.run(
        [sys.executable, str(ROOT / "docs" / "refresh_tutorials.py"), "--check", str(ROOT / "README.md")],
        cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]


def test_gallery_caption_numbers_are_the_demo_s():
    """The A02 caption's energy error and closure are what `nonmin demo` prints for n_four_bar
    (it said ≤ 1e-9 J and ≤ 1e-15 while the demo printed 2.7e-9 J and 1.3e-14)."""
    from importlib.resources import files

    from nonmin.io import load_scenario, run_scenario

    readme = (ROOT / "README.md").read_text()
    m = re.search(r"\*\*A02 N four-bar\*\*.*?energy error ([0-9.e+-]+) J, closure ([0-9.e+-]+) m", readme)
    assert m, "the A02 caption states no energy error and closure"
    path = files("nonmin") / "data" / "scenarios" / "n_four_bar.toml"
    traj = run_scenario(load_scenario(str(path)), write=False, progress=False).trajectory
    drift = traj.energy_drift  # the summary's drift[J]
    assert drift == pytest.approx(float(m.group(1)), rel=0.1), (drift, m.group(1))
    assert float(traj.phi_norm.max()) < 10 * float(m.group(2))
