"""What the 3-D viewer draws besides the bodies: every element of a planar model (as the 2-D
drawings do), robots' ground pins and loop closures, and the reaction arrows of every
constraint — weld and planar ones included — against closed forms and Pinocchio statics."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import nonmin
from nonmin import library
from nonmin.model.planar import PlanarBuilder, PlanarModel
from nonmin.viz._scene import model_scene
from nonmin.viz._view_elements import reaction_arrows

G = 9.81


def _cantilever(m=2.0, L=1.2):
    """A bar welded to the ground at its left end, horizontal: the weld carries its weight."""
    b = PlanarBuilder("cantilever")
    b.body("bar", mass=m, inertia=m * L**2 / 12, points={"end": (-L / 2, 0.0)})
    b.weld("clamp", ("ground", (0.0, 0.0)), "end")
    return b.build()


def test_planar_weld_force_and_moment_arrows_closed_form():
    m, L = 2.0, 1.2
    model = _cantilever(m, L)
    traj = nonmin.simulate(model, 0.05, np.array([L / 2, 0.0, 0.0]), np.zeros(3), dt=1e-2, progress=False)
    arr = reaction_arrows(model, traj)
    assert arr is not None and arr.names == ["clamp"]
    for forces, moments in zip(arr.forces, arr.moments, strict=True):
        (p, f), = forces
        (pm, mo), = moments
        # drawn on the bar at the clamp, in the viewer's x–z plane: (x, y) -> (x, 0, y)
        np.testing.assert_allclose(p, [0.0, 0.0, 0.0], atol=1e-12)
        np.testing.assert_allclose(f, [0.0, 0.0, m * G], atol=1e-9 * m * G)
        # the clamp holds the weight's moment m g L/2 (counter-clockwise: the planar +z axis,
        # which is the viewer's −y)
        np.testing.assert_allclose(mo, [0.0, -m * G * L / 2, 0.0], atol=1e-9 * m * G * L)
        np.testing.assert_allclose(pm, p)


def test_planar_pin_arrow_is_the_pendulum_tension_and_carries_no_moment():
    m, L = 2.0, 1.2
    b = PlanarBuilder("pendulum")
    b.body("bar", mass=m, inertia=m * L**2 / 12, points={"end": (-L / 2, 0.0)})
    b.revolute("pivot", ("ground", (0.0, 0.0)), "end")
    model = b.build()
    # hanging at rest: the pin holds the weight, straight up
    traj = nonmin.simulate(model, 0.05, np.array([0.0, -L / 2, -np.pi / 2]), np.zeros(3), dt=1e-2,
                           progress=False)
    arr = reaction_arrows(model, traj)
    for forces, moments in zip(arr.forces, arr.moments, strict=True):
        (p, f), = forces
        np.testing.assert_allclose(f, [0.0, 0.0, m * G], atol=1e-9 * m * G)
        np.testing.assert_allclose(p, 0.0, atol=1e-12)
        assert moments == []  # a pin's moment about its own point is zero: no arrow


def _ur5(constraint):
    import pinocchio as pin

    from nonmin.model import assemble
    from nonmin.model.robots import FrameConstraint, RobotModel

    urdf = (Path(pin.__file__).resolve().parents[4] / "share" / "example-robot-data" / "robots"
            / "ur_description" / "urdf" / "ur5_robot.urdf")
    if not urdf.is_file():
        pytest.skip("example-robot-data is not installed")
    free = RobotModel.from_urdf(urdf)
    qg = np.array([0.2, -1.0, 1.3, -0.6, 0.9, 0.4])
    con = getattr(FrameConstraint, constraint)("loop", "ee_link", placement_b=free.frame_placement(qg, "ee_link"))
    model = RobotModel.from_urdf(urdf, constraints=[con])
    return urdf, model, assemble(model, qg).q


def test_robot_weld_arrows_hold_the_robot_as_pinocchio_statics_say():
    """A UR5 welded at its tool is locked: the weld's wrench w on the tool (force, and moment
    about the tool frame, world axes) balances gravity, J(q)ᵀ w = g(q), with J the tool's
    Jacobian and g the gravity torques from Pinocchio's own model of the URDF."""
    pin = pytest.importorskip("pinocchio")
    urdf, model, q0 = _ur5("weld")
    traj = nonmin.simulate(model, (0.0, 0.02), q0, np.zeros(6), dt=1e-2, progress=False)
    arr = reaction_arrows(model, traj)
    (p, f), = arr.forces[0]
    (_, mo), = arr.moments[0]
    pm = pin.buildModelFromUrdf(str(urdf))
    data = pm.createData()
    qp = np.asarray(traj.q[0])
    g = pin.computeGeneralizedGravity(pm, data, qp)
    fid = pm.getFrameId("ee_link")
    J = pin.computeFrameJacobian(pm, data, qp, fid, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)
    w = np.linalg.solve(J.T, g)
    pin.framesForwardKinematics(pm, data, qp)
    np.testing.assert_allclose(p, data.oMf[fid].translation, atol=1e-9)
    np.testing.assert_allclose(f, w[:3], atol=1e-7 * np.abs(w).max())
    np.testing.assert_allclose(mo, w[3:], atol=1e-7 * np.abs(w).max())


