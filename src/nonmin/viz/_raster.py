"""Fast 2-D frames: matplotlib draws the axes once, Pillow draws the moving mechanism.

Drawing every frame with matplotlib costs 30–100 ms; here the axes, grid, labels and title
are rendered once (supersampled ×2), and each frame copies that background, draws the
primitives of :mod:`._scene` with ``PIL.ImageDraw`` in pixel coordinates from the axes'
``transData``, and halves the image (box filter: anti-aliasing). GIFs share one palette
(quantized once), MP4s go to ffmpeg through ``imageio-ffmpeg``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ._scene import Prim, Scene, clip_line

__all__ = ["Canvas2D", "write_gif", "write_mp4"]

_SS = 2  # supersampling factor

_COLORS = {
    "bar": (31, 119, 180),
    "rod": (40, 40, 40),
    "spring": (44, 160, 44),
    "joint_fill": (255, 255, 255),
    "joint_edge": (30, 30, 30),
    "mass": (30, 30, 30),
    "block": (255, 127, 14),
    "pin": (60, 60, 60),
    "wall": (90, 90, 90),
    "guide": (130, 130, 130),
    "closure": (214, 39, 40),
    "point": (148, 103, 189),
    "inactive": (190, 190, 190),
    "text": (0, 0, 0),
}


class Canvas2D:
    """A fixed 2-D view (limits, pixel size) onto which frames of a :class:`Scene` are drawn.

    Parameters
    ----------
    scene : Scene
        A 2-D scene.
    lo, hi : ndarray, shape (2,)
        Data limits [m].
    title : str
    size : (int, int)
        Output frame size in pixels (width, height).
    """

    def __init__(self, scene: Scene, lo: np.ndarray, hi: np.ndarray, title: str,
                 size: tuple[int, int] = (480, 440)) -> None:
        from PIL import Image

        from ._mpl import pyplot

        plt = pyplot()
        self.scene = scene
        self.size = size
        w, h = size
        dpi = 100
        fig = plt.figure(figsize=(w / dpi, h / dpi), dpi=dpi * _SS)
        try:
            ax = fig.add_axes((0.13, 0.1, 0.83, 0.8))
            ax.set_xlim(lo[0], hi[0])
            ax.set_ylim(lo[1], hi[1])
            ax.set_aspect("equal", adjustable="box")
            ax.grid(True, lw=0.4, color="0.85")
            ax.set_xlabel(f"{scene.axes[0]} [m]", fontsize=8)
            ax.set_ylabel(f"{scene.axes[1]} [m]", fontsize=8)
            ax.tick_params(labelsize=7)
            ax.set_title(title, fontsize=9)
            fig.canvas.draw()
            self.lo = np.array([ax.get_xlim()[0], ax.get_ylim()[0]])
            self.hi = np.array([ax.get_xlim()[1], ax.get_ylim()[1]])
            rgba = np.asarray(fig.canvas.buffer_rgba())
            self._bg = Image.fromarray(rgba[..., :3].copy())
            self._H = rgba.shape[0]
            self._trans = ax.transData.frozen()
            bbox = ax.get_window_extent()
            self._clip = (bbox.x0, self._H - bbox.y1, bbox.x1, self._H - bbox.y0)
        finally:
            plt.close(fig)
        p0 = self._px(np.zeros((1, 2)))[0]
        p1 = self._px(np.array([[1.0, 0.0]]))[0]
        self.ppm = float(abs(p1[0] - p0[0]))  # supersampled pixels per metre
        from PIL import ImageFont

        try:
            self._font = ImageFont.load_default(size=11 * _SS)
        except TypeError:  # Pillow < 10.1
            self._font = ImageFont.load_default()

    def _px(self, pts: np.ndarray) -> np.ndarray:
        d = self._trans.transform(np.asarray(pts, dtype=float).reshape(-1, 2))
        d[:, 1] = self._H - d[:, 1]
        return d

    # ------------------------------------------------------------------ primitives
    def _line(self, draw: Any, pts: np.ndarray, color: tuple[int, int, int], width: float,
              dash: float = 0.0, caps: bool = False) -> None:
        px = self._px(pts)
        w = max(1, round(width * _SS))
        if dash <= 0:
            draw.line([tuple(p) for p in px], fill=color, width=w)
        else:
            a, b = px[0], px[-1]
            length = float(np.hypot(*(b - a)))
            step = dash * _SS
            n = int(length // (2 * step)) + 1
            for k in range(n):
                s0, s1 = 2 * k * step / max(length, 1e-9), min(1.0, (2 * k + 1) * step / max(length, 1e-9))
                if s0 >= 1.0:
                    break
                draw.line([tuple(a + s0 * (b - a)), tuple(a + s1 * (b - a))], fill=color, width=w)
        if caps:
            r = w / 2
            for p in (px[0], px[-1]):
                draw.ellipse((p[0] - r, p[1] - r, p[0] + r, p[1] + r), fill=color)

    def _disc(self, draw: Any, p: np.ndarray, radius_px: float, fill: Any, outline: Any = None,
              width: float = 1.0) -> None:
        c = self._px(p.reshape(1, 2))[0]
        r = radius_px * _SS
        draw.ellipse((c[0] - r, c[1] - r, c[0] + r, c[1] + r), fill=fill, outline=outline,
                     width=max(1, round(width * _SS)))

    def _size_px(self, size: float, default: float) -> float:
        px = size * self.ppm / _SS if size > 0 else default
        return float(np.clip(px, 2.0, 14.0))

    def draw_prim(self, draw: Any, p: Prim) -> None:
        """Draw one primitive."""
        col = _COLORS.get(p.kind, _COLORS["bar"]) if p.active else _COLORS["inactive"]
        if p.kind == "bar":
            self._line(draw, p.pts, col, 4.0, caps=True)
        elif p.kind == "rod":
            self._line(draw, p.pts, col, 1.5)
        elif p.kind == "spring":
            a, b = p.pts
            d = b - a
            L = float(np.hypot(*d))
            if L > 0:
                u = d / L
                nrm = np.array([-u[1], u[0]])
                amp = max(p.size, 0.02 * L)
                k = 10
                zz = [a, a + 0.1 * d]
                for i in range(k):
                    s = 0.1 + 0.8 * (i + 0.5) / k
                    zz.append(a + s * d + (amp if i % 2 == 0 else -amp) * nrm)
                zz += [a + 0.9 * d, b]
                self._line(draw, np.array(zz), col, 1.2)
        elif p.kind == "guide":
            pts = p.pts
            if p.infinite:
                seg = clip_line(pts[0], pts[1], self.lo, self.hi)
                if seg is None:
                    return
                pts = seg
            self._line(draw, pts, col, 1.5, dash=5.0)
        elif p.kind == "wall":
            seg = clip_line(p.pts[0], p.pts[1], self.lo, self.hi)
            if seg is None:
                return
            self._line(draw, seg, col, 3.0)
            nrm = p.normal if p.normal is not None else np.array([0.0, -1.0])
            u = p.pts[1]
            L = float(np.linalg.norm(seg[1] - seg[0]))
            step = 10.0 / (self.ppm / _SS)  # a hatch every 10 px
            hlen = 7.0 / (self.ppm / _SS)
            for s in np.arange(0.0, L, step):
                q0 = seg[0] + s * u
                q1 = q0 - hlen * nrm - 0.6 * hlen * u
                self._line(draw, np.array([q0, q1]), col, 1.0)
        elif p.kind == "pin":
            c = self._px(p.pts[:1])[0]
            r = 7.0 * _SS
            draw.polygon([(c[0], c[1]), (c[0] - r, c[1] + 1.6 * r), (c[0] + r, c[1] + 1.6 * r)],
                         fill=None, outline=col, width=max(1, int(1.5 * _SS)))
            y = c[1] + 1.6 * r
            draw.line([(c[0] - 1.4 * r, y), (c[0] + 1.4 * r, y)], fill=col, width=max(1, int(1.5 * _SS)))
            for k in range(-3, 4):
                x = c[0] + k * 0.4 * r
                draw.line([(x, y), (x - 0.4 * r, y + 0.5 * r)], fill=col, width=_SS)
        elif p.kind == "joint":
            rad = self._size_px(p.size, 3.5)
            self._disc(draw, p.pts[0], rad, _COLORS["joint_fill"],
                       _COLORS["joint_edge"] if p.active else _COLORS["inactive"], 1.2)
        elif p.kind == "closure":
            rad = self._size_px(p.size, 4.0)
            self._disc(draw, p.pts[0], rad, None, col, 1.8)
        elif p.kind == "mass":
            rad = self._size_px(p.size, 6.0)
            self._disc(draw, p.pts[0], max(rad, 5.0), col)
        elif p.kind == "point":
            self._disc(draw, p.pts[0], 2.0, col)
        elif p.kind == "block":
            half = self._size_px(p.size, 9.0) * _SS
            half = max(half, 7.0 * _SS)
            c = self._px(p.pts[:1])[0]
            ca, sa = math.cos(p.angle), math.sin(p.angle)
            corners = []
            for sx, sy in ((-1, -0.6), (1, -0.6), (1, 0.6), (-1, 0.6)):
                x, y = sx * half, sy * half
                corners.append((c[0] + ca * x - sa * y, c[1] - (sa * x + ca * y)))
            draw.polygon(corners, fill=col, outline=_COLORS["joint_edge"])

    def render(self, prims: Sequence[Prim], static: Sequence[Prim], text: str) -> Any:
        """One frame (RGB ``PIL.Image`` of :attr:`size`)."""
        from PIL import ImageDraw

        img = self._bg.copy()
        draw = ImageDraw.Draw(img)
        order = {"wall": 0, "guide": 1, "pin": 2, "spring": 3, "rod": 4, "bar": 5, "block": 6,
                 "mass": 7, "joint": 8, "closure": 9, "point": 10}
        for p in sorted((*static, *prims), key=lambda p: order.get(p.kind, 5)):
            self.draw_prim(draw, p)
        x0, y0, _, _ = self._clip
        draw.text((x0 + 6 * _SS, y0 + 4 * _SS), text, fill=_COLORS["text"], font=self._font)
        return img.reduce(_SS)


def frames(canvas: Canvas2D, prims: Sequence[Sequence[Prim]], statics: Sequence[Sequence[Prim]],
           texts: Sequence[str], progress: Callable[[int, int], None] | None = None) -> Iterator[Any]:
    """Render every frame (a generator of RGB images)."""
    count = len(prims)
    for i in range(count):
        yield canvas.render(prims[i], statics[i], texts[i])
        if progress is not None:
            progress(i + 1, count)


def write_gif(images: Iterator[Any], path: Path, fps: float) -> int:
    """Write RGB frames to a GIF with one shared palette; returns the frame count."""
    from PIL import Image

    imgs = list(images)
    if not imgs:
        raise ValueError("no frames")
    # one palette for all frames: quantize a strip of the first, middle and last frames
    w, h = imgs[0].size
    picks = [imgs[0], imgs[len(imgs) // 2], imgs[-1]]
    strip = Image.new("RGB", (w, h * len(picks)))
    for k, im in enumerate(picks):
        strip.paste(im, (0, k * h))
    pal = strip.quantize(colors=64, method=Image.Quantize.MEDIANCUT)
    pframes = [im.quantize(palette=pal, dither=Image.Dither.NONE) for im in imgs]
    duration = round(1000.0 / fps)
    pframes[0].save(path, format="GIF", save_all=True, append_images=pframes[1:],
                    duration=duration, loop=0, optimize=False, disposal=1)
    return len(pframes)


def write_mp4(images: Iterator[Any], path: Path, fps: float) -> int:
    """Write RGB frames to an H.264 MP4 through imageio-ffmpeg; returns the frame count."""
    from ..errors import missing_dependency

    try:
        import imageio_ffmpeg
    except ImportError:
        raise missing_dependency("imageio-ffmpeg", "video", "Writing MP4 animations") from None
    writer = None
    count = 0
    try:
        for im in images:
            arr = np.asarray(im)
            if writer is None:
                h, w = arr.shape[:2]
                writer = imageio_ffmpeg.write_frames(
                    str(path), (w, h), fps=float(fps), codec="libx264", pix_fmt_out="yuv420p",
                    macro_block_size=2, quality=7, ffmpeg_log_level="error", output_params=["-f", "mp4"],
                )
                writer.send(None)
            writer.send(np.ascontiguousarray(arr))
            count += 1
    finally:
        if writer is not None:
            writer.close()
    return count
