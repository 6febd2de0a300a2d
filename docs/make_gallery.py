"""Regenerate the README gallery (docs/img/) from a `nonmin demo` output folder.

Usage::

    nonmin demo --out nonmin-demo          # runs the three built-in scenarios
    python docs/make_gallery.py nonmin-demo

Copies the demo's plots and animations and adds a snapshot of the N four-bar drawn at the
configurations where it passes its horizontal (singular) configuration.
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
    for p in sorted(IMG.iterdir()):
        print(f"{p.name:28s} {p.stat().st_size / 1024:8.1f} KiB")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "nonmin-demo")
