"""Parameter sweeps: many runs over grids, random samples and lists of values, stored as they
finish, resumable, local or on a Dask cluster (extra ``sweep``: xarray, zarr, dask[distributed]).

:func:`sweep` builds the runs (:mod:`._spec`), simulates them in blocks — each block one
batched engine call (:func:`nonmin.sim.simulate_batch`) on a local thread or a Dask worker
(:mod:`._run`) — and writes every finished block to a Zarr store with an atomic commit record
(:mod:`._store`); :func:`open_sweep` reads the store as an xarray Dataset with dims
(run, time, coordinate); :func:`plot_sweep` draws a per-run metric over the swept keys.

Importing this package imports none of xarray, zarr or dask: they are imported when a sweep runs.
"""

from ._plot import plot_sweep as plot_sweep
from ._run import SweepResult as SweepResult
from ._run import open_sweep as open_sweep
from ._run import run_block as run_block
from ._run import sweep as sweep
from ._spec import Grid as Grid
from ._spec import SweepSpec as SweepSpec
from ._spec import Uniform as Uniform
from ._spec import parse_vary as parse_vary

__all__ = ["Grid", "SweepResult", "SweepSpec", "Uniform", "open_sweep", "parse_vary", "plot_sweep", "run_block", "sweep"]
