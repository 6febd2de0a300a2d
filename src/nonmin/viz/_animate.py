"""Animations of planar (2D) and spatial (3D) mechanisms, drawn element by element."""

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

__all__ = ["DEFAULT_FPS", "animate", "frame_geometries", "frame_times"]


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


#: Default frame rate of animations [frames/s] (``nonmin run`` and ``nonmin animate`` alike).
DEFAULT_FPS = 20.0


def frame_times(t: np.ndarray, *, fps: float = DEFAULT_FPS, speed: float = 1.0,
                max_frames: int = 400) -> np.ndarray:
    """The times of the animation frames: ``round(duration / speed · fps) + 1`` evenly spaced
    times (at least 2, at most ``max_frames``; one for a single sample)."""
    t = np.asarray(t, dtype=float)
    duration = float(t[-1] - t[0]) if t.size else 0.0
    count = int(np.clip(round(duration / speed * fps) + 1, 2, max_frames)) if duration > 0 else 1
    return np.linspace(t[0], t[-1], count)


class Progress:
    """Progress of a long job on stderr: silent for the first ``after`` seconds, then a line
    every ``every`` seconds and a last one with the total time."""

    def __init__(self, what: str, enabled: bool | None = True, after: float = 2.0,
                 every: float = 2.0) -> None:
        import time

        self.what, self.enabled, self.after, self.every = what, enabled is not False, after, every
        self._clock = time.perf_counter
        self.t0 = self._clock()
        self._last = self.t0
        self.shown = False

    def __call__(self, done: int, total: int) -> None:
        if not self.enabled:
            return
        now = self._clock()
        if now - self.t0 < self.after or (now - self._last < self.every and done < total):
            return
        import sys

        self._last = now
        self.shown = True
        print(f"    {self.what}: {done}/{total} frames, {now - self.t0:.1f} s", file=sys.stderr, flush=True)


def _check_options(fps: float, speed: float, dpi: float, max_frames: int) -> None:
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


def _frame_states(traj: Any, tf: np.ndarray) -> tuple[np.ndarray, list[frozenset[str] | None], list[str]]:
    """Interpolated q, the active set and the event label of every frame time."""
    t = np.asarray(traj.t, dtype=float)
    q = np.asarray(traj.q, dtype=float)
    qf = np.stack([np.interp(tf, t, q[:, j]) for j in range(q.shape[1])], axis=1)
    idx = np.clip(np.searchsorted(t, tf, side="right") - 1, 0, len(t) - 1)
    mask = getattr(traj, "active_mask", None)
    names = tuple(getattr(traj, "constraint_names", ()))
    actives: list[frozenset[str] | None] = []
    cache: dict[int, frozenset[str]] = {}
    for i in idx:
        if mask is None or not len(names):
            actives.append(None)
            continue
        if int(i) not in cache:
            cache[int(i)] = frozenset(n for n, a in zip(names, mask[i], strict=True) if a)
        actives.append(cache[int(i)])
    events = _event_times(traj)
    texts = []
    for ti in tf:
        fired = [n for (te, n) in events if te <= ti]
        texts.append(f"t = {ti:6.3f} s" + (f"   last event: {fired[-1]}" if fired else ""))
    return qf, actives, texts


