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


def _legend(ax: Any, labels: Sequence[str] | None, count: int) -> None:
    """A legend outside the axes on the right (never over the curves or the event labels)."""
    if not labels or count == 0:
        return
    ncol = 1 if count <= 10 else 2 if count <= 24 else 3
    ax.legend(list(labels)[:count], fontsize=6, ncol=ncol, loc="upper left",
              bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0, frameon=False)


def _unit_text(units: Sequence[str]) -> str:
    seen = [u for u in dict.fromkeys(units) if u != "?"]
    return ", ".join(seen) if seen else "?"


def _coordinate_names(traj: Any, model: Model | None) -> list[str] | None:
    if model is not None:
        return list(model.coordinate_names)
    names = getattr(traj, "coordinate_names", None)
    if names:
        return list(names)
    meta = getattr(traj, "metadata", None) or {}
    coords = meta.get("coordinate_names") if isinstance(meta, dict) else None
    return list(coords) if coords else None


def plot_trajectory(traj: Any, model: Model | None = None, *, title: str | None = None) -> Any:
    """Plot a :class:`~nonmin.sim.Trajectory`: coordinates, velocities, constraint forces,
    rank of the active A with cond(M̄), μ and σ_r/σ₁, and the energy balance with the
    constraint residuals, with events marked.

    Every curve is labelled with its coordinate and unit (m, rad; rates m/s, rad/s;
    generalized forces N, N·m). The rank axis has integer ticks. σ_r/σ₁ is computed on the
    constraints active at each sample (:func:`~nonmin.viz.singularity_distance`). The energy
    panel shows the drift ``|E − E₀ − W − W_fr + L_imp|`` where W is the work of actuators,
    controllers, dampers and drivers, W_fr the work of Coulomb friction and L_imp the energy
    lost at impacts (:func:`~nonmin.viz.energy_balance`), next to |W|, |W_fr| and L_imp.

    Parameters
    ----------
    traj : Trajectory
        Result of :func:`nonmin.sim.simulate` (or a loaded one).
    model : Model, optional
        The model the trajectory came from: needed for σ_r/σ₁ and the work W (without it the
        energy panel shows ``|E − E₀|`` and says so).
    title : str, optional

    Returns
    -------
    matplotlib.figure.Figure
    """
    plt = pyplot()
    from matplotlib.ticker import FixedLocator, MaxNLocator

    from ._diagnostics import (
        coordinate_units,
        energy_balance,
        force_unit,
        singularity_distance,
        velocity_unit,
    )

    t = np.asarray(traj.t)
    names = _coordinate_names(traj, model)
    events = _event_times(traj)
    fig, axes = plt.subplots(5, 1, figsize=(10, 12.5), sharex=True, constrained_layout=True)
    q = _field(traj, "q")
    qd = _field(traj, "qd")
    fc = _field(traj, "f_c")
    n = q.shape[1] if q is not None and q.ndim == 2 else 0
    names = names if names is not None and len(names) == n else [f"q{i}" for i in range(n)]
    units = coordinate_units(model, names) if n else ()
    for ax, data, sym, unit_of in (
        (axes[0], q, "q", lambda u: u),
        (axes[1], qd, "q̇", velocity_unit),
        (axes[2], fc, "f_c", force_unit),
    ):
        if data is None or data.size == 0:
            ax.set_ylabel(sym)
            continue
        us = [unit_of(u) for u in units]
        ax.plot(t, data, lw=1)
        _legend(ax, [f"{c} [{u}]" for c, u in zip(names, us, strict=True)], data.shape[1])
        label = {"q": "coordinates q", "q̇": "velocities q̇",
                 "f_c": "constraint forces f_c\n(generalized)"}[sym]
        ax.set_ylabel(f"{label} [{_unit_text(us)}]")
    ax = axes[3]
    rank = _field(traj, "rank")
    cond = _field(traj, "cond_mbar", "cond")
    mu = _field(traj, "mu")
    handles = []
    if rank is not None and rank.size:
        handles += ax.step(t, rank, where="post", color="C0", label="rank of active A")
        ax.set_ylabel("rank of active A", color="C0")
        lo, hi = int(np.min(rank)), int(np.max(rank))
        ax.set_ylim(lo - 0.5, hi + 0.5)
        if hi - lo <= 12:  # every rank met, and only integers (also when the rank is constant)
            ax.yaxis.set_major_locator(FixedLocator(list(range(lo, hi + 1))))
        else:
            ax.yaxis.set_major_locator(MaxNLocator(integer=True, min_n_ticks=1))
    ax2 = ax.twinx()
    if cond is not None and cond.size:
        handles += ax2.semilogy(t, np.maximum(cond, 1.0), color="C1", lw=1, label="cond(M̄)")
    if mu is not None and mu.size:
        handles += ax2.semilogy(t, np.maximum(np.abs(mu), 1e-300), color="C2", lw=1,
                                label="μ [kg, kg·m²]")
    ratio = singularity_distance(traj, model) if model is not None else None
    if ratio is not None and np.isfinite(ratio).any():
        handles += ax2.semilogy(t, np.maximum(ratio, 1e-17), color="C3", lw=1,
                                label="σ_r/σ₁ of active A")
    ax2.set_ylabel("cond(M̄), μ, σ_r/σ₁ (log)")
    if handles:
        ax.legend(handles=handles, fontsize=6, loc="upper left", bbox_to_anchor=(1.17, 1.0),
                  borderaxespad=0.0, frameon=False)
    ax = axes[4]
    bal = energy_balance(traj, model)
    if bal is not None:
        if bal.known:
            ax.semilogy(t, np.maximum(np.abs(bal.balance), 1e-17), lw=1,
                        label="drift |E − E₀ − W − W_fr + L_imp| [J]")
            if np.max(np.abs(bal.work)) > 0:
                ax.semilogy(t, np.maximum(np.abs(bal.work), 1e-17), lw=1, ls=":", color="0.4",
                            label="|W| work of forces, controllers, drivers [J]")
        else:
            ax.semilogy(t, np.maximum(np.abs(bal.balance), 1e-17), lw=1,
                        label="|E − E₀ − W_fr + L_imp| [J] (no model: W not subtracted)")
        if np.max(np.abs(bal.friction)) > 0:
            ax.semilogy(t, np.maximum(np.abs(bal.friction), 1e-17), lw=1, ls="--", color="0.55",
                        label="|W_fr| work of friction (slip) [J]")
        if np.max(np.abs(bal.impacts)) > 0:
            ax.semilogy(t, np.maximum(np.abs(bal.impacts), 1e-17), lw=1, ls="-.", color="0.25",
                        label="L_imp energy lost at impacts [J]")
    phi = _field(traj, "phi_norm", "position_residual_norm")
    if phi is not None and phi.size:
        ax.semilogy(t, np.maximum(phi, 1e-17), label="‖φ‖ position residual [m, rad]", lw=1)
    vel = _field(traj, "velocity_residual_norm", "velocity_residual")
    if vel is not None and vel.size:
        ax.semilogy(t, np.maximum(vel, 1e-17), label="‖A q̇ + φ_t‖ [m/s, rad/s]", lw=1)
    ax.set_ylabel("energy balance,\nresiduals (log)")
    ax.legend(fontsize=6, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0,
              frameon=False)
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


