"""Shared test configuration: deterministic hypothesis profile in CI."""

import importlib.util
import os
import re
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
    paths, ``-p no:xdist`` and ``-n 0`` stay in one process.

    The workers share the tests by work stealing (``--dist worksteal``, unless ``--dist`` was
    given): each starts with half of the ordered collection and an idle worker takes half of
    the other's remaining queue, so the two finish within about one short test of each other.
    xdist's default ``load`` hands the last tests out in chunks, and a chunk that holds a long
    test leaves the other worker idle at the end of the run."""
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
            if config.getoption("dist", "no") == "no":
                config.option.dist = "worksteal"


#: A test module marked slow as a whole (``pytestmark = pytest.mark.slow`` at its top level).
_SLOW_MODULE = re.compile(r"^pytestmark\s*=\s*pytest\.mark\.slow\s*$", re.M)


def pytest_ignore_collect(collection_path: Path, config: pytest.Config) -> bool | None:
    """A run that deselects the slow tests with the default ``-m "not slow"`` (pyproject's
    addopts) does not import a test module marked slow as a whole: all its tests would be
    deselected, but the import ran in every xdist worker (tests/sweep/test_dask.py imported
    distributed, dask, xarray, zarr, pandas and pyarrow at collection: 4.7 s of CPU per
    worker). Such a module is left out instead of deselected; ``-m slow`` (or any other ``-m``)
    and a module named on the command line collect it as before."""
    if (
        collection_path.suffix == ".py"
        and collection_path.name.startswith("test_")
        and config.getoption("markexpr", "") == "not slow"
    ):
        try:
            text = collection_path.read_text(encoding="utf-8")
        except OSError:
            return None
        if _SLOW_MODULE.search(text):
            return True
    return None


#: The longest tests of a fresh clone, longest first (``--durations`` of the default suite on a
#: fresh clone of a9b1940, 07:00 UTC 2026-11-27, quiet: mypy 27.3 s, the two browser tests 11.2
#: and 10.4 s (+ 2.4 s for Chromium's start), the API docs' build 8.3 s, tutorial 03 7.1 s, the
#: demo 6.2 s, ...). They go first, so that the two workers take them in turn beside the rest
#: instead of one worker finishing them alone at the end (longest-processing-time-first
#: scheduling). The browser tests were 2382nd and 2383rd of 2422 in collection order: ~24 s on
#: one worker while the other had ~40 short tests left. A prefix keeps the tests it matches in
#: their order, together (the browser tests share their module's Chromium, the API docs their
#: built site).
_FIRST = (
    "tests/test_lint.py::test_mypy_clean",
    "tests/viz/test_view.py::test_browser_",
    "tests/docs/test_api_docs.py::",
    "tests/docs/test_tutorials.py::test_tutorial_runs[03",
    "tests/cli/test_cli_e2e.py::test_demo_",  # the demo's tests share one run (module fixture)
    "tests/control/test_control_hybrid.py::test_passivity_set_point_lyapunov_non_increasing",
    "tests/docs/test_tutorials.py::test_tutorial_runs[02",
    "tests/sim/test_sim_passages.py::test_a_run_that_ends_at_a_change_point_ends_on_the_branch[0.00025-python]",
    "tests/sim/test_energy_bookkeeping.py::test_work_of_a_sinusoidal_push_is_half_m_v_squared[dop853-1e-08-python]",
    "tests/sim/test_sim_engine.py::test_events_located_by_the_general_driver_between_engine_steps[kw0]",
    "tests/cli/test_cli_e2e.py::test_run_",  # idem, one `nonmin run` of the crossed four-bar
    "tests/control/test_control_hybrid.py::test_tracker_follows_crank_trajectory[passivity]",
    "tests/docs/test_tutorials.py::test_tutorial_runs[04",
    "tests/docs/test_tutorials.py::test_tutorial_runs[01",
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
