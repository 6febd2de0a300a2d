"""Regenerate the README gallery (docs/img/) from a `nonmin demo` output folder.

Usage::

    nonmin demo --out nonmin-demo          # runs the four built-in scenarios
    python docs/make_gallery.py nonmin-demo

Copies the demo's animations, redraws its plots with their models (σ_r/σ₁ of the active
constraints, the energy balance), adds a snapshot of the N four-bar drawn at the
configurations where it passes its horizontal (singular) configuration and, when the python
``playwright`` package and Debian's ``/usr/bin/chromium`` are installed, a screenshot of the
interactive viewer on the UR5 of example-robot-data with its tool point pinned (a loop
closure) (``docs/img/viewer_ur5.png``).
"""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

import numpy as np

from nonmin import library
from nonmin.sim import load_trajectory
from nonmin.viz import plot_snapshot, plot_trajectory, save_figure

IMG = Path(__file__).resolve().parent / "img"


def main(demo_dir: str) -> None:
    demo = Path(demo_dir)
    IMG.mkdir(parents=True, exist_ok=True)
    for name, lib, params in (
        ("n_four_bar", "A02_n_four_bar", {"N": 2}),
        ("crossed_four_bar", "crossed_four_bar", {}),
        ("arm_wall", "arm2r_wall", {}),
        ("foot_friction", "foot_friction", {}),
    ):
        traj = load_trajectory(demo / name / "trajectory.npz")
        model = library.get(lib, **params).model
        save_figure(plot_trajectory(traj, model, title=traj.metadata.get("scenario_name", name)),
                    IMG / f"{name}.png", dpi=70)
        shutil.copy(demo / name / "animation.gif", IMG / f"{name}.gif")
    # snapshot: the N four-bar from start through its first singular (horizontal) configuration
    traj = load_trajectory(demo / "n_four_bar" / "trajectory.npz")
    model = library.get("A02_n_four_bar", N=2).model
    times = [0.0, 0.25, 0.5, 0.714]
    qs = np.array([traj.q[np.argmin(np.abs(traj.t - t))] for t in times])
    save_figure(plot_snapshot(model, qs, title="A02 N four-bar reaching its singular configuration"),
                IMG / "n_four_bar_snapshot.png", dpi=80)
    try:
        viewer_screenshot(IMG / "viewer_ur5.png")
    except ImportError as exc:
        print(f"viewer screenshot skipped: {exc}")
    for p in sorted(IMG.iterdir()):
        print(f"{p.name:28s} {p.stat().st_size / 1024:8.1f} KiB")


def viewer_screenshot(path: Path) -> None:
    """Open the viewer on the UR5 loop in headless Chromium and save a screenshot."""
    import tempfile
    import time

    import pinocchio as pin
    from playwright.sync_api import sync_playwright

    import nonmin
    from nonmin.model import assemble
    from nonmin.model.robots import FrameConstraint, RobotModel
    from nonmin.viz.view import view

    urdf = (Path(pin.__file__).resolve().parents[4] / "share" / "example-robot-data" / "robots"
            / "ur_description" / "urdf" / "ur5_robot.urdf")
    free = RobotModel.from_urdf(urdf)
    qg = np.array([0.2, -1.0, 1.3, -0.6, 0.9, 0.4])
    con = FrameConstraint.point("closure", "ee_link", placement_b=free.frame_placement(qg, "ee_link"))
    model = RobotModel.from_urdf(urdf, constraints=[con])
    traj = nonmin.simulate(model, (0.0, 1.0), assemble(model, qg).q, np.zeros(6), dt=2e-3, progress=False)
    v = view(traj, model, port=0, open_browser=False, autoplay=False)
    try:
        v.show_time(0.6)
        args = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                "--disable-background-networking", "--disable-component-update", "--disable-sync",
                "--enable-unsafe-swiftshader", "--use-angle=swiftshader"]
        with sync_playwright() as p:
            ctx = p.chromium.launch_persistent_context(
                tempfile.mkdtemp(), executable_path="/usr/bin/chromium", args=args, headless=True,
                viewport={"width": 1000, "height": 620})
            page = ctx.new_page()
            page.goto(v.url)
            page.wait_for_selector("text=closure", timeout=120_000)
            time.sleep(4.0)
            for close in page.query_selector_all("button.mantine-Notification-closeButton, .mantine-Notification-closeButton"):
                close.click()
            time.sleep(0.5)
            page.screenshot(path=str(path))
            ctx.close()
    finally:
        v.stop()


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "nonmin-demo")
