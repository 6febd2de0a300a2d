"""What a drawing of a model shows: every element the model has, as plain primitives.

A :class:`Scene` is built once per model (:func:`model_scene`) and gives, for a configuration
``q`` and an active set, the primitives of that frame; the static ones (ground pins, walls and
contact lines, guides fixed to the ground) are listed once. Renderers (the matplotlib
snapshot, the fast 2-D GIF/MP4 writer of :mod:`._raster`, the 3-D animation) only draw them.

Planar models (:class:`~nonmin.model.planar.PlanarModel`) map each element to its drawing:

=====================================  ===================================================
element                                drawing
=====================================  ===================================================
rigid body                             bars between its joint points (a polygon for 3+)
body with no extent (slider block)     an oriented block
point mass                             a filled disc
revolute joint to the ground           a ground pin (triangle and hatch), static
revolute joint between bodies          a joint circle (loop closures included)
point-on-line / prismatic on ground    a guide line (dashed), static
unilateral point-on-line on ground     a wall: a thick line hatched on its forbidden side
line on a moving body                  a guide segment moving with the body
rod (distance constraint)              a thin line between its points
spring                                 a zig-zag between its points
named point                            a small dot
=====================================  ===================================================

Inactive constraints are drawn light (a released pin, an open contact). Other models are drawn
from their :meth:`~nonmin.model.Model.geometry` (segments and points); a spatial model whose
geometry stays in a coordinate plane (a planar URDF loop) gets a 2-D scene in that plane.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = ["Prim", "Scene", "model_scene"]


@dataclass(frozen=True)
class Prim:
    """One drawing primitive.

    ``kind`` is one of ``bar``, ``rod``, ``spring``, ``joint``, ``mass``, ``block``, ``pin``,
    ``wall``, ``guide``, ``line`` (an infinite line: ``pts`` = point and direction), ``point``;
    ``pts`` its points (shape (k, dim)); ``size`` a length for blocks/pins [m] (0: renderer
    default); ``angle`` the orientation of a block [rad]; ``active`` False draws it light;
    ``label`` a name; ``normal`` the free side of a wall; ``infinite`` True for a line
    given as (point, unit direction) that the renderer clips to its view.
    """

    kind: str
    pts: np.ndarray
    size: float = 0.0
    angle: float = 0.0
    active: bool = True
    label: str = ""
    normal: np.ndarray | None = field(default=None)
    infinite: bool = False


@dataclass
class Scene:
    """The drawing of one model: static primitives and a function of (q, active)."""

    dim: int
    axes: tuple[str, ...]
    static: list[Prim]
    frame_fn: Callable[[np.ndarray, frozenset[str] | None], list[Prim]]
    scale: float = 1.0

    def frame(self, q: np.ndarray, active: Iterable[str] | None = None) -> list[Prim]:
        """The moving primitives at ``q`` with the constraints ``active`` (None: all active)."""
        return self.frame_fn(np.asarray(q, dtype=float), None if active is None else frozenset(active))

    def static_at(self, active: Iterable[str] | None) -> list[Prim]:
        """The static primitives, light where their constraint is inactive."""
        if active is None:
            return self.static
        act = frozenset(active)
        return [p if not p.label or p.label in act or p.kind == "line" else
                Prim(p.kind, p.pts, p.size, p.angle, False, p.label, p.normal, p.infinite)
                for p in self.static]


def _rot(th: float) -> np.ndarray:
    c, s = math.cos(th), math.sin(th)
    return np.array([[c, -s], [s, c]])


def _planar_scene(model: Any) -> Scene:
    from ..model.planar import GROUND, PointOnLine, Prismatic, Revolute, Rod, Weld

    offsets: dict[str, tuple[int, int]] = {}
    k = 0
    for b in model.bodies:
        offsets[b.name] = (k, b.ncoords)
        k += b.ncoords

    def pose(q: np.ndarray, body: str) -> tuple[np.ndarray, float]:
        i, nc = offsets[body]
        return q[i : i + 2], (float(q[i + 2]) if nc == 3 else 0.0)

    def point(q: np.ndarray, p: Any) -> np.ndarray:
        if p.body == GROUND:
            return np.asarray(p.local, dtype=float)
        r, th = pose(q, p.body)
        return r + _rot(th) @ np.asarray(p.local, dtype=float)

    # attachment points of each body (joints, springs, named points), as in model.geometry
    attach: dict[str, list[tuple[float, float]]] = {b.name: [] for b in model.bodies}

    def add(p: Any) -> None:
        if p.body != GROUND and tuple(p.local) not in attach[p.body]:
            attach[p.body].append(tuple(p.local))

    for j in model.joints:
        for attr in ("a", "b"):
            p = getattr(j, attr, None)
            if p is not None and hasattr(p, "body"):
                add(p)
    for f in model.forces:
        for attr in ("a", "b"):
            p = getattr(f, attr, None)
            if p is not None and hasattr(p, "body"):
                add(p)
    for _, p in model.points:
        add(p)

    # a length scale for symbols: the extent of the ground points and body attachments
    q0 = np.zeros(k)
    ext = [np.asarray(p.local) for j in model.joints for p in (getattr(j, "a", None), getattr(j, "b", None))
           if p is not None and hasattr(p, "body")]
    ext += [np.asarray(loc) for locs in attach.values() for loc in locs]
    span = float(np.ptp(np.array(ext), axis=0).max()) if len(ext) > 1 else 1.0
    scale = span if span > 1e-9 else 1.0
    sym = 0.05 * scale

    static: list[Prim] = []
    for j in model.joints:
        if isinstance(j, Revolute) and GROUND in (j.a.body, j.b.body):
            g = j.a if j.a.body == GROUND else j.b
            static.append(Prim("pin", np.array([g.local], dtype=float), size=sym, label=j.name))
        elif isinstance(j, PointOnLine | Prismatic) and j.a.body == GROUND:
            p0 = np.asarray(j.a.local, dtype=float)
            u = np.asarray(j.axis, dtype=float)
            u = u / np.linalg.norm(u)
            if isinstance(j, PointOnLine) and j.unilateral:
                normal = np.array([-u[1], u[0]])  # gap >= 0 on the left of the axis
                static.append(Prim("wall", np.array([p0, u]), size=sym, label=j.name, normal=normal,
                                   infinite=True))
            else:
                static.append(Prim("guide", np.array([p0, u]), size=sym, label=j.name, infinite=True))
    del q0

    def frame(q: np.ndarray, active: frozenset[str] | None) -> list[Prim]:
        def on(name: str) -> bool:
            return active is None or name in active

        out: list[Prim] = []
        for b in model.bodies:
            r, th = pose(q, b.name)
            R = _rot(th)
            locs = attach[b.name]
            glob = [r + R @ np.asarray(s) for s in locs]
            extent = max((float(np.hypot(*s)) for s in locs), default=0.0)
            if len(glob) >= 3:
                for i in range(len(glob)):
                    out.append(Prim("bar", np.array([glob[i], glob[(i + 1) % len(glob)]]), label=b.name))
            elif len(glob) == 2:
                out.append(Prim("bar", np.array(glob), label=b.name))
            elif len(glob) == 1 and extent > 1e-9 * scale:
                out.append(Prim("bar", np.array([r, glob[0]]), label=b.name))
            if b.inertia is None:
                out.append(Prim("mass", np.array([r]), size=0.6 * sym, label=b.name))
            elif extent <= 1e-9 * scale or (len(glob) <= 1 and extent < 0.5 * sym):
                out.append(Prim("block", np.array([r]), size=1.6 * sym, angle=th, label=b.name))
        for f in model.forces:
            pa, pb = getattr(f, "a", None), getattr(f, "b", None)
            if pa is not None and pb is not None:
                out.append(Prim("spring", np.array([point(q, pa), point(q, pb)]), size=0.5 * sym,
                                label=f.name))
        for j in model.joints:
            act = on(j.name)
            if isinstance(j, Revolute | Weld) and not isinstance(j, Weld):
                out.append(Prim("joint", np.array([point(q, j.a)]), size=0.35 * sym, active=act,
                                label=j.name))
            elif isinstance(j, Rod):
                out.append(Prim("rod", np.array([point(q, j.a), point(q, j.b)]), active=act, label=j.name))
                out.append(Prim("joint", np.array([point(q, j.a)]), size=0.3 * sym, active=act))
                out.append(Prim("joint", np.array([point(q, j.b)]), size=0.3 * sym, active=act))
            elif isinstance(j, PointOnLine | Prismatic):
                if j.a.body != GROUND:
                    _, th = pose(q, j.a.body)
                    u = _rot(th) @ np.asarray(j.axis, dtype=float)
                    u = u / np.linalg.norm(u)
                    pa = point(q, j.a)
                    half = max(3 * sym, float(np.linalg.norm(point(q, j.b) - pa)) + 2 * sym)
                    out.append(Prim("guide", np.array([pa - half * u, pa + half * u]), active=act,
                                    label=j.name))
                out.append(Prim("joint", np.array([point(q, j.b)]), size=0.3 * sym, active=act,
                                label=j.name))
        for name, p in model.points:
            out.append(Prim("point", np.array([point(q, p)]), size=0.2 * sym, label=name))
        return out

    return Scene(2, ("x", "y"), static, frame, scale)


def _plane_axes(points: np.ndarray) -> tuple[int, ...] | None:
    """The two coordinate axes a 3-D point cloud spans when it stays in a coordinate plane."""
    if points.size == 0:
        return None
    span = np.ptp(points, axis=0)
    top = float(span.max())
    if top <= 0:
        return None
    flat = [i for i in range(3) if span[i] <= 1e-9 * top]
    if len(flat) != 1:
        return None
    return tuple(i for i in range(3) if i != flat[0])


def _geometry_scene(model: Any, geometry: Callable[[np.ndarray], Any], samples: Sequence[np.ndarray]) -> Scene:
    g0 = geometry(samples[0])
    dim = int(g0.dim)
    keep: tuple[int, ...] = tuple(range(dim))
    if dim == 3:
        chunks = []
        for q in samples:
            g = geometry(q)
            chunks += [np.asarray(g.segments).reshape(-1, 3), np.asarray(g.points).reshape(-1, 3)]
        plane = _plane_axes(np.vstack(chunks))
        if plane is not None:
            keep = plane
    names = ("x", "y", "z")
    labels = tuple(getattr(g0, "labels", ()) or ())
    pts0 = np.asarray(g0.points).reshape(-1, dim)
    allp = np.vstack([np.asarray(g0.segments).reshape(-1, dim), pts0]) if pts0.size else np.asarray(g0.segments).reshape(-1, dim)
    span = float(np.ptp(allp, axis=0).max()) if allp.size else 1.0
    scale = span if span > 1e-9 else 1.0

    pm = getattr(model, "_pm", None)  # a robot: joints on the world frame get a ground pin
    grounded = {pm.names[j] for j in range(1, pm.njoints) if pm.parents[j] == 0} if pm is not None else set()

    def frame(q: np.ndarray, active: frozenset[str] | None) -> list[Prim]:
        g = geometry(q)
        seg = np.asarray(g.segments).reshape(-1, 2, dim)[:, :, keep]
        pts = np.asarray(g.points).reshape(-1, dim)[:, keep]
        out = [Prim("bar", s) for s in seg]
        labs = tuple(getattr(g, "labels", ()) or ())
        for i, p in enumerate(pts):
            lab = labs[i] if i < len(labs) else ""
            con = lab.rsplit(":", 1)[0] if ":" in lab else ""
            is_con = bool(con)
            act = True if not is_con or active is None else con in active
            if lab in grounded and len(keep) == 2:
                out.append(Prim("pin", p[None, :], size=0.05 * scale, label=lab))
            out.append(Prim("closure" if is_con else "joint", p[None, :], size=0.02 * scale,
                            active=act, label=lab))
        return out

    del labels
    return Scene(len(keep), tuple(names[i] for i in keep), [], frame, scale)


def model_scene(model: Any, samples: Sequence[np.ndarray] | None = None) -> Scene:
    """The :class:`Scene` of a model (or of a function ``q -> Geometry``).

    Parameters
    ----------
    model : Model or callable
        A planar model gets the element-by-element drawing of this module's table; any other
        model (or function) is drawn from its geometry.
    samples : sequence of ndarray, optional
        Configurations the drawing will show (used to find the plane of a planar spatial
        model); default: none.
    """
    from ..model.planar import PlanarModel

    if isinstance(model, PlanarModel):
        return _planar_scene(model)
    geometry = model.geometry if hasattr(model, "geometry") else model
    if not samples:
        raise ValueError("model_scene: a model drawn from its geometry needs sample configurations")
    return _geometry_scene(model, geometry, samples)


def scene_bounds(scene: Scene, frames: Sequence[list[Prim]]) -> tuple[np.ndarray, np.ndarray]:
    """Axis limits (lo, hi) that hold every moving primitive and the finite static ones."""
    chunks = []
    for prims in frames:
        for p in prims:
            chunks.append(p.pts.reshape(-1, scene.dim))
    for p in scene.static:
        if p.kind in ("pin",):
            chunks.append(p.pts.reshape(-1, scene.dim))
        elif p.kind in ("wall", "guide"):
            chunks.append(p.pts[:1].reshape(-1, scene.dim))
    allp = np.vstack(chunks) if chunks else np.zeros((1, scene.dim))
    lo, hi = allp.min(axis=0), allp.max(axis=0)
    span = float(np.max(hi - lo)) or 1.0
    pad = 0.1 * span
    return lo - pad, hi + pad


def clip_line(p0: np.ndarray, u: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray | None:
    """The segment of the infinite line ``p0 + s u`` inside the box [lo, hi] (2-D), or None."""
    s_lo, s_hi = -np.inf, np.inf
    for i in range(2):
        if abs(u[i]) < 1e-15:
            if not lo[i] <= p0[i] <= hi[i]:
                return None
            continue
        a, b = (lo[i] - p0[i]) / u[i], (hi[i] - p0[i]) / u[i]
        s_lo, s_hi = max(s_lo, min(a, b)), min(s_hi, max(a, b))
    if not s_lo < s_hi:
        return None
    return np.array([p0 + s_lo * u, p0 + s_hi * u])
