"""Plots, animations and the interactive 3-D viewer.

matplotlib (extra ``plot``) and viser (extra ``view``) are imported only when a function that
needs them runs: ``import nonmin.viz`` stays light. Figures are returned, never shown;
:func:`save_figure` writes and closes them.
"""

from ._animate import DEFAULT_FPS as DEFAULT_FPS
from ._animate import animate as animate
from ._animate import frame_geometries as frame_geometries
from ._animate import frame_times as frame_times
from ._diagnostics import EnergyBalance as EnergyBalance
from ._diagnostics import coordinate_units as coordinate_units
from ._diagnostics import energy_balance as energy_balance
from ._diagnostics import singularity_distance as singularity_distance
from ._plots import draw_geometry as draw_geometry
from ._plots import plot_snapshot as plot_snapshot
from ._plots import plot_trajectory as plot_trajectory
from ._plots import save_figure as save_figure
from ._reactions import plot_reaction as plot_reaction
from .view import Viewer as Viewer
from .view import view as view

__all__ = [
    "DEFAULT_FPS",
    "EnergyBalance",
    "Viewer",
    "animate",
    "coordinate_units",
    "draw_geometry",
    "energy_balance",
    "frame_geometries",
    "frame_times",
    "plot_reaction",
    "plot_snapshot",
    "plot_trajectory",
    "save_figure",
    "singularity_distance",
    "view",
]
