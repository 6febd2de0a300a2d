"""Command line and plotting helpers shared by the control examples (not an example itself)."""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt


def parse(name: str, doc: str | None, argv: list[str] | None) -> argparse.Namespace:
    """``--out DIR`` (default ``./out/<name>``) and ``--quick`` (short run, for tests)."""
    p = argparse.ArgumentParser(description=(doc or name).strip().splitlines()[0])
    p.add_argument("--out", type=Path, default=Path("out") / name, help="folder for the plots")
    p.add_argument("--quick", action="store_true", help="short, coarse run (used by the tests)")
    args = p.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    return args


def save(fig: plt.Figure, out: Path, filename: str) -> Path:
    """Save and close a figure; print its path."""
    path = out / filename
    fig.savefig(path, dpi=110)
    plt.close(fig)
    print(f"wrote {path}")
    return path


def figure(rows: int, cols: int = 1, *, size: tuple[float, float] = (7.0, 6.0)):
    """A figure with a grid of axes (always a flat list)."""
    fig, axes = plt.subplots(rows, cols, figsize=size, constrained_layout=True, squeeze=False)
    return fig, list(axes.ravel())
