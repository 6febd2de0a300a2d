"""Every control example runs (``--quick``) and writes its plots into the folder given by --out."""

from __future__ import annotations

import runpy
import sys
from pathlib import Path

import pytest

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"

#: example script -> plots it must write
CONTROL_EXAMPLES = {
    "regulate_pendulum.py": ["regulation.png", "path.png"],
    "sigma_sticking.py": ["sigma_sticking.png"],
    "regulate_four_bar.py": ["regulation.png", "snapshots.png"],
    "five_bar_near_singularity.py": ["regulation.png", "snapshots.png"],
    "track_four_bar.py": ["tracking.png"],
    "wall_force_control.py": ["force_control.png", "snapshots.png"],
    "dual_arm_grasp.py": ["grasp.png", "snapshots.png"],
    "quaternion_no_unwinding.py": ["rotation.png"],
    "actuator_saturation.py": ["saturation.png"],
}


@pytest.mark.parametrize("script", sorted(CONTROL_EXAMPLES))
def test_control_example_runs_quick(script: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    path = EXAMPLES / script
    out = tmp_path / path.stem
    monkeypatch.setattr(sys, "argv", [str(path), "--quick", "--out", str(out)])
    monkeypatch.syspath_prepend(str(EXAMPLES))
    runpy.run_path(str(path), run_name="__main__")
    for name in CONTROL_EXAMPLES[script]:
        f = out / name
        assert f.is_file() and f.stat().st_size > 1000, f"{script} did not write {name}"


def test_control_examples_listed_in_readme() -> None:
    readme = (EXAMPLES / "README.md").read_text(encoding="utf-8")
    for script in CONTROL_EXAMPLES:
        assert script in readme, f"{script} missing from examples/README.md"
