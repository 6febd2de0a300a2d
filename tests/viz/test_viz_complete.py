"""Plots and animations are correct and complete (issue 23): diagnostics on the active
constraints, the energy balance instead of work shown as drift, units, legends, integer rank
ticks, every model element drawn, a 2-D view for planar URDF loops, fast rendering."""

from __future__ import annotations

import numpy as np
import pytest

import nonmin
from nonmin import library
from nonmin.core import range_basis
from nonmin.viz import (
    animate,
    coordinate_units,
    energy_balance,
    frame_times,
    plot_trajectory,
    singularity_distance,
)
from nonmin.viz._scene import model_scene


@pytest.fixture(scope="module")
def arm_wall():
    """The demo's arm_wall scenario, shortened: free motion, then the wall impact."""
    from nonmin.cli import _scenario_dir
    from nonmin.io import load_scenario, run_scenario

    res = run_scenario(load_scenario(_scenario_dir() / "arm_wall.toml"), write=False, t_final=0.6,
                       progress=False)
    return res.model, res.trajectory


def test_singularity_distance_uses_the_active_constraints(arm_wall):
    model, traj = arm_wall
    ratio = singularity_distance(traj, model)
    te = traj.events[0].t
    pre = traj.t < te
    assert pre.any() and (~pre).any()
    assert set(traj.rank[pre]) == {4} and 5 in set(traj.rank[~pre])
    # before the impact only 4 rows are active: the old curve (rank 5 of the whole run) read 0
    assert np.all(ratio[pre] > 0.3), ratio[pre].min()
    # against an independent SVD of the active rows (equilibrated as range_basis does)
    i = int(np.flatnonzero(pre)[3])
    A = model.constraint_jacobian(float(traj.t[i]), traj.q[i], traj.active[i])
    s = range_basis(A).s
    assert ratio[i] == pytest.approx(s[3] / s[0], rel=1e-12)
    sv = np.linalg.svd(A / np.linalg.norm(A, axis=1, keepdims=True), compute_uv=False)
    assert ratio[i] == pytest.approx(sv[3] / sv[0], rel=1e-6)


def test_energy_balance_separates_work_from_drift(arm_wall):
    model, traj = arm_wall
    bal = energy_balance(traj, model)
    pre = traj.t < traj.events[0].t
    de = np.abs(traj.energy - traj.energy[0])
    # the controller does ~7.6 J of work before the impact: that is not drift
    assert de[pre].max() > 5.0
    assert np.abs(bal.work[pre]).max() > 5.0
    assert np.abs(bal.balance[pre]).max() < 0.01 * de[pre].max()
    # a conservative run: W = 0 and the balance is the drift itself
    mech = library.get("A01_pendulum")
    tr = nonmin.simulate(mech, (0.0, 0.5), dt=1e-2, progress=False)
    b = energy_balance(tr, mech.model)
    assert np.max(np.abs(b.work)) < 1e-12
    assert np.allclose(b.balance, tr.energy - tr.energy[0], atol=1e-12)
    # the simulation recorded W (Trajectory.work): known without the model too; a trajectory
    # without it (NaN: an old file, a batch run) and no model: the panel says W is unknown
    assert energy_balance(tr).known is True
    from dataclasses import replace

    old = replace(tr, work=np.full(len(tr), np.nan))
    assert energy_balance(old).known is False
    assert np.allclose(energy_balance(old, mech.model).work, tr.work, atol=1e-12)


def test_plot_units_legends_integer_rank_and_balance(arm_wall):
    model, traj = arm_wall
    fig = plot_trajectory(traj, model)
    try:
        q_ax, qd_ax, fc_ax, rank_ax, e_ax = fig.axes[:5]
        labels = [t.get_text() for t in q_ax.get_legend().get_texts()]
        assert any(lab.endswith("[m]") for lab in labels) and any(lab.endswith("[rad]") for lab in labels)
        assert "[m, rad]" in q_ax.get_ylabel() and "[m/s, rad/s]" in qd_ax.get_ylabel()
        assert "[N, N·m]" in fc_ax.get_ylabel()
        fig.canvas.draw()
        ticks = [t for t in rank_ax.get_yticks() if rank_ax.get_ylim()[0] <= t <= rank_ax.get_ylim()[1]]
        assert ticks and all(float(t).is_integer() for t in ticks)
        e_labels = [t.get_text() for t in e_ax.get_legend().get_texts()]
        # the drift is the balance with the work of forces, of friction and the impact losses
        # taken out, each shown on its own (arm_wall: the controller's work and the impact)
        assert any(lab.startswith("drift |E − E₀ − W − W_fr + L_imp|") for lab in e_labels)
        assert any(lab.startswith("|W| work of forces") for lab in e_labels)
        assert any(lab.startswith("L_imp energy lost at impacts") for lab in e_labels)
        # legends sit outside the axes (never over the curves or the event labels)
        bbox = q_ax.get_legend().get_window_extent()
        assert bbox.x0 >= q_ax.get_window_extent().x1 - 1
    finally:
        import matplotlib.pyplot as plt

        plt.close(fig)


