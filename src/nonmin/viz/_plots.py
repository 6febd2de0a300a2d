"""Plots of trajectories and mechanism snapshots. Figures are returned, never shown."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .._files import as_path, atomic_path
from ..errors import InputError
from ..model._protocol import Geometry, Model
from ._mpl import pyplot

__all__ = ["draw_geometry", "plot_snapshot", "plot_trajectory", "save_figure"]


def _field(traj: Any, *names: str) -> np.ndarray | None:
    for name in names:
        val = getattr(traj, name, None)
        if val is not None:
            return np.asarray(val)
    return None


def _event_times(traj: Any) -> list[tuple[float, str]]:
    out: list[tuple[float, str]] = []
    for ev in getattr(traj, "events", ()) or ():
        t = getattr(ev, "t", None)
        if t is None:
            t = getattr(ev, "time", None)
        if t is None and isinstance(ev, dict):
            t = ev.get("t", ev.get("time"))
        name = getattr(ev, "name", None) or (ev.get("name") if isinstance(ev, dict) else "")
        if t is not None:
            out.append((float(t), str(name or "")))
    return out


def _mark_events(ax: Any, events: Sequence[tuple[float, str]], label: bool = False) -> None:
    for t, name in events:
        ax.axvline(t, color="0.5", lw=0.8, ls="--", zorder=0)
        if label and name:
            ax.annotate(
                name,
                (t, 1.0),
                xycoords=("data", "axes fraction"),
                rotation=90,
                fontsize=7,
                va="top",
                ha="right",
                color="0.35",
            )


def _legend(ax: Any, names: Sequence[str] | None, count: int) -> None:
    if names and count <= 12:
        ax.legend(list(names)[:count], fontsize=7, ncol=min(count, 6), loc="upper right")


def _singularity_distance(traj: Any, model: Model) -> np.ndarray | None:
    """σ_r/σ₁ of the (equilibrated) active A at every sample, r = the largest rank met.

    Dips towards 0 show the configurations where A loses rank (singular or change points),
    which the sampled rank itself rarely hits exactly.
    """
    from ..core import range_basis

    q = _field(traj, "q")
    rank = _field(traj, "rank")
    if q is None or rank is None or rank.size == 0 or int(np.max(rank)) == 0:
        return None
    rmax = int(np.max(rank))
    actives = getattr(traj, "active", None)
    out = np.empty(len(q))
    for i, qi in enumerate(q):
        act = actives[i] if actives is not None else None
        A = model.constraint_jacobian(float(traj.t[i]), qi, act)
        s = range_basis(A).s
        out[i] = s[rmax - 1] / s[0] if s.size >= rmax and s[0] > 0 else 0.0
    return out


def plot_trajectory(traj: Any, model: Model | None = None, *, title: str | None = None) -> Any:
    """Plot a :class:`~nonmin.sim.Trajectory`: coordinates, velocities, constraint forces,
    rank of A with cond(M̄) and μ, energy and constraint residuals, with events marked.

    Parameters
    ----------
    traj : Trajectory
        Result of :func:`nonmin.sim.simulate` (or a loaded one).
    model : Model, optional
        Used for coordinate names in legends.
    title : str, optional

    Returns
    -------
    matplotlib.figure.Figure
    """
    plt = pyplot()
    t = np.asarray(traj.t)
    names = list(model.coordinate_names) if model is not None else None
    if names is None:
        meta = getattr(traj, "metadata", None) or {}
        coords = meta.get("coordinate_names") if isinstance(meta, dict) else None
        names = list(coords) if coords else None
    events = _event_times(traj)
    fig, axes = plt.subplots(5, 1, figsize=(9, 12), sharex=True, constrained_layout=True)
    q = _field(traj, "q")
    qd = _field(traj, "qd")
    fc = _field(traj, "f_c")
    ax = axes[0]
    if q is not None:
        ax.plot(t, q, lw=1)
        _legend(ax, names, q.shape[1])
    ax.set_ylabel("q")
    ax = axes[1]
    if qd is not None:
        ax.plot(t, qd, lw=1)
    ax.set_ylabel("qd")
    ax = axes[2]
    if fc is not None and fc.size:
        ax.plot(t, fc, lw=1)
    ax.set_ylabel("f_c (generalized)")
    ax = axes[3]
    rank = _field(traj, "rank")
    cond = _field(traj, "cond_mbar", "cond")
    mu = _field(traj, "mu")
    if rank is not None:
        ax.step(t, rank, where="post", color="C0", label="rank A")
        ax.set_ylabel("rank A", color="C0")
        lo, hi = float(np.min(rank)), float(np.max(rank))
        ax.set_ylim(lo - 0.5, hi + 0.5)
    ax2 = ax.twinx()
    if cond is not None:
        ax2.semilogy(t, np.maximum(cond, 1.0), color="C1", lw=1, label="cond(M̄)")
    if mu is not None:
        ax2.semilogy(t, np.maximum(np.abs(mu), 1e-300), color="C2", lw=1, label="μ")
    ratio = _singularity_distance(traj, model) if model is not None else None
    if ratio is not None:
        ax2.semilogy(t, np.maximum(ratio, 1e-17), color="C3", lw=1, label="σ_r/σ₁ of A")
    ax2.set_ylabel("cond(M̄), μ, σ_r/σ₁")
    ax2.legend(fontsize=7, loc="upper right")
    ax = axes[4]
    energy = _field(traj, "energy")
    if energy is not None and energy.size:
        de = np.abs(energy - energy[0])
        ax.semilogy(t, np.maximum(de, 1e-17), label="|E − E₀| [J]", lw=1)
    phi = _field(traj, "phi_norm", "position_residual_norm")
    if phi is not None:
        ax.semilogy(t, np.maximum(phi, 1e-17), label="‖φ‖", lw=1)
    vel = _field(traj, "velocity_residual_norm", "velocity_residual")
    if vel is not None:
        ax.semilogy(t, np.maximum(vel, 1e-17), label="‖A qd + φ_t‖", lw=1)
    ax.set_ylabel("drift / residuals")
    ax.legend(fontsize=7, loc="upper right")
    ax.set_xlabel("t [s]")
    for i, a in enumerate(axes):
        _mark_events(a, events, label=(i == 0))
        a.grid(True, lw=0.3)
    fig.suptitle(title or (model.name if model is not None else "trajectory"))
    return fig


def draw_geometry(ax: Any, geom: Geometry, *, color: str = "C0", alpha: float = 1.0) -> list[Any]:
    """Draw one :class:`~nonmin.model.Geometry` on an axis (2D or 3D); returns the artists."""
    artists: list[Any] = []
    seg = np.asarray(geom.segments)
    pts = np.asarray(geom.points)
    for s in seg:
        if geom.dim == 2:
            (ln,) = ax.plot(
                s[:, 0], s[:, 1], "-", color=color, lw=3, alpha=alpha, solid_capstyle="round"
            )
        else:
            (ln,) = ax.plot(s[:, 0], s[:, 1], s[:, 2], "-", color=color, lw=3, alpha=alpha)
        artists.append(ln)
    if pts.size:
        if geom.dim == 2:
            artists.append(ax.plot(pts[:, 0], pts[:, 1], "o", color="k", ms=4, alpha=alpha)[0])
        else:
            artists.append(
                ax.plot(pts[:, 0], pts[:, 1], pts[:, 2], "o", color="k", ms=3, alpha=alpha)[0]
            )
    return artists


def _bounds(geoms: Sequence[Geometry]) -> tuple[np.ndarray, np.ndarray]:
    chunks = []
    for g in geoms:
        if np.asarray(g.segments).size:
            chunks.append(np.asarray(g.segments).reshape(-1, g.dim))
        if np.asarray(g.points).size:
            chunks.append(np.asarray(g.points).reshape(-1, g.dim))
    allp = np.vstack(chunks) if chunks else np.zeros((1, geoms[0].dim if geoms else 2))
    lo, hi = allp.min(axis=0), allp.max(axis=0)
    span = float(np.max(hi - lo)) or 1.0
    pad = 0.08 * span
    return lo - pad, hi + pad


def plot_snapshot(
    model: Model, qs: np.ndarray | Sequence[np.ndarray], *, title: str | None = None
) -> Any:
    """Draw the mechanism at one or several configurations (later ones darker).

    Parameters
    ----------
    model : Model
        A model whose :meth:`~nonmin.model.Model.geometry` is not None.
    qs : array_like, shape (n,) or (s, n)

    Returns
    -------
    matplotlib.figure.Figure
    """
    plt = pyplot()
    qarr = np.atleast_2d(np.asarray(qs, dtype=float))
    geoms = [model.geometry(q) for q in qarr]
    if any(g is None for g in geoms):
        raise InputError(f"model {model.name!r} has no geometry to draw")
    gs: list[Geometry] = [g for g in geoms if g is not None]
    dim = gs[0].dim
    fig = plt.figure(figsize=(6, 5), constrained_layout=True)
    ax = fig.add_subplot(111, projection="3d" if dim == 3 else None)
    for i, g in enumerate(gs):
        a = 0.25 + 0.75 * (i + 1) / len(gs)
        draw_geometry(ax, g, color="C0", alpha=a)
    lo, hi = _bounds(gs)
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    if dim == 2:
        ax.set_aspect("equal")
    else:
        ax.set_zlim(lo[2], hi[2])
    ax.set_title(title or model.name)
    return fig


def save_figure(fig: Any, path: str | Path, dpi: int = 110) -> Path:
    """Save a figure durably (temporary file, fsync, rename) and close it; returns the path.

    Raises
    ------
    InputError
        ``dpi`` is not a positive number or the file name has no image format Matplotlib knows.
    OutputError
        The file cannot be written (the previous file there is unchanged).
    """
    plt = pyplot()
    try:
        p = as_path(path, "save_figure: path")
    except InputError:
        plt.close(fig)
        raise
    try:
        dpi_v = float(dpi)
    except (TypeError, ValueError):
        dpi_v = float("nan")
    if not (math.isfinite(dpi_v) and 0 < dpi_v <= 2000):
        plt.close(fig)
        raise InputError(f"save_figure: dpi must be a number in (0, 2000], got {dpi!r}")
    fmt = p.suffix.lower().lstrip(".")
    if fmt not in fig.canvas.get_supported_filetypes():
        plt.close(fig)
        raise InputError(
            f"save_figure: cannot tell the image format of {str(p)!r}; expected one of "
            f"{sorted('.' + k for k in fig.canvas.get_supported_filetypes())}"
        )
    try:
        with atomic_path(p) as tmp:
            fig.savefig(tmp, dpi=dpi_v, format=fmt)
    finally:
        plt.close(fig)
    return p