def animate(
    traj: Any,
    model: Model | Callable[[np.ndarray], Geometry | None],
    path: str | Path,
    *,
    fps: float = DEFAULT_FPS,
    speed: float = 1.0,
    max_frames: int = 400,
    title: str | None = None,
    dpi: int = 100,
    progress: bool | None = True,
) -> Path:
    """Write an animation (GIF or MP4) of a trajectory.

    Planar models are drawn element by element (bars, sliders, point masses, ground pins,
    walls and guides, rods, springs, loop-closure joints; see :mod:`nonmin.viz._scene`), with
    inactive constraints light; spatial models whose motion stays in a coordinate plane (a
    planar URDF loop) are drawn in 2-D in that plane; other spatial models in 3-D with equal
    axis scales. 2-D frames are drawn by Pillow on an axes background rendered once by
    matplotlib (~10 ms per frame).

    Parameters
    ----------
    traj : Trajectory
        Anything with ``t`` (T,) and ``q`` (T, n) (and, optionally, ``active_mask``,
        ``constraint_names``, ``events``).
    model : Model or callable
        The model (its elements or :meth:`geometry`) or a function ``q -> Geometry``.
    path : str or Path
        Output file, ``.gif`` (Pillow) or ``.mp4`` (ffmpeg from the ``video`` extra).
    fps, speed : float
        Frames per second and playback speed (2 = twice real time); the frame count is
        ``round(duration / speed · fps) + 1`` (:func:`frame_times`).
    max_frames : int
        Upper bound on the number of frames (long runs are sped up to fit).
    title : str, optional
    dpi : int
        Resolution of 3-D frames (2-D frames are 480 × 440 px).
    progress : bool, optional
        Report on stderr when rendering takes more than 2 s (default True).

    Returns
    -------
    Path
    """
    out = as_path(path, "animate: path")
    _check_options(fps, speed, dpi, max_frames)
    suffix = out.suffix.lower()
    if suffix not in (".gif", ".mp4"):
        raise InputError(f"animation file must end in .gif or .mp4, got {out.name!r}")
    if suffix == ".mp4":
        try:
            import imageio_ffmpeg  # noqa: F401
        except ImportError:
            raise missing_dependency("imageio-ffmpeg", "video", "Writing MP4 animations") from None
    geometry = model.geometry if isinstance(model, Model) else model
    if isinstance(model, Model) and np.shape(traj.q)[-1:] != (model.n,):
        raise InputError(
            f"animate: the trajectory has {np.shape(traj.q)[-1]} coordinates, the model "
            f"{model.name!r} has {model.n}: not the model this trajectory came from"
        )
    name = model.name if isinstance(model, Model) else "mechanism"
    tf, geoms = frame_geometries(geometry, traj.t, traj.q, fps=fps, speed=speed, max_frames=2)
    del geoms  # validates t, q and that the model has a geometry
    tf = frame_times(np.asarray(traj.t, dtype=float), fps=fps, speed=speed, max_frames=max_frames)
    qf, actives, texts = _frame_states(traj, tf)
    from ._scene import model_scene, scene_bounds

    picks = qf[:: max(1, len(qf) // 40)]
    scene = model_scene(model if isinstance(model, Model) else geometry, list(picks))
    report = Progress(f"rendering {out.name}", progress)
    if scene.dim == 2:
        from ._raster import Canvas2D, frames, write_gif, write_mp4

        prims = [scene.frame(qi, act) for qi, act in zip(qf, actives, strict=True)]
        statics = [scene.static_at(act) for act in actives]
        lo, hi = scene_bounds(scene, prims)
        pyplot()  # the plot extra is needed for the axes
        canvas = Canvas2D(scene, lo, hi, title or name)
        images = frames(canvas, prims, statics, texts, report)
    else:
        images = _frames_3d(geometry, qf, texts, title or name, dpi, report)
    with atomic_path(out) as tmp:
        if suffix == ".gif":
            from ._raster import write_gif

            write_gif(images, tmp, fps)
        else:
            from ._raster import write_mp4

            write_mp4(images, tmp, fps)
    return out


def _frames_3d(geometry: Callable[[np.ndarray], Geometry | None], qf: np.ndarray, texts: list[str],
               title: str, dpi: int, report: Callable[[int, int], None]) -> Any:
    """3-D frames drawn by matplotlib (equal axis scales), as RGB images."""
    from PIL import Image

    plt = pyplot()
    geoms = [geometry(qi) for qi in qf]
    gs: list[Geometry] = [g for g in geoms if g is not None]
    lo, hi = _bounds(gs)
    fig = plt.figure(figsize=(5.5, 5), dpi=dpi)
    try:
        ax = fig.add_subplot(111, projection="3d")
        ax.set_xlim(lo[0], hi[0])
        ax.set_ylim(lo[1], hi[1])
        ax.set_zlim(lo[2], hi[2])
        ax.set_box_aspect(tuple(np.maximum(hi - lo, 1e-9)))
        ax.set_xlabel("x [m]")
        ax.set_ylabel("y [m]")
        ax.set_zlabel("z [m]")
        ax.set_title(title)
        nseg = max(len(np.asarray(g.segments)) for g in gs)
        lines = [ax.plot([], [], [], "-", lw=3, color="C0")[0] for _ in range(nseg)]
        (pts,) = ax.plot([], [], [], "o", color="k", ms=3)
        label = ax.text2D(0.02, 0.95, "", transform=ax.transAxes)
        for i, g in enumerate(gs):
            seg = np.asarray(g.segments).reshape(-1, 2, 3)
            for j, ln in enumerate(lines):
                if j < len(seg):
                    ln.set_data_3d(seg[j][:, 0], seg[j][:, 1], seg[j][:, 2])
                else:
                    ln.set_data_3d([], [], [])
            p = np.asarray(g.points).reshape(-1, 3)
            pts.set_data_3d(p[:, 0], p[:, 1], p[:, 2])
            label.set_text(texts[i])
            fig.canvas.draw()
            rgba = np.asarray(fig.canvas.buffer_rgba())
            yield Image.fromarray(rgba[..., :3].copy())
            report(i + 1, len(gs))
    finally:
        plt.close(fig)
