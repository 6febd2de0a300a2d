"""Interactive 3-D viewer in the browser (viser; extra ``view``).

:func:`view` serves a model, or a :class:`~nonmin.sim.Trajectory` of it, on a local web
server and (by default) opens the browser on it. The page shows

* the bodies: a robot's visual meshes and primitives from its URDF (through Pinocchio's
  geometry model; ``package://`` paths resolved), or, for links without visuals and for
  spatial models, the *inertia box* of each body (the uniform box with the body's mass and
  principal inertias, at its centre of mass and principal axes); planar models are drawn in
  the x–z plane; links as line segments between joint origins;
* the constraint frames (both sides of every frame constraint), the contact planes, a ground
  pin under every joint on the world and markers on both frames of every loop closure;
* for planar models, every element their 2-D drawing has (walls, guides, slider blocks,
  ground pins, point masses, rods, springs; :mod:`nonmin.viz._view_elements`);
* the reaction of every active constraint: its force on one of the bodies it joins as a red
  arrow at the attachment point and its moment as a purple arrow (weld, hinge, planar weld,
  ...), read from :meth:`Trajectory.with_reactions` (``(Aᵀ)⁺ f_c`` split per constraint;
  1 N = ``force_scale`` m);
* a *Playback* panel: play/pause, a time slider to scrub, the playback speed, loop; the
  current time, the active constraint set and the last event, updated as it plays;
* an *Active set over time* panel: the number of active constraints and the rank of A
  against time, and the instants at which constraints switch on or off.

The server runs in background threads; :meth:`Viewer.stop` ends it. Nothing is imported
from viser until :func:`view` is called.
"""

from __future__ import annotations

import functools
import os
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError, missing_dependency

__all__ = ["Viewer", "view"]

_BODY = (255, 140, 40)
_LINK = (31, 119, 180)
_ARROW = (214, 39, 40)
_MOMENT = (148, 50, 190)
_PLANE = (160, 160, 160)


def _viser() -> Any:
    try:
        import viser
    except ImportError:
        raise missing_dependency("viser", "view", "The interactive 3-D viewer") from None
    return viser


