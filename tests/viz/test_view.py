"""The interactive 3-D viewer (viser, extra ``view``): scenes of the dual-arm grasp, a URDF
robot with meshes and a loop closure, and a planar model; a headless Chromium loads the page
(slow: needs Debian's chromium and the python playwright package, see docs/viewer.md)."""

from __future__ import annotations

import os
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np
import pytest

import nonmin

pytest.importorskip("viser")
pytest.importorskip("pinocchio")

from nonmin.viz.view import inertia_box, view

CHROMIUM = os.environ.get("NONMIN_CHROMIUM", "/usr/bin/chromium")
CHROMIUM_ARGS = [
    "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
    "--disable-background-networking", "--disable-component-update", "--disable-sync",
    "--enable-unsafe-swiftshader", "--use-angle=swiftshader",
]


@pytest.fixture(scope="module")
def grasp():
    from nonmin.model.robots import two_arm_grasp

    model, state = two_arm_grasp()
    traj = nonmin.simulate(model, (0.0, 0.1), state.q, state.qd, dt=2e-3, progress=False)
    return model, traj


def ur5_loop():
    """UR5 of example-robot-data (visual meshes) with its tool point pinned: one loop closure."""
    import pinocchio as pin

    from nonmin.model import assemble
    from nonmin.model.robots import FrameConstraint, RobotModel

    urdf = (Path(pin.__file__).resolve().parents[4] / "share" / "example-robot-data" / "robots"
            / "ur_description" / "urdf" / "ur5_robot.urdf")
    if not urdf.is_file():
        pytest.skip("example-robot-data is not installed")
    free = RobotModel.from_urdf(urdf)
    qg = np.array([0.2, -1.0, 1.3, -0.6, 0.9, 0.4])
    con = FrameConstraint.point("closure", "ee_link", placement_b=free.frame_placement(qg, "ee_link"))
    model = RobotModel.from_urdf(urdf, constraints=[con])
    q0 = assemble(model, qg).q
    return model, nonmin.simulate(model, (0.0, 0.1), q0, np.zeros(6), dt=2e-3, progress=False)


def test_inertia_box_reproduces_mass_and_inertia():
    m, dims = 2.0, np.array([0.3, 0.2, 0.1])
    a, b, c = dims
    inertia = m / 12 * np.diag([b * b + c * c, a * a + c * c, a * a + b * b])
    got, R = inertia_box(m, inertia)
    assert np.allclose(np.sort(got), np.sort(dims))
    assert np.allclose(R.T @ R, np.eye(3)) and np.linalg.det(R) > 0


def test_grasp_scene_has_every_body_and_plays(grasp):
    model, traj = grasp
    v = view(traj, model, port=0, open_browser=False, autoplay=False)
    try:
        assert "/bodies/box" in v.body_nodes
        assert {"/bodies/left_yaw", "/bodies/right_wrist"} <= set(v.body_nodes)
        v.show_time(0.05)
        assert v.url.startswith("http://127.0.0.1:")
    finally:
        v.stop()


def test_model_alone_and_planar_model():
    from nonmin import library

    mech = library.get("slider_crank")
    v = view(mech.model, port=0, open_browser=False)
    try:
        assert v.body_nodes == ["/links", "/joints"]
    finally:
        v.stop()


def _page_with(url: str, viewer, seconds: float = 60.0):
    sync_api = pytest.importorskip("playwright.sync_api")
    if not shutil.which(CHROMIUM) and not Path(CHROMIUM).is_file():
        pytest.skip(f"no Chromium at {CHROMIUM} (apt-get install -y chromium)")
    pw = sync_api.sync_playwright().start()
    ctx = pw.chromium.launch_persistent_context(
        tempfile.mkdtemp(prefix="nonmin-chromium-"), executable_path=CHROMIUM, args=CHROMIUM_ARGS,
        headless=True, viewport={"width": 900, "height": 650})
    page = ctx.new_page()
    page.goto(url)
    deadline = time.time() + seconds
    while not viewer.server.get_clients() and time.time() < deadline:
        time.sleep(0.1)
    assert viewer.server.get_clients(), "the page never connected to the viewer"
    return pw, ctx, page


def _orange_pixels(img: np.ndarray) -> int:
    rgb = img[..., :3].astype(int)
    return int(np.sum((rgb[..., 0] > 170) & (rgb[..., 1] > 70) & (rgb[..., 1] < 190) & (rgb[..., 2] < 120)))


@pytest.mark.slow
def test_browser_shows_the_dual_arm_grasp(grasp, tmp_path):
    model, traj = grasp
    v = view(traj, model, port=0, open_browser=False, autoplay=False)
    pw = ctx = None
    try:
        pw, ctx, page = _page_with(v.url, v)
        page.wait_for_selector("text=Playback", timeout=60_000)
        page.wait_for_selector("text=grasp_left", timeout=60_000)  # the active set panel
        client = next(iter(v.server.get_clients().values()))
        img = client.get_render(240, 320, transport_format="png", timeout=60)
        # the inertia boxes of the arms and the grasped box are drawn in orange
        assert _orange_pixels(img) > 200, _orange_pixels(img)
        page.screenshot(path=str(tmp_path / "grasp.png"))
    finally:
        if ctx is not None:
            ctx.close()
        if pw is not None:
            pw.stop()
        v.stop()


@pytest.mark.slow
def test_browser_shows_a_urdf_robot_with_meshes_and_a_loop(tmp_path):
    model, traj = ur5_loop()
    v = view(traj, model, port=0, open_browser=False, autoplay=False)
    pw = ctx = None
    try:
        assert any("forearm" in n for n in v.body_nodes)
        pw, ctx, page = _page_with(v.url, v)
        page.wait_for_selector("text=closure", timeout=60_000)
        client = next(iter(v.server.get_clients().values()))
        empty = np.full((240, 320), 255)
        img = client.get_render(240, 320, transport_format="png", timeout=60)
        grey = img[..., :3].astype(int)
        # the meshes are shaded grey-white against the white page: many pixels differ from it
        assert np.sum(np.abs(grey.mean(axis=-1) - empty) > 25) > 1000
    finally:
        if ctx is not None:
            ctx.close()
        if pw is not None:
            pw.stop()
        v.stop()


def test_readme_five_lines_open_a_urdf_loop(monkeypatch, tmp_path):
    """The README's 'your URDF with a loop closure' snippet: at most 5 lines from pip install
    to the viewer, and they run (on the shipped four-bar URDF, no browser opened)."""
    import ast
    import re
    import shutil as sh

    from nonmin.model.robots import data_path

    readme = (Path(__file__).resolve().parents[2] / "README.md").read_text()
    block = next(b for b in re.findall(r"```py\n(.*?)```", readme, flags=re.S) if "viz.view(" in b)
    lines = [ln for ln in block.splitlines() if ln.strip()]
    assert len(lines) <= 5 and lines[0].startswith("# pip install")
    sh.copy(data_path("fourbar.urdf"), tmp_path / "fourbar.urdf")
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("NONMIN_NO_BROWSER", "1")
    tree = ast.parse(block)
    last = tree.body.pop()
    ns: dict = {}
    exec(compile(tree, "README", "exec"), ns)
    viewer = eval(compile(ast.Expression(last.value), "README", "eval"), ns)
    try:
        assert viewer.url.startswith("http://")
        assert set(viewer.body_nodes) == {"/bodies/crank", "/bodies/coupler", "/bodies/rocker"}
    finally:
        viewer.stop()
