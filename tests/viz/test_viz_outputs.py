"""Plots and animations (2D and 3D) are written and non-empty; bad inputs are typed errors."""

import numpy as np
import pytest

from nonmin import library
from nonmin.errors import InputError
from nonmin.sim import simulate
from nonmin.viz import animate, frame_geometries, plot_snapshot, plot_trajectory, save_figure


def _nonblank(path):
    from PIL import Image

    with Image.open(path) as im:
        assert np.asarray(im.convert("L"), dtype=float).std() > 5.0


@pytest.fixture(scope="module")
def top_traj():
    mech = library.get("spinning_top")
    return mech, simulate(mech, (0.0, 0.2), method="rk4", dt=2e-3, progress=False)


def test_3d_animation_snapshot_and_plot(tmp_path, top_traj):
    mech, traj = top_traj
    assert mech.model.geometry(traj.q[0]).dim == 3
    gif = animate(traj, mech.model, tmp_path / "top.gif", fps=10)
    assert gif.stat().st_size > 5_000
    snap = save_figure(plot_snapshot(mech.model, traj.q[::20]), tmp_path / "snap.png")
    _nonblank(snap)
    fig = plot_trajectory(traj, mech.model)
    assert len(fig.axes) >= 5
    _nonblank(save_figure(fig, tmp_path / "traj.png"))


def test_save_figure_lays_out_once_with_the_same_pixels(tmp_path, top_traj):
    """save_figure runs a PNG's constrained layout once (savefig would run it twice): the
    image is the one savefig writes, pixel for pixel (shared axes, a twin, a log axis and a
    legend outside the axes, as in plot_trajectory; and a 3-D snapshot)."""
    from PIL import Image

    from nonmin.viz._mpl import pyplot

    plt = pyplot()
    mech, traj = top_traj

    def panels():
        fig, axes = plt.subplots(2, 1, figsize=(5, 4), sharex=True, constrained_layout=True)
        axes[0].plot(traj.t, traj.q[:, :3], lw=1)
        axes[0].legend(["a [m]", "b [m]", "c [m]"], loc="upper left", bbox_to_anchor=(1.01, 1.0))
        axes[1].twinx().semilogy(traj.t, np.abs(traj.qd[:, 0]) + 1e-12)
        axes[1].set_ylabel("rank\nof A")
        fig.suptitle("panels")
        return fig

    for name, make in (("panels", panels), ("snap", lambda: plot_snapshot(mech.model, traj.q[::40]))):
        ref = make()
        assert ref.get_layout_engine() is not None
        ref.savefig(tmp_path / f"{name}_ref.png", dpi=110)
        plt.close(ref)
        save_figure(make(), tmp_path / f"{name}.png", dpi=110)
        with Image.open(tmp_path / f"{name}_ref.png") as a, Image.open(tmp_path / f"{name}.png") as b:
            assert np.array_equal(np.asarray(a), np.asarray(b)), name


def test_2d_mp4(tmp_path):
    pytest.importorskip("imageio_ffmpeg")
    mech = library.get("A01_pendulum")
    traj = simulate(mech, (0.0, 0.4), method="rk4", dt=1e-2, progress=False)
    out = animate(traj, mech.model, tmp_path / "p.mp4", fps=10)
    assert out.stat().st_size > 1_000


def test_frames_follow_the_trajectory():
    mech = library.get("A01_pendulum")
    traj = simulate(mech, (0.0, 1.0), method="rk4", dt=1e-2, progress=False)
    tf, geoms = frame_geometries(mech.model.geometry, traj.t, traj.q, fps=10)
    assert tf[0] == 0.0 and tf[-1] == pytest.approx(1.0) and len(geoms) == len(tf) == 11


def test_bad_inputs(tmp_path, top_traj):
    mech, traj = top_traj
    with pytest.raises(InputError, match=r"\.gif or \.mp4"):
        animate(traj, mech.model, tmp_path / "x.avi")
    with pytest.raises(InputError, match="shape"):
        frame_geometries(mech.model.geometry, traj.t, traj.q[:-1])
