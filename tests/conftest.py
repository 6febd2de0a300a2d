"""Shared test configuration: deterministic hypothesis profile in CI."""

import os

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


#: Tests that take the longest on a fresh clone (mypy checks ``src`` without a cache): first, so
#: that with two workers they run beside the rest instead of at the end.
_FIRST = ("tests/test_lint.py::test_mypy_clean",)


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    items.sort(key=lambda it: it.nodeid not in _FIRST)  # stable: the rest keep their order
