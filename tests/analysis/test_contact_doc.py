"""docs/contact.md runs: its ```python blocks, in order, form one script whose output carries the
page's claims (reactions vs the closed form, undetermined redundant pins, an impact's impulses
by the lever rule, a driven slider-crank
vs its closed form, driver torque = inverse dynamics, redundant actuation)."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PAGE = ROOT / "docs" / "contact.md"
CLAIMS = [
    "ground -> bar | force on the bar, bar frame: (1501, 2)",
    "all determined: True",
    "pivot determined: [False False  True]  pivot2: [False False  True]",
    "engine program: True",
    "all ok: True",
    "ok=True fully_actuated=True dof=2 redundancy=2",
    "floor_l on the bar [0.       1.461643] N s, determined: True",
    "floor_r on the bar [0.       2.923286] N s, determined: True",
    "lever rule: 1.461643 and 2.923286 N s",
]
#: printed residual -> bound it must meet
BOUNDS = {
    r"max \|F - closed form\| = (\S+) N": 1e-8,
    r"max \|x - closed form\| = (\S+) m": 1e-9,
    r"max \|u_inverse - driver torque\| = (\S+) N m": 1e-7,
    r"replayed q̈ error (\S+)": 1e-9,
}


def test_contact_page_runs(tmp_path: Path) -> None:
    blocks = re.findall(
        r"^```python\n(.*?)^```", PAGE.read_text(encoding="utf-8"), flags=re.S | re.M
    )
    assert len(blocks) >= 5
    script = tmp_path / "contact.py"
    script.write_text("\n\n".join(b.rstrip() for b in blocks) + "\n", encoding="utf-8")
    env = dict(os.environ, MPLBACKEND="Agg", PYTHONHASHSEED="0")
    proc = subprocess.run(
        [sys.executable, str(script)],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-4000:]
    for phrase in CLAIMS:
        assert phrase in proc.stdout, f"output lacks {phrase!r}:\n{proc.stdout}"
    for pattern, bound in BOUNDS.items():
        m = re.search(pattern, proc.stdout)
        assert m is not None, f"output lacks {pattern!r}:\n{proc.stdout}"
        assert float(m.group(1)) < bound, f"{pattern}: {m.group(1)} ≥ {bound}"
