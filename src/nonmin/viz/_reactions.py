"""Plot of one constraint's reaction (force and torque on both bodies) over time."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from ..errors import InputError
from ._mpl import pyplot

__all__ = ["plot_reaction"]


def plot_reaction(reaction: Any, t: ArrayLike | None = None, *, title: str | None = None) -> Any:
    """Force and torque components of a :class:`nonmin.analysis.Reaction` against time.

    One row per body (a, b), forces left and torques right, in the body frames; undetermined
    components (redundant constraints) are drawn dashed. Returns the figure (never shown).

    Parameters
    ----------
    reaction : Reaction
        Per-sample reaction (``Trajectory.with_reactions(model).reactions[name]``).
    t : array_like, shape (N,), optional
        Sample times (default the sample index).
    title : str, optional
    """
    fa = np.asarray(reaction.force_a)
    if fa.ndim != 2:
        raise InputError("plot_reaction needs a per-sample Reaction (arrays of shape (N, d))")
    N = fa.shape[0]
    x = np.arange(N) if t is None else np.asarray(t, dtype=float)
    if x.shape != (N,):
        raise InputError(f"t must have shape ({N},), got shape {x.shape}")
    plt = pyplot()
    fig, axes = plt.subplots(2, 2, figsize=(9, 5.5), sharex=True, squeeze=False)
    comps = "xyz"
    for row, side in enumerate(("a", "b")):
        force = np.asarray(getattr(reaction, f"force_{side}"))
        torque = np.asarray(getattr(reaction, f"torque_{side}"))
        det = np.asarray(getattr(reaction, f"determined_{side}"))
        body = getattr(reaction, f"body_{side}") or side
        for col, (vals, label, off) in enumerate(((force, "F", 0), (torque, "τ", force.shape[1]))):
            ax = axes[row][col]
            for j in range(vals.shape[1]):
                style = "-" if det[:, off + j].all() else "--"
                name = f"{label}{comps[j] if vals.shape[1] > 1 else ''}"
                ax.plot(
                    x, vals[:, j], style, label=name + ("" if style == "-" else " (undetermined)")
                )
            ax.set_title(
                f"{label} on {body} ({'body' if body != 'ground' else 'world'} frame)", fontsize=9
            )
            if vals.shape[1]:
                ax.legend(fontsize=8)
            ax.grid(True, alpha=0.3)
    for ax in axes[1]:
        ax.set_xlabel("t [s]" if t is not None else "sample")
    fig.suptitle(title or f"reaction of {reaction.name!r}")
    fig.tight_layout()
    return fig
