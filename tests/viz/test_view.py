"""The interactive 3-D viewer (viser, extra ``view``): scenes of the dual-arm grasp, a URDF
robot with meshes and a loop closure, and planar models with every element; a headless Chromium
(Debian's package, driven by the python playwright package; .ci/run installs it, see
docs/viewer.md) loads the page once per module and checks that the scene shows the bodies."""

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


def test_playback_plays_at_its_speed():
    """Play advances the shown frame with the wall clock times ``speed``: at speed 0.01 the
    slider block stays at its first sample for 0.6 s of playing, at speed 1 it moves (issue 23:
    play, scrub, speed)."""
    from nonmin import library

    mech = library.get("slider_crank")
    traj = nonmin.simulate(mech, (0.0, 1.0), dt=1e-2, progress=False)
    pos = {}
    for speed in (0.01, 1.0):
        v = view(traj, mech.model, port=0, open_browser=False, autoplay=True, speed=speed)
        try:
            block = v.node("/sliders/slider")
            p0 = np.array(block.position, dtype=float)
            time.sleep(0.6)
            pos[speed] = float(np.linalg.norm(np.array(block.position, dtype=float) - p0))
        finally:
            v.stop()
    assert pos[0.01] == 0.0 and pos[1.0] > 1e-3, pos


def test_model_alone_and_planar_model():
    from nonmin import library

    mech = library.get("slider_crank")
    v = view(mech.model, port=0, open_browser=False)
    try:
        # the bars and joints, the ground pin, the slide guide and the slider block
        assert v.body_nodes == ["/links", "/joints", "/ground/pins/O", "/ground/guides/slide", "/sliders/slider"]
    finally:
        v.stop()


@pytest.fixture(scope="module")
def browser():
    """One headless Chromium for the module's page tests (Debian's package driven by the python
    playwright package; .ci/run installs it). Skips when either is missing."""
    sync_api = pytest.importorskip("playwright.sync_api")
    if not shutil.which(CHROMIUM) and not Path(CHROMIUM).is_file():
        pytest.skip(f"no Chromium at {CHROMIUM} (apt-get install -y chromium)")
    profile = tempfile.mkdtemp(prefix="nonmin-chromium-")
    pw = sync_api.sync_playwright().start()
    try:
        ctx = pw.chromium.launch_persistent_context(
            profile, executable_path=CHROMIUM, args=CHROMIUM_ARGS, headless=True,
            viewport={"width": 480, "height": 360})
        try:
            yield ctx
        finally:
            ctx.close()
    finally:
        pw.stop()
        shutil.rmtree(profile, ignore_errors=True)


def _open_page(browser, viewer, seconds: float = 120.0):
    """A page on the viewer, once it has connected (the server sees a client).

    The HDR environment map is switched off first: software WebGL (SwiftShader, no GPU here)
    spends ~15 s prefiltering it before the first render; the bodies' colours and shading by
    the scene's lights do not need it. So are the shadows of viser's default lights (viser's
    default, not the viewer's): the page redraws continuously while it is open, and with
    shadows each frame renders the scene twice in software (Chromium's processes: 3.9 s of CPU
    in 4 s idle on the UR5 page, 2.3 s without; one render pair of _body_pixels_now 3.6-4.1 s
    wall, 1.6-2.2 s without). The bodies still cover > 3000 pixels of the UR5's render."""
    viewer.server.scene.configure_environment_map(hdri=None)
    viewer.server.scene.configure_default_lights(enabled=True, cast_shadow=False)
    page = browser.new_page()
    page.goto(viewer.url)
    deadline = time.time() + seconds
    while not viewer.server.get_clients() and time.time() < deadline:
        time.sleep(0.05)
    assert viewer.server.get_clients(), "the page never connected to the viewer"
    return page


def _body_pixels(viewer, want: int, seconds: float = 120.0) -> int:
    """Pixels of the page's render that the bodies cover, once more than ``want`` (or the
    count when ``seconds`` have passed): meshes reach the page after its panels do, and
    a loaded machine may take seconds to add them to the scene."""
    deadline = time.time() + seconds
    while True:
        px = _body_pixels_now(viewer)
        if px > want or time.time() > deadline:
            return px
        time.sleep(0.5)


def _body_pixels_now(viewer) -> int:
    """The page renders the scene with and without the body nodes (the server asks the
    connected page for each image); the pixels that differ."""
    client = next(iter(viewer.server.get_clients().values()))
    with_bodies = client.get_render(240, 320, transport_format="png", timeout=120)
    for name in viewer.body_nodes:
        viewer.node(name).visible = False
    without = client.get_render(240, 320, transport_format="png", timeout=120)
    for name in viewer.body_nodes:
        viewer.node(name).visible = True
    diff = np.abs(with_bodies.astype(int) - without.astype(int)).max(axis=-1)
    return int(np.sum(diff > 30))


def test_browser_shows_the_dual_arm_grasp(browser, grasp):
    model, traj = grasp
    v = view(traj, model, port=0, open_browser=False, autoplay=False)
    try:
        page = _open_page(browser, v)
        page.wait_for_selector("text=Playback", timeout=120_000)
        page.wait_for_selector("text=grasp_left", timeout=120_000)  # the active set panel
        # the inertia boxes of the arms and of the grasped box
        px = _body_pixels(v, 500)
        assert px > 500, px
        page.close()
    finally:
        v.stop()


def test_browser_shows_a_urdf_robot_with_meshes_and_a_loop(browser):
    model, traj = ur5_loop()
    v = view(traj, model, port=0, open_browser=False, autoplay=False)
    try:
        assert any("forearm" in n for n in v.body_nodes)
        page = _open_page(browser, v)
        page.wait_for_selector("text=closure", timeout=120_000)
        # the UR5's meshes (and the loop closure's markers)
        px = _body_pixels(v, 1000)
        assert px > 1000, px
        page.close()
    finally:
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
        assert {"/bodies/crank", "/bodies/coupler", "/bodies/rocker"} <= set(viewer.body_nodes)
        assert "/closures" in viewer.body_nodes  # the loop closure's two frames are marked
    finally:
        viewer.stop()


def test_a_port_outside_0_65535_is_a_usage_error(capsys):
    """--port 99999 let viser's server thread die with OverflowError: bind(): port must be
    0-65535 (a raw traceback); the API and the CLI now refuse it by name."""
    from nonmin import library
    from nonmin.cli import EXIT_USAGE, main
    from nonmin.errors import InputError
    from nonmin.viz import view

    with pytest.raises(InputError, match=r"port must be an integer in \[0, 65535\]"):
        view(library.get("crossed_four_bar").model, port=99999)
    with pytest.raises(SystemExit) as info:
        main(["view", "x.npz", "--model", "crossed_four_bar", "--port", "99999", "--no-browser"])
    assert info.value.code == EXIT_USAGE
    assert "--port" in capsys.readouterr().err
