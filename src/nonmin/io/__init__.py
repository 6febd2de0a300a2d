"""Scenario files (TOML) and their execution (used by the command line)."""

from ._run import ScenarioResult as ScenarioResult
from ._run import build_controller as build_controller
from ._run import build_events as build_events
from ._run import run_scenario as run_scenario
from ._run import simulate_kwargs as simulate_kwargs
from ._run import write_outputs as write_outputs
from ._scenario import SCENARIO_SCHEMA as SCENARIO_SCHEMA
from ._scenario import Scenario as Scenario
from ._scenario import load_scenario as load_scenario

__all__ = [
    "SCENARIO_SCHEMA",
    "Scenario",
    "ScenarioResult",
    "build_controller",
    "build_events",
    "load_scenario",
    "run_scenario",
    "simulate_kwargs",
    "write_outputs",
]
