"""Shared test configuration: deterministic hypothesis profile in CI."""

import importlib.util
import os
import sys
from collections.abc import Callable
from pathlib import Path
from types import ModuleType

import pytest
from hypothesis import HealthCheck, settings

settings.register_profile(
    "ci",
    derandomize=True,
    max_examples=60,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow],
)
settings.register_profile("dev", max_examples=100, deadline=None)
settings.load_profile("ci" if os.environ.get("CI") else os.environ.get("HYPOTHESIS_PROFILE", "ci"))


@pytest.hookimpl(tryfirst=True)
def pytest_cmdline_main(config: pytest.Config) -> None:
    """The default suite (``python -m pytest`` with no paths: the README's test command and
    ``.ci/run``) runs on two worker processes (pytest-xdist) when xdist is installed and no
    ``-n`` was given: the suite is sized for two cores (issue 17, target 7). Runs of chosen
    paths, ``-p no:xdist`` and ``-n 0`` stay in one process."""
    if (
        config.pluginmanager.hasplugin("xdist")
        and config.getoption("numprocesses", None) is None
        and config.args_source == pytest.Config.ArgsSource.TESTPATHS
        and "PYTEST_XDIST_WORKER" not in os.environ
        and not config.getoption("usepdb", False)
    ):
        cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
        if cores > 1:
            config.option.numprocesses = 2


#: The longest tests of a fresh clone, longest first (``--durations`` of the default suite, 17:58
#: UTC 2026-11-26, load ~15: mypy 140 s, the tutorial pages 17–30 s each, the demo 29 s, ...;
#: not the browser tests, whose module fixture starts Chromium once per worker that runs them):
#: they go first, so that the two workers take them in turn beside the rest instead of one
#: worker finishing them alone at the end (longest-processing-time-first scheduling).
_FIRST = (
    "tests/test_lint.py::test_mypy_clean",
    "tests/docs/test_tutorials.py::test_tutorial_runs[03",
    "tests/cli/test_cli_e2e.py::test_demo_quick",
    "tests/docs/test_tutorials.py::test_tutorial_runs[02",
    "tests/docs/test_tutorials.py::test_tutorial_runs[01",
    "tests/cli/test_cli_e2e.py::test_run_writes_all_outputs",
    "tests/docs/test_tutorials.py::test_tutorial_runs[04",
    "tests/control/test_control_hybrid.py::test_passivity_set_point_lyapunov_non_increasing",
)


def _rank(item: pytest.Item) -> int:
    return next((i for i, p in enumerate(_FIRST) if item.nodeid.startswith(p)), len(_FIRST))


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    items.sort(key=_rank)  # stable: the rest keep their order


@pytest.fixture(scope="session")
def pin_frame_constraints() -> Callable[..., tuple]:
    """``pin_frame_constraints(robot, [(rows, name), ...])``: Pinocchio's ``RigidConstraintModel``
    for each of a ``RobotModel``'s frame constraints (``CONTACT_3D`` for 3 rows, else
    ``CONTACT_6D``, between the frames ``name:a`` and ``name:b``, LOCAL reference frame) and
    their data, as the vectors ``constraintDynamics`` takes (the tests that compare with it)."""

    def build(robot: object, specs: list[tuple[int, str]]) -> tuple:
        import pinocchio as pin

        pm = robot.pinocchio_model  # type: ignore[attr-defined]
        models = pin.StdVec_RigidConstraintModel()
        datas = pin.StdVec_RigidConstraintData()
        for rows, name in specs:
            fa = pm.frames[robot.frame_id(f"{name}:a")]  # type: ignore[attr-defined]
            fb = pm.frames[robot.frame_id(f"{name}:b")]  # type: ignore[attr-defined]
            ctype = pin.ContactType.CONTACT_3D if rows == 3 else pin.ContactType.CONTACT_6D
            cm = pin.RigidConstraintModel(
                ctype, pm, fa.parentJoint, fa.placement, fb.parentJoint, fb.placement, pin.ReferenceFrame.LOCAL
            )
            models.append(cm)
            datas.append(cm.createData())
        return models, datas

    return build


@pytest.fixture(scope="session")
def load_benchmark() -> Callable[[str], ModuleType]:
    """``load_benchmark("sim_bench")``: a script of ``benchmarks/`` imported as a module (the
    tests that check the peer models the benchmarks run)."""

    here = Path(__file__).resolve().parents[1] / "benchmarks"
    if str(here) not in sys.path:  # the scripts import their helpers beside them (pin_loops)
        sys.path.append(str(here))

    def load(name: str) -> ModuleType:
        if name in sys.modules:
            return sys.modules[name]
        path = here / f"{name}.py"
        spec = importlib.util.spec_from_file_location(name, path)
        assert spec is not None and spec.loader is not None
        mod = importlib.util.module_from_spec(spec)
        sys.modules[name] = mod
        spec.loader.exec_module(mod)
        return mod

    return load
