"""Animations of planar (2D) and spatial (3D) mechanisms, drawn from the model's geometry."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from .._files import as_path, atomic_path
from ..errors import InputError, missing_dependency
from ..model._protocol import Geometry, Model
from ._mpl import pyplot
from ._plots import _bounds, _event_times

__all__ = ["animate", "frame_geometries"]


def frame_geometries(
    geometry: Callable[[np.ndarray], Geometry | None],
    t: np.ndarray,
    q: np.ndarray,
    *,
    fps: float = 25.0,
    speed: float = 1.0,
    max_frames: int = 400,
) -> tuple[np.ndarray, list[Geometry]]:
    """Sample a trajectory at the animation frame rate and evaluate the geometry.

    Returns the frame times and one :class:`~nonmin.model.Geometry` per frame. Configurations
    are linearly interpolated between samples.
    """
    t = np.asarray(t, dtype=float)
    q = np.asarray(q, dtype=float)
    if t.ndim != 1 or q.ndim != 2 or q.shape[0] != t.shape[0] or t.size < 1:
        raise InputError(
            f"animate: need t shape (T,) and q shape (T, n), got {t.shape} and {q.shape}"
        )
    if not (np.isfinite(t).all() and np.isfinite(q).all()):
        raise InputError("animate: the trajectory's t and q must be finite")
    if np.any(np.diff(t) < 0):
        raise InputError("animate: the trajectory's times t must be non-decreasing")
    duration = float(t[-1] - t[0])
    count = int(np.clip(round(duration / speed * fps) + 1, 2, max_frames)) if duration > 0 else 1
    tf = np.linspace(t[0], t[-1], count)
    qf = np.stack([np.interp(tf, t, q[:, j]) for j in range(q.shape[1])], axis=1)
    geoms: list[Geometry] = []
    for qi in qf:
        g = geometry(qi)
        if g is None:
            raise InputError("animate: the model has no geometry (model.geometry(q) returned None)")
        geoms.append(g)
    return tf, geoms


def _writer(path: Path, fps: float) -> Any:
    from matplotlib import animation

    suffix = path.suffix.lower()
    if suffix == ".gif":
        return animation.PillowWriter(fps=round(fps))
    if suffix == ".mp4":
        import matplotlib as mpl

        try:
            import imageio_ffmpeg
        except ImportError:
            raise missing_dependency("imageio-ffmpeg", "video", "Writing MP4 animations") from None
        mpl.rcParams["animation.ffmpeg_path"] = imageio_ffmpeg.get_ffmpeg_exe()
        return animation.FFMpegWriter(
            fps=round(fps), codec="libx264", extra_args=["-pix_fmt", "yuv420p"]
        )
    raise InputError(f"animation file must end in .gif or .mp4, got {path.name!r}")


def animate(
    traj: Any,
    model: Model | Callable[[np.ndarray], Geometry | None],
    path: str | Path,
    *,
    fps: float = 25.0,
    speed: float = 1.0,
    max_frames: int = 400,
    title: str | None = None,
    dpi: int = 80,
) -> Path:
    """Write an animation (GIF or MP4) of a trajectory.

    Parameters
    ----------
    traj : Trajectory
        Anything with ``t`` (T,) and ``q`` (T, n).
    model : Model or callable
        The model (its :meth:`geometry`) or a function ``q -> Geometry``.
    path : str or Path
        Output file, ``.gif`` (Pillow) or ``.mp4`` (ffmpeg from the ``video`` extra).
    fps, speed : float
        Frames per second and playback speed (2 = twice real time).
    max_frames : int
        Upper bound on the number of frames (long runs are sped up to fit).

    Returns
    -------
    Path
    """
    plt = pyplot()
    from matplotlib import animation

    out = as_path(path, "animate: path")
    for name_, val, top in (("fps", fps, 1000.0), ("speed", speed, 1e6), ("dpi", dpi, 2000.0)):
        try:
            val_f = float(val)
        except (TypeError, ValueError):
            val_f = float("nan")
        if not (np.isfinite(val_f) and 0 < val_f <= top):
            raise InputError(f"animate: {name_} must be a number in (0, {top:g}], got {val!r}")
    if isinstance(max_frames, bool) or not isinstance(max_frames, int | np.integer) or not 1 <= max_frames <= 100_000:
        raise InputError(f"animate: max_frames must be an integer in [1, 100000], got {max_frames!r}")
    if round(fps) < 1:
        raise InputError(f"animate: fps must be at least 1 frame per second once rounded, got {fps!r}")
    writer = _writer(out, fps)
    geometry = model.geometry if isinstance(model, Model) else model
    if isinstance(model, Model) and np.shape(traj.q)[-1:] != (model.n,):
        raise InputError(
            f"animate: the trajectory has {np.shape(traj.q)[-1]} coordinates, the model "
            f"{model.name!r} has {model.n}: not the model this trajectory came from"
        )
    name = model.name if isinstance(model, Model) else "mechanism"
    tf, geoms = frame_geometries(
        geometry, traj.t, traj.q, fps=fps, speed=speed, max_frames=max_frames
    )
    dim = geoms[0].dim
    lo, hi = _bounds(geoms)
    fig = plt.figure(figsize=(5.5, 5), constrained_layout=True)
    ax = fig.add_subplot(111, projection="3d" if dim == 3 else None)
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    if dim == 2:
        ax.set_aspect("equal")
        ax.grid(True, lw=0.3)
    else:
        ax.set_zlim(lo[2], hi[2])
    nseg = max(len(g.segments) for g in geoms)
    if dim == 2:
        lines = [
            ax.plot([], [], "-", lw=3, color="C0", solid_capstyle="round")[0] for _ in range(nseg)
        ]
        (pts,) = ax.plot([], [], "o", color="k", ms=4)
    else:
        lines = [ax.plot([], [], [], "-", lw=3, color="C0")[0] for _ in range(nseg)]
        (pts,) = ax.plot([], [], [], "o", color="k", ms=3)
    label = (
        ax.text2D(0.02, 0.95, "", transform=ax.transAxes)
        if dim == 3
        else ax.text(0.02, 0.95, "", transform=ax.transAxes)
    )
    events = _event_times(traj)
    ax.set_title(title or name)

    def update(i: int) -> list[Any]:
        g = geoms[i]
        seg = np.asarray(g.segments)
        for j, ln in enumerate(lines):
            if j < len(seg):
                if dim == 2:
                    ln.set_data(seg[j][:, 0], seg[j][:, 1])
                else:
                    ln.set_data_3d(seg[j][:, 0], seg[j][:, 1], seg[j][:, 2])
            elif dim == 2:
                ln.set_data([], [])
            else:
                ln.set_data_3d([], [], [])
        p = np.asarray(g.points)
        if p.size:
            if dim == 2:
                pts.set_data(p[:, 0], p[:, 1])
            else:
                pts.set_data_3d(p[:, 0], p[:, 1], p[:, 2])
        fired = [n for (te, n) in events if te <= tf[i]]
        label.set_text(f"t = {tf[i]:.3f} s" + (f"   last event: {fired[-1]}" if fired else ""))
        return [*lines, pts, label]

    anim = animation.FuncAnimation(fig, update, frames=len(geoms), blit=False)
    try:
        with atomic_path(out) as tmp:
            anim.save(str(tmp), writer=writer, dpi=dpi)
    finally:
        plt.close(fig)
    return out
