"""The README's quick start runs, and .ci/run runs the README's test command."""

import re
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def _python_blocks(text: str) -> list[str]:
    return re.findall(r"```python\n(.*?)```", text, flags=re.S)


def test_quick_start_executes(capsys):
    blocks = _python_blocks((ROOT / "README.md").read_text())
    assert blocks, "README has no python block"
    ns: dict = {}
    exec(compile(blocks[0], "README-quickstart", "exec"), ns)
    assert np.allclose(ns["qdd"], [0.0, -9.81])


def test_ci_runs_readme_test_command():
    readme = (ROOT / "README.md").read_text()
    cmds = re.findall(r"```bash\n(.*?)```", readme, flags=re.S)
    test_cmd = [c.strip() for c in cmds if "pytest" in c and "pip install" in c][0]
    assert test_cmd in (ROOT / ".ci" / "run").read_text()