def test_legend_of_the_15_coordinate_n_four_bar():
    mech = library.get("A02_n_four_bar", N=2)
    tr = nonmin.simulate(mech, (0.0, 0.05), dt=1e-2, progress=False)
    fig = plot_trajectory(tr, mech.model)
    try:
        assert mech.model.n == 15
        assert len(fig.axes[0].get_legend().get_texts()) == 15
        fig.canvas.draw()  # a constant rank (14) still gets integer ticks only
        rank_ax = fig.axes[3]
        ticks = [t for t in rank_ax.get_yticks() if rank_ax.get_ylim()[0] <= t <= rank_ax.get_ylim()[1]]
        assert ticks == [14.0]
    finally:
        import matplotlib.pyplot as plt

        plt.close(fig)


@pytest.mark.parametrize(("name", "kinds"), [
    ("arm2r_wall", {"wall", "pin", "bar", "joint"}),
    ("slider_crank", {"block", "guide", "pin", "bar"}),
    ("A01_pendulum", {"mass", "rod"}),
    ("A02_n_four_bar", {"pin", "bar", "joint"}),
    ("foot_friction", {"wall", "bar", "joint"}),  # its floor contacts (heel, toe) are walls
])
def test_every_element_has_a_drawing(name, kinds):
    mech = library.get(name)
    scene = model_scene(mech.model)
    drawn = {p.kind for p in scene.static} | {p.kind for p in scene.frame(mech.state.q)}
    assert kinds <= drawn, (name, drawn)


def test_released_constraint_is_drawn_light(arm_wall):
    model, traj = arm_wall
    scene = model_scene(model)
    wall = [p for p in scene.static_at(traj.active[0]) if p.kind == "wall"]
    assert wall and not wall[0].active
    wall = [p for p in scene.static_at(traj.active[-1]) if p.kind == "wall"]
    assert wall[0].active


def test_planar_urdf_loop_gets_a_2d_view():
    from nonmin.model.robots import fourbar

    model, state = fourbar()
    scene = model_scene(model, [state.q])
    assert scene.dim == 2 and scene.axes == ("x", "z")
    kinds = {p.kind for p in scene.frame(state.q)}
    assert {"bar", "pin", "closure"} <= kinds


def test_units_of_coordinates():
    from nonmin.model.robots import two_arm_grasp

    assert coordinate_units(library.get("slider_crank").model, ["crank.x", "crank.theta"]) == ("m", "rad")
    model, _ = two_arm_grasp()
    units = dict(zip(model.coordinate_names, coordinate_units(model, model.coordinate_names), strict=True))
    assert units["box.x"] == "m" and units["box.qw"] == "1" and units["left_yaw"] == "rad"


def test_demo_scene_renders_with_the_run_frame_count(tmp_path, arm_wall):
    model, traj = arm_wall
    fps = 15.0
    out = animate(traj, model, tmp_path / "a.gif", fps=fps, progress=False)
    from PIL import Image

    with Image.open(out) as im:
        frames = im.n_frames
        im.seek(frames - 1)
        last = np.asarray(im.convert("RGB"))
    assert frames == len(frame_times(traj.t, fps=fps))
    # the wall (dark grey, hatched) is in the picture
    grey = np.all(np.abs(last.astype(int) - 90) < 12, axis=-1)
    assert grey.sum() > 300


def test_singularity_distance_after_a_pin_is_released():
    """The issue's case: after a pin is released the curve read ~1e-17 (σ of the whole run's
    rank on the smaller active A); it is σ_r/σ₁ of the active rows, r their own rank."""
    from nonmin.sim import Deactivate, Event

    mech = library.get("A02_n_four_bar", N=2)
    pin = "A1"  # the middle ground pin
    release = Event(lambda t, q, qd, f_c: t - 0.05, direction=1, transition=Deactivate(pin), name="release")
    traj = nonmin.simulate(mech, (0.0, 0.1), dt=1e-3, events=[release], progress=False)
    after = np.array([pin not in a for a in traj.active])
    assert after.any() and (~after).any()
    ratio = singularity_distance(traj, mech.model)
    i = int(np.flatnonzero(after)[5])
    A = mech.model.constraint_jacobian(float(traj.t[i]), traj.q[i], traj.active[i])
    sv = np.linalg.svd(A / np.linalg.norm(A, axis=1, keepdims=True), compute_uv=False)
    r = int(traj.rank[i])
    assert ratio[i] == pytest.approx(sv[r - 1] / sv[0], rel=1e-6)
    assert np.all(ratio[after] > 1e-3), ratio[after].min()


def test_rendering_progress_after_two_seconds(capsys):
    """Rendering that takes more than 2 s reports on stderr (every 2 s, and at the end);
    quicker rendering stays silent. The clock is a list of readings."""
    from nonmin.viz._animate import Progress

    readings = iter([0.0, 0.5, 2.5, 3.0, 4.6, 5.0])
    p = Progress("rendering a.gif", True)
    p._clock = lambda: next(readings)
    p.t0 = p._clock()
    p._last = p.t0
    p(10, 100)  # 0.5 s: silent
    assert capsys.readouterr().err == ""
    p(50, 100)  # 2.5 s: shown
    assert "rendering a.gif: 50/100 frames, 2.5 s" in capsys.readouterr().err
    p(60, 100)  # 3.0 s: within 2 s of the last line
    assert capsys.readouterr().err == ""
    p(90, 100)  # 4.6 s
    assert "90/100" in capsys.readouterr().err
    p(100, 100)  # the end is always reported once shown
    assert "100/100" in capsys.readouterr().err
    assert p.shown