def _draw_prims(ax: Any, prims: Sequence[Any], lo: np.ndarray, hi: np.ndarray, alpha: float) -> None:
    """Draw 2-D scene primitives (:mod:`._scene`) with matplotlib."""
    from ._scene import clip_line

    for p in prims:
        col = "0.75" if not p.active else None
        if p.kind == "bar":
            ax.plot(p.pts[:, 0], p.pts[:, 1], "-", lw=3.5, color=col or "C0", alpha=alpha,
                    solid_capstyle="round", zorder=3)
        elif p.kind in ("rod", "spring"):
            ax.plot(p.pts[:, 0], p.pts[:, 1], "-", lw=1.2, color=col or ("C2" if p.kind == "spring" else "0.15"),
                    alpha=alpha, zorder=2)
        elif p.kind in ("guide", "wall"):
            seg = clip_line(p.pts[0], p.pts[1], lo, hi) if p.infinite else p.pts
            if seg is None:
                continue
            ax.plot(seg[:, 0], seg[:, 1], "-" if p.kind == "wall" else "--", color=col or "0.35",
                    lw=3 if p.kind == "wall" else 1.2, alpha=alpha, zorder=1)
        elif p.kind == "pin":
            ax.plot(*p.pts[0], marker="^", ms=11, mfc="none", mec="0.25", alpha=alpha, zorder=1)
        elif p.kind in ("joint", "closure"):
            ax.plot(*p.pts[0], "o", ms=6, mfc="white", mec=col or ("C3" if p.kind == "closure" else "0.1"),
                    alpha=alpha, zorder=5)
        elif p.kind == "mass":
            ax.plot(*p.pts[0], "o", ms=10, color=col or "0.15", alpha=alpha, zorder=5)
        elif p.kind == "block":
            ax.plot(*p.pts[0], "s", ms=12, mfc="C1", mec="0.1", alpha=alpha, zorder=4)