def test_robot_planar_weld_moment_is_along_its_normal_and_point_closure_has_none():
    _, model, q0 = _ur5("planar_weld")
    traj = nonmin.simulate(model, (0.0, 0.02), q0, np.zeros(6), dt=1e-2, progress=False)
    arr = reaction_arrows(model, traj)
    for forces, moments in zip(arr.forces, arr.moments, strict=True):
        (_, f), = forces
        assert abs(f[1]) <= 1e-9 * np.linalg.norm(f)  # the planar rows act in the plane ⟂ y
        for _, mo in moments:
            assert np.linalg.norm(mo[[0, 2]]) <= 1e-9 * np.linalg.norm(mo)
    _, model, q0 = _ur5("point")
    traj = nonmin.simulate(model, (0.0, 0.02), q0, np.zeros(6), dt=1e-2, progress=False)
    arr = reaction_arrows(model, traj)
    assert all(len(fr) == 1 for fr in arr.forces) and all(m == [] for m in arr.moments)


# ------------------------------------------------------------------ the viewer's scene
pytest.importorskip("viser")


def _view(*args, **kw):
    from nonmin.viz.view import view

    return view(*args, port=0, open_browser=False, autoplay=False, **kw)


@pytest.mark.parametrize("name", ["slider_crank", "arm2r_wall", "dual_arm_grasp", "five_bar",
                                  "A01_pendulum", "A02_n_four_bar", "crossed_four_bar", "foot_friction"])
def test_planar_models_show_every_element_of_their_2d_drawing(name):
    """Each element the 2-D drawing has (ground pins, walls, guides, slider blocks, point
    masses) is a node of the 3-D scene; the bars and joints are drawn."""
    model = library.get(name).model
    assert isinstance(model, PlanarModel)
    scene = model_scene(model)
    q0 = np.asarray(library.get(name).state.q, dtype=float)
    want = set()
    for p in scene.static:
        want.add({"pin": "/ground/pins/", "wall": "/walls/", "guide": "/ground/guides/"}[p.kind] + p.label)
    for p in scene.frame(q0):
        if p.kind == "block":
            want.add(f"/sliders/{p.label}")
        elif p.kind == "mass":
            want.add(f"/masses/{p.label}")
    v = _view(model)
    try:
        assert want <= set(v.body_nodes), want - set(v.body_nodes)
        assert {"/links", "/joints"} <= set(v.body_nodes)
        links = v.node("/links")
        assert (len(links.points) if links.visible else 0) == len([p for p in scene.frame(q0) if p.kind == "bar"])
    finally:
        v.stop()


def test_arm_wall_viewer_draws_the_wall_on_its_forbidden_side_and_light_when_open():
    import viser

    from nonmin.viz._view_elements import planar_drawing

    mech = library.get("arm2r_wall")
    model = mech.model
    wall = next(p for p in model_scene(model).static if p.kind == "wall")
    server = viser.ViserServer(port=0, verbose=False)
    try:
        drawing = planar_drawing(server, model, mech.state.q[None, :], 1.0)
        h = drawing.handles[f"/walls/{wall.label}"]
        centre = np.asarray(h.position)[[0, 2]]
        # the slab lies behind the wall line, on the side the tip may not enter
        assert float((centre - wall.pts[0]) @ wall.normal) < 0
        drawing.update(mech.state.q, frozenset({"shoulder", "elbow"}))
        assert h.opacity == pytest.approx(0.15)  # open contact: light
        drawing.update(mech.state.q, frozenset({"shoulder", "elbow", "wall"}))
        assert h.opacity == pytest.approx(0.55)
    finally:
        server.stop()


