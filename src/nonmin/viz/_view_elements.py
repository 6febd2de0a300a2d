"""What the 3-D viewer draws besides the bodies: every element of a planar model, the ground
pins and loop closures of robots, and the reaction arrows of every constraint.

Planar models are drawn in the x–z plane of the viewer (planar ``(x, y)`` → ``(x, 0, y)``; the
planar z axis, along which planar torques point, is the viewer's −y). Each primitive of
:func:`nonmin.viz._scene.model_scene` gets a 3-D drawing:

==========================  =================================================================
primitive                   3-D drawing
==========================  =================================================================
bar, rod, spring, guide     line segments (springs as their zig-zag, guides dashed)
joint, loop-closure joint   dots (dark; light when the constraint is inactive)
point mass                  a sphere
block (slider body)         a box turned with the body
ground pin                  a triangular prism under the pin
wall / contact line         a slab along the line, extended across the plane, on its
                            forbidden side (light when the contact is open)
guide fixed to the ground   a dashed line clipped to the scene
==========================  =================================================================

Reaction arrows: the force each active constraint exerts on one of the bodies it joins (body
b, or body a when b is the ground), at that body's attachment point, and the moment it
exerts there (weld, hinge, planar weld, prismatic, ...) as a second arrow along the moment
axis — read from :meth:`Trajectory.with_reactions` (``(Aᵀ)⁺ f_c`` split per constraint,
no multipliers solved for).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = ["PlanarDrawing", "ReactionArrows", "planar_drawing", "reaction_arrows", "robot_markers"]

_LINK = np.array([31, 119, 180])
_LIGHT = np.array([200, 200, 200])
_DARK = np.array([30, 30, 30])
_SPRING = np.array([44, 160, 44])
_ROD = np.array([90, 90, 90])
_GUIDE = np.array([120, 120, 120])
_WALL = (110, 110, 110)
_BLOCK = (255, 140, 40)
_MASS = (148, 103, 189)
_PIN = (70, 70, 70)
_CLOSURE = np.array([214, 39, 160])


def to3(p: np.ndarray) -> np.ndarray:
    """Planar points (..., 2) → viewer points (..., 3) in the x–z plane."""
    p = np.asarray(p, dtype=float)
    out = np.zeros((*p.shape[:-1], 3))
    out[..., 0], out[..., 2] = p[..., 0], p[..., 1]
    return out


def _wxyz_y(angle: float) -> tuple[float, float, float, float]:
    """Quaternion of a planar rotation by ``angle`` as seen in the x–z plane (about −y)."""
    return (float(np.cos(angle / 2)), 0.0, float(-np.sin(angle / 2)), 0.0)


def _zigzag(a: np.ndarray, b: np.ndarray, width: float, turns: int = 6) -> np.ndarray:
    d = b - a
    L = float(np.linalg.norm(d))
    if L < 1e-12:
        return np.array([[a, b]])
    u = d / L
    nrm = np.array([-u[1], u[0]])
    k = np.arange(2 * turns + 1)
    s = np.concatenate([[0.0], 0.15 + 0.7 * (k + 0.5) / (2 * turns + 1), [1.0]])
    off = np.concatenate([[0.0], width * np.where(k % 2 == 0, 1.0, -1.0), [0.0]])
    pts = a + np.outer(s * L, u) + np.outer(off, nrm)
    return np.stack([pts[:-1], pts[1:]], axis=1)


def _dashes(a: np.ndarray, b: np.ndarray, dash: float) -> np.ndarray:
    L = float(np.linalg.norm(b - a))
    if L < 1e-12 or dash <= 0:
        return np.array([[a, b]])
    n = max(1, int(L / (2 * dash)))
    s0 = np.arange(n) / n
    s1 = s0 + 0.5 / n
    return np.stack([a + np.outer(s0, b - a), a + np.outer(s1, b - a)], axis=1)


@dataclass
class PlanarDrawing:
    """The 3-D drawing of a planar model: scene nodes and the update for one frame."""

    nodes: list[str]
    update: Any  # (q, active) -> None
    handles: dict[str, Any] = field(default_factory=dict)


def planar_drawing(server: Any, model: Any, qs: np.ndarray, size: float) -> PlanarDrawing:
    """Add every element of a planar model to the viewer; the returned ``update(q, active)``
    moves them to one sample."""
    from ._scene import clip_line, model_scene, scene_bounds

    scene = model_scene(model)
    sample = [scene.frame(q) for q in qs[:: max(1, len(qs) // 50)]]
    lo, hi = scene_bounds(scene, sample)
    pad = 0.15 * float(np.max(hi - lo))
    lo, hi = lo - pad, hi + pad
    depth = 0.25 * size  # how far walls and pins reach across the plane (the viewer's y)
    nodes: list[str] = []
    handles: dict[str, Any] = {}
    # static: ground pins, walls, guides fixed to the ground
    walls: list[tuple[str, Any]] = []
    for k, p in enumerate(scene.static):
        if p.kind == "pin":
            c = to3(p.pts[0])
            h = max(p.size, 0.03 * size)
            tri = np.array([[0.0, 0.0], [-0.6 * h, -h], [0.6 * h, -h]])
            v = np.vstack([to3(tri) + c + [0, -depth / 8, 0], to3(tri) + c + [0, depth / 8, 0]])
            f = np.array([[0, 1, 2], [3, 5, 4], [0, 3, 4], [0, 4, 1], [1, 4, 5], [1, 5, 2],
                          [2, 5, 3], [2, 3, 0]])
            name = f"/ground/pins/{p.label or k}"
            handles[name] = server.scene.add_mesh_simple(name, v, f, color=_PIN, flat_shading=True,
                                                         side="double")
            nodes.append(name)
        elif p.kind in ("wall", "guide"):
            seg = clip_line(p.pts[0], p.pts[1], lo, hi)
            if seg is None:
                continue
            if p.kind == "guide":
                name = f"/ground/guides/{p.label or k}"
                dash = _dashes(to3(seg[0]), to3(seg[1]), 0.03 * size)
                handles[name] = server.scene.add_line_segments(
                    name, dash, tuple(int(x) for x in _GUIDE), thickness=0.006 * size)
                nodes.append(name)
                continue
            a, b = seg
            L = float(np.linalg.norm(b - a))
            u = (b - a) / L
            nrm = np.asarray(p.normal, dtype=float) if p.normal is not None else np.array([-u[1], u[0]])
            thick = 0.04 * size
            centre = 0.5 * (a + b) - 0.5 * thick * nrm  # the slab lies on the forbidden side
            name = f"/walls/{p.label or k}"
            handles[name] = server.scene.add_box(
                name, color=_WALL, dimensions=(L, 2 * depth, thick), opacity=0.55,
                position=tuple(to3(centre)), wxyz=_wxyz_y(float(np.arctan2(u[1], u[0]))))
            walls.append((p.label, handles[name]))
            nodes.append(name)
    # moving: one node per kind; blocks and masses one node per body
    first = scene.frame(qs[0])
    blocks = {}
    masses = {}
    for p in first:
        if p.kind == "block" and p.label not in blocks:
            name = f"/sliders/{p.label}"
            blocks[p.label] = handles[name] = server.scene.add_box(
                name, color=_BLOCK, dimensions=(p.size, 0.5 * p.size, 0.6 * p.size))
            nodes.append(name)
        elif p.kind == "mass" and p.label not in masses:
            name = f"/masses/{p.label}"
            masses[p.label] = handles[name] = server.scene.add_icosphere(
                name, radius=max(p.size, 0.02 * size), color=_MASS)
            nodes.append(name)
    seg_h = server.scene.add_line_segments("/links", np.zeros((1, 2, 3)), tuple(int(x) for x in _LINK),
                                           thickness=0.012 * size)
    thin_h = server.scene.add_line_segments("/rods", np.zeros((1, 2, 3)), tuple(int(x) for x in _ROD),
                                            thickness=0.005 * size, visible=False)
    pt_h = server.scene.add_point_cloud("/joints", np.zeros((1, 3)), colors=tuple(int(x) for x in _DARK),
                                        point_size=0.025 * size, point_shape="circle")
    nodes[:0] = ["/links", "/joints"]
    handles.update({"/links": seg_h, "/rods": thin_h, "/joints": pt_h})

    def update(q: np.ndarray, active: frozenset[str] | None) -> None:
        prims = scene.frame(q, active)
        thick: list[np.ndarray] = []
        thick_c: list[np.ndarray] = []
        thin: list[np.ndarray] = []
        thin_c: list[np.ndarray] = []
        pts: list[np.ndarray] = []
        pts_c: list[np.ndarray] = []
        for p in prims:
            if p.kind == "bar":
                thick.append(to3(p.pts)[None])
                thick_c.append(np.tile(_LINK, (1, 2, 1)))
            elif p.kind in ("rod", "spring", "guide"):
                base = {"rod": _ROD, "spring": _SPRING, "guide": _GUIDE}[p.kind]
                col = base if p.active else _LIGHT
                if p.kind == "spring":
                    s = to3(_zigzag(p.pts[0], p.pts[1], max(p.size, 0.01 * size)))
                elif p.kind == "guide":
                    s = _dashes(to3(p.pts[0]), to3(p.pts[1]), 0.02 * size)
                else:
                    s = to3(p.pts)[None]
                thin.append(s)
                thin_c.append(np.tile(col, (len(s), 2, 1)))
            elif p.kind in ("joint", "point"):
                pts.append(to3(p.pts))
                pts_c.append(np.tile(_DARK if p.active else _LIGHT, (len(p.pts), 1)))
            elif p.kind == "block" and p.label in blocks:
                h = blocks[p.label]
                h.position = tuple(to3(p.pts[0]))
                h.wxyz = _wxyz_y(p.angle)
            elif p.kind == "mass" and p.label in masses:
                masses[p.label].position = tuple(to3(p.pts[0]))
        seg_h.visible = bool(thick)
        if thick:
            seg_h.points = np.concatenate(thick).astype(np.float32)
            seg_h.colors = np.concatenate(thick_c).astype(np.uint8)
        if thin:
            thin_h.points = np.concatenate(thin).astype(np.float32)
            thin_h.colors = np.concatenate(thin_c).astype(np.uint8)
            thin_h.visible = True
        if pts:
            pt_h.points = np.concatenate(pts).astype(np.float32)
            pt_h.colors = np.concatenate(pts_c).astype(np.uint8)
        for label, h in walls:
            h.opacity = 0.55 if (active is None or not label or label in active) else 0.15

    return PlanarDrawing(nodes, update, handles)


def robot_markers(server: Any, model: Any, size: float) -> tuple[dict[str, Any], Any]:
    """Ground pins (a cone under every joint on the world) and loop-closure markers (both
    frames of every frame constraint, light when inactive) of a robot; returns the nodes (name
    → handle) and ``update(q, active)``."""
    pm = model._pm
    nodes: dict[str, Any] = {}
    for j in range(1, pm.njoints):
        if pm.parents[j] != 0 or "FreeFlyer" in pm.joints[j].shortname():
            continue  # a floating base stands on nothing
        name = f"/ground/pins/{pm.names[j]}"
        p = np.array(pm.jointPlacements[j].translation)
        r, h = 0.04 * size, 0.06 * size
        ang = np.linspace(0, 2 * np.pi, 13)[:-1]
        ring = np.stack([r * np.cos(ang), r * np.sin(ang), np.full_like(ang, -h)], axis=1)
        v = np.vstack([[0.0, 0.0, 0.0], ring, [[0.0, 0.0, -h]]]) + p
        k = len(ang)
        faces = [[0, 1 + i, 1 + (i + 1) % k] for i in range(k)] + [[k + 1, 1 + (i + 1) % k, 1 + i] for i in range(k)]
        nodes[name] = server.scene.add_mesh_simple(name, v, np.array(faces), color=_PIN, flat_shading=True,
                                                   side="double")
    cons = [c for c in getattr(model, "robot_constraints", ()) if hasattr(c, "frame_a")]
    if not cons:
        return nodes, lambda q, active: None
    h = server.scene.add_point_cloud("/closures", np.zeros((2 * len(cons), 3)),
                                     colors=tuple(int(x) for x in _CLOSURE), point_size=0.035 * size,
                                     point_shape="diamond")
    nodes["/closures"] = h

    def update(q: np.ndarray, active: frozenset[str] | None) -> None:
        pts = []
        cols = []
        for c in cons:
            on = active is None or c.name in active
            for side in "ab":
                pts.append(model.frame_placement(q, f"{c.name}:{side}")[:3, 3])
                cols.append(_CLOSURE if on else _LIGHT)
        h.points = np.array(pts, dtype=np.float32)
        h.colors = np.array(cols, dtype=np.uint8)

    return nodes, update


# ---------------------------------------------------------------------------- reactions
@dataclass
class ReactionArrows:
    """Per sample: world (point, force) and (point, moment) of every active constraint."""

    forces: list[list[tuple[np.ndarray, np.ndarray]]]
    moments: list[list[tuple[np.ndarray, np.ndarray]]]
    names: list[str]

    def max_force(self) -> float:
        return max((float(np.linalg.norm(f)) for fr in self.forces for _, f in fr), default=0.0)

    def max_moment(self) -> float:
        return max((float(np.linalg.norm(m)) for fr in self.moments for _, m in fr), default=0.0)


def _is_ground(model: Any, kind: str, body: str, cname: str, side: str) -> bool:
    if kind in ("planar", "spatial"):
        return body == "ground"
    fid = model.frame_id(f"{cname}:{side}")
    return int(model._pm.frames[fid].parentJoint) == 0


def reaction_arrows(model: Any, traj: Any) -> ReactionArrows | None:
    """World force and moment arrows of every constraint that has a wrench, per sample.

    The wrench drawn is the one on body b (body a when b is the ground), at its attachment
    point (a contact's: the contact point), in world axes. Constraints without a wrench
    (joint limits and drivers, couplings) are not drawn. Planar models give 3-D points and
    vectors in the viewer's x–z plane.
    """
    from ..model.planar import PlanarModel
    from ..model.spatial import SpatialModel

    planar = isinstance(model, PlanarModel)
    spatial = isinstance(model, SpatialModel)
    robot = hasattr(model, "robot_constraints") and hasattr(model, "frame_placement")
    if not (planar or spatial or robot):
        return None
    reacts = dict(getattr(traj, "reactions", {}) or {})
    missing = [n for n in traj.constraint_names if n not in reacts]
    if missing:
        reacts.update(traj.with_reactions(model, missing).reactions)
    use = [r for r in reacts.values() if r.kind in ("planar", "spatial", "frame")]
    if not use:
        return None
    N = len(traj)
    forces: list[list[tuple[np.ndarray, np.ndarray]]] = [[] for _ in range(N)]
    moments: list[list[tuple[np.ndarray, np.ndarray]]] = [[] for _ in range(N)]
    qs = np.asarray(traj.q, dtype=float)
    for r in use:
        side = "b"
        if _is_ground(model, r.kind, r.body_b, r.name, "b"):
            if _is_ground(model, r.kind, r.body_a, r.name, "a"):
                continue
            side = "a"
        body = getattr(r, f"body_{side}")
        s = np.asarray(getattr(r, f"point_{side}"), dtype=float)
        F = np.asarray(getattr(r, f"force_{side}"), dtype=float)
        T = np.asarray(getattr(r, f"torque_{side}"), dtype=float)
        act = np.asarray(r.active, dtype=bool)
        ctype = ""
        if r.kind == "frame":
            ctype = next((c.type for c in model.robot_constraints if c.name == r.name), "")
        for i in np.flatnonzero(act):
            q = qs[i]
            if r.kind == "planar":
                ix, iy, ith = model._index[body]
                th = float(q[ith]) if ith >= 0 else 0.0
                c, sn = np.cos(th), np.sin(th)
                R = np.array([[c, -sn], [sn, c]])
                p2 = np.array([q[ix], q[iy]]) + R @ s
                p, f = to3(p2), to3(R @ F[i])
                m = np.array([0.0, -float(T[i][0]), 0.0]) if T.shape[-1] else np.zeros(3)
            elif r.kind == "spatial":
                k = model.body_index(body)
                R3 = model.rotation(q, body)
                p = q[7 * k : 7 * k + 3] + R3 @ s
                f, m = R3 @ F[i], R3 @ T[i]
            else:
                H = model.frame_placement(q, f"{r.name}:{side}")
                R3 = H[:3, :3]
                if ctype in ("contact", "point_on_plane"):
                    p = model.frame_placement(q, f"{r.name}:b")[:3, 3]
                else:
                    p = H[:3, 3]
                f, m = R3 @ F[i], R3 @ T[i]
            forces[i].append((p, f))
            moments[i].append((p, m))
    # drop round-off moments (a revolute's moment about its own point is zero)
    fmax = max((float(np.linalg.norm(f)) for fr in forces for _, f in fr), default=0.0)
    mmax = max((float(np.linalg.norm(m)) for fr in moments for _, m in fr), default=0.0)
    cut = 1e-9 * max(mmax, fmax, 1e-300)
    moments = [[(p, m) for p, m in fr if float(np.linalg.norm(m)) > cut] for fr in moments]
    return ReactionArrows(forces, moments, [r.name for r in use])