def plot_snapshot(
    model: Model, qs: np.ndarray | Sequence[np.ndarray], *, title: str | None = None
) -> Any:
    """Draw the mechanism at one or several configurations (later ones darker).

    Planar models (and spatial ones moving in a coordinate plane) are drawn element by element
    as in :func:`~nonmin.viz.animate` (ground pins, walls, guides, sliders, ...); other
    spatial models as 3-D segments with equal axis scales.

    Parameters
    ----------
    model : Model
        A model whose :meth:`~nonmin.model.Model.geometry` is not None.
    qs : array_like, shape (n,) or (s, n)

    Returns
    -------
    matplotlib.figure.Figure
    """
    from ._scene import model_scene, scene_bounds

    plt = pyplot()
    qarr = np.atleast_2d(np.asarray(qs, dtype=float))
    geoms = [model.geometry(q) for q in qarr]
    if any(g is None for g in geoms):
        raise InputError(f"model {model.name!r} has no geometry to draw")
    gs: list[Geometry] = [g for g in geoms if g is not None]
    scene = model_scene(model, list(qarr))
    fig = plt.figure(figsize=(6, 5), constrained_layout=True)
    if scene.dim == 2:
        ax = fig.add_subplot(111)
        frames = [scene.frame(q) for q in qarr]
        lo, hi = scene_bounds(scene, frames)
        _draw_prims(ax, scene.static, lo, hi, 1.0)
        for i, prims in enumerate(frames):
            _draw_prims(ax, prims, lo, hi, 0.25 + 0.75 * (i + 1) / len(frames))
        ax.set_xlim(lo[0], hi[0])
        ax.set_ylim(lo[1], hi[1])
        ax.set_aspect("equal")
        ax.grid(True, lw=0.3)
        ax.set_xlabel(f"{scene.axes[0]} [m]")
        ax.set_ylabel(f"{scene.axes[1]} [m]")
    else:
        ax = fig.add_subplot(111, projection="3d")
        for i, g in enumerate(gs):
            draw_geometry(ax, g, color="C0", alpha=0.25 + 0.75 * (i + 1) / len(gs))
        lo, hi = _bounds(gs)
        ax.set_xlim(lo[0], hi[0])
        ax.set_ylim(lo[1], hi[1])
        ax.set_zlim(lo[2], hi[2])
        ax.set_box_aspect(tuple(np.maximum(hi - lo, 1e-9)))
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
        if fmt == "png":
            _layout_once(fig, dpi_v)
        with atomic_path(p) as tmp:
            fig.savefig(tmp, dpi=dpi_v, format=fmt)
    finally:
        plt.close(fig)
    return p


def _layout_once(fig: Any, dpi: float) -> None:
    """Run the figure's constrained (or tight) layout once, at the image's dpi, and fix it.

    ``savefig`` with a layout engine draws the figure twice (a draw without output to run the
    layout, then the real draw, which runs the layout again); a figure saved once and then
    closed needs the layout once. The PNG has the same pixels (the layout is computed with
    the same Agg renderer at the same dpi; checked on the trajectory plots and 2-D and 3-D
    snapshots of the demo scenarios and library models) in 0.75x the CPU time. Other formats
    (vector backends measure text their own way) keep ``savefig``'s own path.
    """
    import matplotlib as mpl
    from matplotlib.layout_engine import ConstrainedLayoutEngine, TightLayoutEngine

    engine = fig.get_layout_engine()
    if not isinstance(engine, ConstrainedLayoutEngine | TightLayoutEngine):
        return
    if mpl.rcParams["savefig.bbox"] == "tight" or type(fig.canvas).__name__ != "FigureCanvasAgg":
        return
    fig.set_dpi(dpi)
    engine.execute(fig)
    with mpl.rc_context({"figure.autolayout": False, "figure.constrained_layout.use": False}):
        fig.set_layout_engine(None)  # None under these settings: no engine, no second layout