def test_planar_viewer_draws_the_reaction_arrows():
    model = _cantilever()
    traj = nonmin.simulate(model, 0.05, np.array([0.6, 0.0, 0.0]), np.zeros(3), dt=1e-2, progress=False)
    v = _view(traj, model)
    try:
        v.show_time(0.0)
        f, mo = v.node("/forces"), v.node("/moments")
        assert f.visible and mo.visible
        # one arrow each, from the clamp, up (force) and along −y (moment)
        np.testing.assert_allclose(f.points[0][0], 0.0, atol=1e-6)
        assert f.points[0][1][2] > 0 and abs(f.points[0][1][0]) < 1e-6
        assert mo.points[0][1][1] < 0
    finally:
        v.stop()


def test_robot_viewer_shows_ground_pin_and_loop_closure_markers():
    _, model, q0 = _ur5("point")
    traj = nonmin.simulate(model, (0.0, 0.02), q0, np.zeros(6), dt=1e-2, progress=False)
    v = _view(traj, model)
    try:
        assert "/ground/pins/shoulder_pan_joint" in v.body_nodes
        assert "/closures" in v.body_nodes
        pts = np.asarray(v.node("/closures").points)
        # both frames of the closed loop coincide
        np.testing.assert_allclose(pts[0], pts[1], atol=1e-4)
    finally:
        v.stop()


@pytest.mark.parametrize("which", ["slider_crank", "ur5"])
def test_no_drawn_node_inherits_another_nodes_pose(which):
    """viser nests nodes by name ("/a/b" moves with "/a"): every ancestor of a drawn node is
    at the identity (the grid, placed at the scene's centre, once moved "/ground/pins/*")."""
    if which == "ur5":
        _, model, _ = _ur5("point")
        v = _view(model)
    else:
        v = _view(library.get(which).model)
    try:
        nodes = v.server.scene._handle_from_node_name
        for name in v.body_nodes:
            parts = name.strip("/").split("/")
            for k in range(1, len(parts)):
                parent = "/" + "/".join(parts[:k])
                if parent in nodes:
                    h = nodes[parent]
                    assert np.allclose(h.position, 0.0) and np.allclose(h.wxyz, [1, 0, 0, 0]), (name, parent)
    finally:
        v.stop()


def test_robot_viewer_draws_a_contact_plane_where_the_model_puts_it():
    """A UR5 with its tool above a tilted plane (``FrameConstraint.contact``): the plane is a
    node through the plane frame's origin, its slab normal (the box's z) along the plane's
    normal in the world — the geometry of the contact's own gap."""
    import pinocchio as pin

    from nonmin.model.robots import FrameConstraint, RobotModel

    urdf = (Path(pin.__file__).resolve().parents[4] / "share" / "example-robot-data" / "robots"
            / "ur_description" / "urdf" / "ur5_robot.urdf")
    if not urdf.is_file():
        pytest.skip("example-robot-data is not installed")
    q0 = np.array([0.2, -1.0, 1.3, -0.6, 0.9, 0.4])
    free = RobotModel.from_urdf(urdf)
    tool = free.frame_placement(q0, "ee_link")[:3, 3]
    normal = np.array([0.0, 0.6, 0.8])
    H = np.eye(4)
    H[:3, 3] = tool - 0.05 * normal  # 5 cm below the tool along the normal
    floor = FrameConstraint.contact("floor", "ee_link", plane_placement=H, normal=normal)
    model = RobotModel.from_urdf(urdf, constraints=[floor], joint_limits="ignore")
    traj = nonmin.simulate(model, (0.0, 0.02), q0, np.zeros(6), dt=1e-2, progress=False)
    v = _view(traj, model)
    try:
        v.show_time(0.0)
        h = v.node("/planes/floor")
        np.testing.assert_allclose(np.asarray(h.position), H[:3, 3], atol=1e-6)
        w, x, y, z = np.asarray(h.wxyz, dtype=float)
        # the box's z axis in the world: third column of the rotation of (w, x, y, z)
        zw = np.array([2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)])
        np.testing.assert_allclose(zw, normal, atol=1e-6)
        # the tool is 5 cm above it, along the normal
        assert abs(normal @ (tool - np.asarray(h.position)) - 0.05) < 1e-6
    finally:
        v.stop()
