"""Plots and animations (the only package that imports matplotlib; extra ``plot``).

Figures are returned, never shown; :func:`save_figure` writes and closes them.
"""

from ._animate import animate as animate
from ._animate import frame_geometries as frame_geometries
from ._plots import draw_geometry as draw_geometry
from ._plots import plot_snapshot as plot_snapshot
from ._plots import plot_trajectory as plot_trajectory
from ._plots import save_figure as save_figure
from ._reactions import plot_reaction as plot_reaction

__all__ = [
    "animate",
    "draw_geometry",
    "frame_geometries",
    "plot_reaction",
    "plot_snapshot",
    "plot_trajectory",
    "save_figure",
]
