"""A missing optional dependency raises MissingDependencyError naming the extra.

Absence is simulated for real in a fresh interpreter: ``sys.modules[name] = None`` makes
``import name`` raise ImportError (Python's own import machinery, no mock of the package).
"""

from __future__ import annotations

import subprocess
import sys
import textwrap


def _run(code: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True, timeout=120
    )


def test_missing_pinocchio_names_extra_pin() -> None:
    out = _run(
        """
        import sys
        sys.modules["pinocchio"] = None
        import nonmin.model
        import nonmin.model.robots as robots          # no pinocchio needed for the values
        c = robots.FrameConstraint.point("c", "ee")
        assert "pinocchio" not in [m for m in sys.modules if sys.modules[m] is not None]
        from nonmin.errors import MissingDependencyError
        try:
            robots.RobotModel
        except MissingDependencyError as exc:
            assert isinstance(exc, ImportError)
            print("MSG", exc)
        else:
            raise SystemExit("no error")
        """
    )
    assert out.returncode == 0, out.stderr
    assert "nonmin[pin]" in out.stdout and "pinocchio" in out.stdout


def test_missing_mujoco_names_extra_mujoco() -> None:
    out = _run(
        """
        import sys
        sys.modules["mujoco"] = None
        from nonmin.errors import MissingDependencyError
        from nonmin.model.robots import RobotModel, data_path
        RobotModel.from_urdf(data_path("arm4.urdf"))   # URDF needs no MuJoCo
        try:
            RobotModel.from_mjcf(data_path("fourbar.xml"))
        except MissingDependencyError as exc:
            print("MSG", exc)
        else:
            raise SystemExit("no error")
        """
    )
    assert out.returncode == 0, out.stderr
    assert "nonmin[mujoco]" in out.stdout
