"""Scenario files (TOML) and their execution (used by the command line); exports of
trajectories to CSV, Parquet and xarray/NetCDF."""

from .._export import columns as columns
from .._export import coordinate_units as coordinate_units
from .._export import to_csv as to_csv
from .._export import to_netcdf as to_netcdf
from .._export import to_parquet as to_parquet
from .._export import to_xarray as to_xarray
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
    "columns",
    "coordinate_units",
    "load_scenario",
    "run_scenario",
    "simulate_kwargs",
    "to_csv",
    "to_netcdf",
    "to_parquet",
    "to_xarray",
    "write_outputs",
]