def _wxyz(R: np.ndarray) -> np.ndarray:
    """Unit quaternion (w, x, y, z) of a rotation matrix."""
    m = np.asarray(R, dtype=float)
    tr = m[0, 0] + m[1, 1] + m[2, 2]
    if tr > 0:
        s = 2.0 * np.sqrt(tr + 1.0)
        q = [0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s]
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = 2.0 * np.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
        q = [(m[2, 1] - m[1, 2]) / s, 0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s]
    elif m[1, 1] > m[2, 2]:
        s = 2.0 * np.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
        q = [(m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s]
    else:
        s = 2.0 * np.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
        q = [(m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s]
    out = np.array(q)
    return out / np.linalg.norm(out)


def inertia_box(mass: float, inertia: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The uniform box with this mass and inertia about its centre: (dimensions (3,), axes R).

    For principal moments ``I₁, I₂, I₃`` the box sides are
    ``a₁ = √(6 (I₂ + I₃ − I₁) / m)`` (and cyclically); the columns of R are the principal
    axes. Degenerate sides (a thin rod) are kept at 5 % of the longest one so they show.
    """
    w, V = np.linalg.eigh(0.5 * (inertia + inertia.T))
    if np.linalg.det(V) < 0:
        V[:, 0] = -V[:, 0]
    tot = w.sum()
    sq = np.array([6.0 * max(tot - 2 * w[i], 0.0) / max(mass, 1e-12) for i in range(3)])
    dims = np.sqrt(sq)
    top = float(dims.max()) if dims.max() > 0 else 0.05
    return np.maximum(dims, 0.05 * top), V


@dataclass
class _Visual:
    """A mesh that moves with a Pinocchio joint: world pose = oMi[joint] · placement."""

    name: str
    joint: int
    placement: np.ndarray  # 4x4
    handle: Any = None


@dataclass
class Viewer:
    """A running viewer: its ``url``, the viser ``server``, and :meth:`stop`.

    Attributes
    ----------
    url : str
    server : viser.ViserServer
    body_nodes : list of str
        Scene-tree names of the bodies drawn (what a test checks in the page).
    """

    url: str
    server: Any
    body_nodes: list[str] = field(default_factory=list)
    _stop: threading.Event = field(default_factory=threading.Event, repr=False)
    _thread: threading.Thread | None = field(default=None, repr=False)
    _show: Any = field(default=None, repr=False)
    _nodes: dict[str, Any] = field(default_factory=dict, repr=False)

    def node(self, name: str) -> Any:
        """The viser handle of a scene node (``"/forces"``, ``"/walls/wall"``, ...): what the
        page shows of it (``points``, ``position``, ``visible``, ``opacity``)."""
        if name not in self._nodes:
            raise InputError(f"view: no scene node {name!r}; known: {sorted(self._nodes)}")
        return self._nodes[name]

    def show_time(self, t: float) -> None:
        """Draw the frame at time ``t`` (the nearest earlier sample)."""
        if self._show is not None:
            self._show(float(t))

    def stop(self) -> None:
        """Stop playback and the web server."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        self.server.stop()


#: Meshes read for the viewer, by file (path, modification time, size): a robot shown again
#: (another trajectory, another viewer in the same session) reuses them. Each viewer draws a
#: copy. Reading the UR5's seven Collada meshes took 0.3-0.45 s of CPU per viewer.
_MESHES: dict[tuple[str, int, int], Any] = {}
@functools.cache
def _mesh_loader() -> Any:
    """Pinocchio's mesh loader for the visual geometry, one per process (None without coal or
    hpp-fcl): it keeps the meshes it read (and reads a file again when it changed), so a robot's
    second viewer does not parse its meshes again (the UR5's buildGeomFromUrdf: 0.43 s of CPU,
    then 0.001 s)."""
    try:
        import coal as fcl
    except ImportError:
        try:
            import hppfcl as fcl
        except ImportError:
            return None
    return fcl.CachedMeshLoader()


def _load_mesh(trimesh: Any, path: str) -> Any:
    """``trimesh.load(path, force="mesh")``, read once per file version; a copy to draw."""
    st = os.stat(path)
    key = (str(Path(path).resolve()), st.st_mtime_ns, st.st_size)
    mesh = _MESHES.get(key)
    if mesh is None:
        mesh = _MESHES[key] = trimesh.load(path, force="mesh")
    return mesh.copy()


def _robot_visuals(model: Any, server: Any) -> list[_Visual]:
    """Meshes and primitives of a URDF robot's visual geometry (Pinocchio), as scene nodes."""
    src = (getattr(model, "metadata", {}) or {}).get("source")
    if not isinstance(src, str) or not src.lower().endswith(".urdf") or not Path(src).is_file():
        return []
    import pinocchio as pin

    try:
        import trimesh
    except ImportError:
        raise missing_dependency("trimesh", "view", "Drawing robot meshes") from None
    urdf = Path(src).resolve()
    pkg_dirs = [str(p) for p in urdf.parents]
    try:
        loader = _mesh_loader()
        if loader is None:
            gm = pin.buildGeomFromUrdf(model._pm, str(urdf), pin.GeometryType.VISUAL, package_dirs=pkg_dirs)
        else:
            gm = pin.buildGeomFromUrdf(model._pm, str(urdf), pin.GeometryType.VISUAL, package_dirs=pkg_dirs,
                                       mesh_loader=loader)
    except Exception:  # no usable visual geometry: the inertia boxes are drawn instead
        return []
    out: list[_Visual] = []
    for k, go in enumerate(gm.geometryObjects):
        geom = go.geometry
        kind = type(geom).__name__
        mesh: Any = None
        color = tuple(int(255 * c) for c in np.asarray(go.meshColor)[:3])
        if kind.startswith(("BVH", "Convex")) and go.meshPath and Path(go.meshPath).is_file():
            try:
                mesh = _load_mesh(trimesh, go.meshPath)
                mesh.apply_scale(np.asarray(go.meshScale, dtype=float))
            except Exception:  # a format trimesh cannot read: the inertia box stands in
                mesh = None
        elif kind == "Box":
            mesh = trimesh.creation.box(extents=2.0 * np.asarray(geom.halfSide))
        elif kind == "Cylinder":
            mesh = trimesh.creation.cylinder(radius=geom.radius, height=2.0 * geom.halfLength)
        elif kind == "Sphere":
            mesh = trimesh.creation.icosphere(radius=geom.radius)
        elif kind == "Capsule":
            mesh = trimesh.creation.capsule(radius=geom.radius, height=2.0 * geom.halfLength)
        if mesh is None:
            continue
        if getattr(mesh.visual, "kind", None) not in ("texture", "vertex", "face"):
            mesh.visual.face_colors = (*(color if any(color) else _BODY), 255)
        name = f"/bodies/{go.name or f'visual{k}'}"
        handle = server.scene.add_mesh_trimesh(name, mesh)
        out.append(_Visual(name, int(go.parentJoint), np.array(go.placement.homogeneous), handle))
    return out


def _inertia_boxes(model: Any, server: Any, skip_joints: set[int]) -> list[_Visual]:
    """One inertia box per body of a robot (joints whose links have no visual)."""
    pm = model._pm
    out = []
    for j in range(1, pm.njoints):
        if j in skip_joints:
            continue
        Y = pm.inertias[j]
        m = float(Y.mass)
        if m <= 0:
            continue
        dims, R = inertia_box(m, np.array(Y.inertia))
        H = np.eye(4)
        H[:3, :3] = R
        H[:3, 3] = np.array(Y.lever)
        name = f"/bodies/{pm.names[j]}"
        handle = server.scene.add_box(name, color=_BODY, dimensions=tuple(dims))
        out.append(_Visual(name, j, H, handle))
    return out


def _constraint_frames(model: Any) -> list[tuple[str, Any]]:
    """(frame name, constraint) for both sides of every robot frame constraint."""
    out = []
    for c in getattr(model, "robot_constraints", ()):
        if not hasattr(c, "frame_a"):
            continue
        for side in ("a", "b"):
            out.append((f"{c.name}:{side}", c))
    return out


def view(
    traj_or_model: Any,
    model: Any | None = None,
    *,
    host: str = "127.0.0.1",
    port: int = 8080,
    speed: float = 1.0,
    open_browser: bool = True,
    autoplay: bool = True,
    force_scale: float | None = None,
) -> Viewer:
    """Open the interactive 3-D viewer on a model or a trajectory (extra ``view``: viser).

    Parameters
    ----------
    traj_or_model : Trajectory or Model
        A trajectory (then ``model`` is the model it came from) or a model alone (shown at
        its default configuration, ready to be rotated and zoomed).
    model : Model, optional
    host, port : str, int
        Address of the local web server (port 0: any free port).
    speed : float
        Initial playback speed (1 = real time).
    open_browser : bool
        Open the system's web browser on the page (not when the environment variable
        ``NONMIN_NO_BROWSER`` is set to anything but 0: tests, remote shells).
    autoplay : bool
        Start playing at once (a trajectory only).
    force_scale : float, optional
        Length of a force arrow per newton [m/N]; default: the largest force is drawn as a
        quarter of the scene's size.

    Returns
    -------
    Viewer
        ``viewer.url`` is the page; ``viewer.stop()`` ends the server.
    """
    from ..model._protocol import Model

    if isinstance(traj_or_model, Model):
        model, traj = traj_or_model, None
    else:
        traj = traj_or_model
        if not isinstance(model, Model):
            raise InputError(f"view: pass the model the trajectory came from, got {type(model).__name__}")
        if np.shape(traj.q)[-1:] != (model.n,):
            raise InputError(f"view: the trajectory has {np.shape(traj.q)[-1]} coordinates, the model "
                             f"{model.name!r} has {model.n}: not the model this trajectory came from")
        if len(traj) == 0:
            raise InputError("view: the trajectory holds no samples")
    try:
        spd = float(speed)
    except (TypeError, ValueError):
        spd = float("nan")
    if not (np.isfinite(spd) and 0 < spd <= 1e3):
        raise InputError(f"view: speed must be a number in (0, 1000], got {speed!r}")
    if isinstance(port, bool) or not isinstance(port, int | np.integer) or not 0 <= int(port) <= 65535:
        raise InputError(f"view: port must be an integer in [0, 65535] (0: any free port), got {port!r}")
    viser = _viser()
    if traj is None:
        q0 = _default_q(model)
        ts = np.array([0.0])
        qs = q0[None, :]
    else:
        ts = np.asarray(traj.t, dtype=float)
        qs = np.asarray(traj.q, dtype=float)
    server = viser.ViserServer(host=host, port=port, verbose=False)
    try:
        return _build(server, model, traj, ts, qs, spd, autoplay, force_scale, open_browser)
    except BaseException:
        server.stop()
        raise


def _default_q(model: Any) -> np.ndarray:
    """The configuration a model alone is shown at: its neutral one, assembled onto its
    default active constraints when that succeeds (so a loop shows closed)."""
    q = np.zeros(model.n)
    fn = getattr(model, "neutral_configuration", None)
    if callable(fn):
        q = np.asarray(fn(), dtype=float)
    from ..model.spatial import SpatialModel

    if isinstance(model, SpatialModel):  # unit quaternions (1, 0, 0, 0), not zeros
        q[3::7] = 1.0
    from ..errors import NonminError
    from ..model import assemble

    try:
        return np.asarray(assemble(model, q).q, dtype=float)
    except NonminError:
        return q


def _build(server: Any, model: Any, traj: Any, ts: np.ndarray, qs: np.ndarray, speed: float,
           autoplay: bool, force_scale: float | None, open_browser: bool) -> Viewer:
    from ..model.robots import RobotModel
    from ..model.spatial import SpatialModel
    from ._view_elements import reaction_arrows, robot_markers

    port = server.get_port()
    url = f"http://{server.get_host() if server.get_host() not in ('0.0.0.0', '::') else '127.0.0.1'}:{port}"
    server.scene.set_up_direction("+z")
    geoms = [model.geometry(q) for q in qs[:: max(1, len(qs) // 50)]]
    dim = geoms[0].dim if geoms and geoms[0] is not None else 3

    def to3(p: np.ndarray) -> np.ndarray:
        p = np.asarray(p, dtype=float)
        if dim == 3:
            return p
        out = np.zeros((*p.shape[:-1], 3))
        out[..., 0], out[..., 2] = p[..., 0], p[..., 1]  # planar (x, y) drawn in the x–z plane
        return out

    pts = np.vstack([to3(np.asarray(g.segments).reshape(-1, dim)) for g in geoms if g is not None]
                    + [to3(np.asarray(g.points).reshape(-1, dim)) for g in geoms if g is not None])
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    size = float(np.max(hi - lo)) if pts.size else 1.0
    size = size if size > 1e-9 else 1.0
    center = 0.5 * (lo + hi)
    if dim == 2:  # a planar model moves in the x–z plane: the grid is the board behind it
        server.scene.add_grid("/grid", width=2 * size, height=2 * size, cell_size=size / 10,
                              section_size=size / 2, plane="xz", position=(center[0], 0.3 * size, center[2]))
        server.initial_camera.position = tuple(center + size * np.array([0.35, -1.6, 0.45]))
    else:
        server.scene.add_grid("/grid", width=2 * size, height=2 * size, cell_size=size / 10,
                              section_size=size / 2, plane="xy", position=(center[0], center[1], 0.0))
        server.initial_camera.position = tuple(center + size * np.array([0.75, -1.05, 0.6]))
    server.initial_camera.look_at = tuple(center)
    body_nodes: list[str] = []
    visuals: list[_Visual] = []
    spatial_boxes: list[tuple[str, int, Any]] = []
    if isinstance(model, RobotModel):
        visuals = _robot_visuals(model, server)
        have = {v.joint for v in visuals}
        visuals += _inertia_boxes(model, server, have)
        body_nodes = [v.name for v in visuals]
    elif isinstance(model, SpatialModel):
        for i, b in enumerate(model.bodies):
            dims, R = inertia_box(float(b.mass), np.asarray(b.inertia, dtype=float))
            name = f"/bodies/{b.name}"
            spatial_boxes.append((name, i, (server.scene.add_box(name, color=_BODY, dimensions=tuple(dims)), R)))
            body_nodes.append(name)
    planar = _planar_drawing(server, model, qs, size)
    link_handle: Any = None
    joint_handle: Any = None
    if planar is not None:
        body_nodes = list(planar.nodes)
    else:
        link_handle = server.scene.add_line_segments(
            "/links", np.zeros((1, 2, 3)), _LINK, thickness=0.012 * size)
        joint_handle = server.scene.add_point_cloud(
            "/joints", np.zeros((1, 3)), colors=(30, 30, 30), point_size=0.025 * size, point_shape="circle")
        if not body_nodes:
            body_nodes = ["/links", "/joints"]
    markers: Any = None
    markers_handles: dict[str, Any] = {}
    if isinstance(model, RobotModel):  # ground pins and loop-closure markers
        markers_handles, markers = robot_markers(server, model, size)
        body_nodes += list(markers_handles)
    # constraint frames and contact planes (robots)
    cframes = _constraint_frames(model)
    frame_handles = {fname: server.scene.add_frame(f"/constraints/{fname}", axes_length=0.12 * size,
                                                   axes_radius=0.006 * size) for fname, _ in cframes}
    planes = []
    for c in getattr(model, "robot_constraints", ()):
        if getattr(c, "type", "") in ("contact", "point_on_plane"):
            h = server.scene.add_box(f"/planes/{c.name}", color=_PLANE, dimensions=(2 * size, 2 * size, 0.002 * size),
                                     opacity=0.35)
            planes.append((c, h))
    # the reactions of every constraint with a wrench: forces (red) and moments (purple)
    react = reaction_arrows(model, traj) if traj is not None else None
    fmax = react.max_force() if react is not None else 0.0
    mmax = react.max_moment() if react is not None else 0.0
    scale = force_scale if force_scale is not None else (0.25 * size / fmax if fmax > 0 else 0.0)
    mscale = 0.2 * size / mmax if mmax > 0 else 0.0
    arrows = server.scene.add_arrows("/forces", np.zeros((1, 2, 3)), _ARROW, shaft_radius=0.006 * size,
                                     head_radius=0.015 * size, head_length=0.03 * size, visible=False)
    marrows = server.scene.add_arrows("/moments", np.zeros((1, 2, 3)), _MOMENT, shaft_radius=0.004 * size,
                                      head_radius=0.012 * size, head_length=0.03 * size, visible=False)
    # GUI
    folder = server.gui.add_folder("Playback")
    with folder:
        play = server.gui.add_checkbox("Play", initial_value=autoplay and traj is not None)
        t_slider = server.gui.add_slider("t [s]", min=float(ts[0]), max=float(max(ts[-1], ts[0] + 1e-9)),
                                         step=float(max((ts[-1] - ts[0]) / 1000.0, 1e-6)),
                                         initial_value=float(ts[0]))
        speed_in = server.gui.add_number("speed", initial_value=float(speed), min=0.01, max=100.0, step=0.05)
        loop = server.gui.add_checkbox("Loop", initial_value=True)
        info = server.gui.add_markdown("")
    if traj is not None and len(ts) > 1:
        _active_set_panel(server, traj)
    names = tuple(getattr(traj, "constraint_names", ())) if traj is not None else ()
    mask = getattr(traj, "active_mask", None) if traj is not None else None
    events = [(float(e.t), str(e.name)) for e in getattr(traj, "events", ())] if traj is not None else []
    is_robot = isinstance(model, RobotModel)

    def show(t: float) -> None:
        i = int(np.clip(np.searchsorted(ts, t, side="right") - 1, 0, len(ts) - 1))
        q = qs[i]
        act_i = (frozenset(n for n, a in zip(names, mask[i], strict=True) if a)
                 if mask is not None else None)
        with server.atomic():
            if planar is not None:
                planar.update(q, act_i)
            else:
                g = model.geometry(q)
                seg = to3(np.asarray(g.segments).reshape(-1, 2, dim))
                jp = to3(np.asarray(g.points).reshape(-1, dim))
                if seg.size:
                    link_handle.points = seg
                if jp.size:
                    joint_handle.points = jp.astype(np.float32)
            if markers is not None:
                markers(q, act_i)
            if is_robot and (visuals or frame_handles or planes):
                oMi, _ = _placements(model, q)
                for v in visuals:
                    H = oMi[v.joint] @ v.placement
                    v.handle.position = H[:3, 3]
                    v.handle.wxyz = _wxyz(H[:3, :3])
                for fname, h in frame_handles.items():
                    H = model.frame_placement(q, fname)
                    h.position = H[:3, 3]
                    h.wxyz = _wxyz(H[:3, :3])
                for c, h in planes:
                    H = model.frame_placement(q, f"{c.name}:a")
                    n = H[:3, :3] @ np.asarray(c.axis, dtype=float)
                    z = np.array([0.0, 0.0, 1.0])
                    h.position = H[:3, 3]
                    h.wxyz = _wxyz(_align(z, n))
            for _name, k, (h, R) in spatial_boxes:
                qb = q[7 * k : 7 * k + 7]
                Rb = model.rotation(q, model.bodies[k].name)
                h.position = qb[:3]
                h.wxyz = _wxyz(Rb @ R)
            for node, vecs, sc in ((arrows, react.forces[i] if react else [], scale),
                                   (marrows, react.moments[i] if react else [], mscale)):
                if vecs and sc > 0:
                    node.points = np.array([[p, p + sc * f] for p, f in vecs], dtype=np.float32)
                    node.visible = True
                else:
                    node.visible = False
            active = sorted(act_i) if act_i is not None else []
            fired = [n for te, n in events if te <= ts[i]]
            info.content = (
                f"**t = {ts[i]:.3f} s** (sample {i + 1}/{len(ts)})  \n"
                f"active ({len(active)}): {', '.join(active) if active else '—'}  \n"
                f"last event: {fired[-1] if fired else '—'}"
                + (f"  \nforce arrows (red): {1 / scale:.3g} N per m" if fmax > 0 and scale > 0 else "")
                + (f"  \nmoment arrows (purple): {1 / mscale:.3g} N·m per m" if mmax > 0 else "")
            )

    show(float(ts[0]))
    stop = threading.Event()
    state = {"t": float(ts[0]), "from_slider": False}

    @t_slider.on_update
    def _(_: Any) -> None:
        if not state["from_slider"]:
            state["t"] = float(t_slider.value)
            show(state["t"])

    def run() -> None:
        last = time.perf_counter()
        while not stop.is_set():
            time.sleep(1 / 30)
            now = time.perf_counter()
            dt, last = now - last, now
            if not play.value or len(ts) < 2:
                continue
            t = state["t"] + dt * float(speed_in.value)
            if t > ts[-1]:
                t = float(ts[0]) if loop.value else float(ts[-1])
                if not loop.value:
                    play.value = False
            state["t"] = t
            state["from_slider"] = True
            try:
                t_slider.value = min(max(t, float(ts[0])), float(ts[-1]))
            finally:
                state["from_slider"] = False
            show(t)

    def goto(t: float) -> None:
        state["t"] = float(t)
        state["from_slider"] = True
        try:
            t_slider.value = min(max(float(t), float(ts[0])), float(ts[-1]))
        finally:
            state["from_slider"] = False
        show(float(t))

    thread = threading.Thread(target=run, name="nonmin-view", daemon=True)
    thread.start()
    nodes: dict[str, Any] = {"/forces": arrows, "/moments": marrows}
    if planar is not None:
        nodes.update(planar.handles)
    else:
        nodes.update({"/links": link_handle, "/joints": joint_handle})
    nodes.update({v.name: v.handle for v in visuals})
    nodes.update({name: h for name, _, (h, _R) in spatial_boxes})
    nodes.update({f"/planes/{c.name}": h for c, h in planes})
    nodes.update({f"/constraints/{f}": h for f, h in frame_handles.items()})
    if markers is not None:
        nodes.update(markers_handles)
    viewer = Viewer(url=url, server=server, body_nodes=body_nodes, _stop=stop, _thread=thread, _show=goto,
                    _nodes=nodes)
    if open_browser and os.environ.get("NONMIN_NO_BROWSER", "") in ("", "0"):
        import webbrowser

        webbrowser.open(url)
    return viewer


def _planar_drawing(server: Any, model: Any, qs: np.ndarray, size: float) -> Any:
    """Every element of a planar model drawn in the x–z plane (None for other models)."""
    from ..model.planar import PlanarModel
    from ._view_elements import planar_drawing

    if not isinstance(model, PlanarModel):
        return None
    return planar_drawing(server, model, qs, size)


def _active_set_panel(server: Any, traj: Any) -> None:
    """A panel with the active set over time: the number of active constraints and the rank of
    A as step curves, and the list of the times at which the active set changes."""
    from viser import uplot

    mask = np.asarray(traj.active_mask, dtype=bool)
    names = tuple(traj.constraint_names)
    t = np.asarray(traj.t, dtype=float)
    changes = []
    for i in range(1, len(t)):
        if not np.array_equal(mask[i], mask[i - 1]):
            on = [n for n, a, b in zip(names, mask[i - 1], mask[i], strict=True) if b and not a]
            off = [n for n, a, b in zip(names, mask[i - 1], mask[i], strict=True) if a and not b]
            changes.append(f"- {t[i]:.4f} s: " + ", ".join([f"+{n}" for n in on] + [f"−{n}" for n in off]))
    with server.gui.add_folder("Active set over time", expand_by_default=True):
        server.gui.add_uplot(
            data=(t, mask.sum(axis=1).astype(float), np.asarray(traj.rank, dtype=float)),
            series=(uplot.Series(label="t [s]"),
                    uplot.Series(label="active constraints", stroke="#d62728", width=2),
                    uplot.Series(label="rank A", stroke="#1f77b4", width=2, dash=(4.0, 4.0))),
            scales={"x": uplot.Scale(time=False)},
            aspect=2.0,
        )
        server.gui.add_markdown(
            ("changes of the active set:\n" + "\n".join(changes[:30])
             + (f"\n- … {len(changes) - 30} more" if len(changes) > 30 else ""))
            if changes else "the active set does not change in this run")


def _align(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """A rotation taking unit vector a to unit vector b."""
    b = b / np.linalg.norm(b)
    v = np.cross(a, b)
    c = float(a @ b)
    if np.linalg.norm(v) < 1e-12:
        return np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    K = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + K + K @ K * (1.0 / (1.0 + c))


def _placements(model: Any, q: np.ndarray) -> tuple[list[np.ndarray], Any]:
    """World placements oMi (4x4) of every joint of a robot at q (Pinocchio kinematics)."""
    import pinocchio as pin

    pm = model._pm
    data = getattr(model, "_viewer_data", None)
    if data is None:
        data = pm.createData()
    pin.forwardKinematics(pm, data, model.pinocchio_configuration(q))
    return [np.array(data.oMi[j].homogeneous) for j in range(pm.njoints)], data
