"""The README's quick start runs, and .ci/run runs the README's test command."""

import re
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]


def _python_blocks(text: str) -> list[str]:
    return re.findall(r"```python\n(.*?)```", text, flags=re.S)


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
    claimed = next(ln for ln in blocks[0].splitlines() if ln.startswith("# ["))[2:]
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
    assert test_cmd in (ROOT / ".ci" / "run").read_text()
