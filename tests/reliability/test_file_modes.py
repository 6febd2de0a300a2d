"""Files nonmin writes durably get the permissions of an ordinary file (umask), not 0600.

The durable writers (nonmin._files) write a temporary made by ``tempfile.mkstemp`` and rename
it over the target; mkstemp creates its file with mode 0600, so every trajectory, CSV, figure
and animation was readable by its owner only — unlike any file ``open(..., "w")`` makes.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path

import numpy as np
import pytest

from nonmin._files import atomic_path, atomic_write, write_text

pytestmark = pytest.mark.skipif(os.name != "posix", reason="POSIX permission bits")


def _mode(p: Path) -> int:
    return stat.S_IMODE(p.stat().st_mode)


@pytest.fixture()
def umask_022():
    old = os.umask(0o022)
    try:
        yield
    finally:
        os.umask(old)


def test_new_files_follow_the_umask(tmp_path: Path, umask_022: None) -> None:
    with atomic_write(tmp_path / "a.bin") as fh:
        fh.write(b"x")
    write_text(tmp_path / "b.txt", "y")
    with atomic_path(tmp_path / "c.png") as tmp:
        tmp.write_bytes(b"z")
    for name in ("a.bin", "b.txt", "c.png"):
        assert _mode(tmp_path / name) == 0o644, name
    # an ordinary open() makes the same
    (tmp_path / "plain").write_text("p")
    assert _mode(tmp_path / "plain") == 0o644


def test_a_replaced_file_keeps_its_mode(tmp_path: Path, umask_022: None) -> None:
    target = tmp_path / "keep.txt"
    target.write_text("old")
    os.chmod(target, 0o640)
    write_text(target, "new")
    assert target.read_text() == "new" and _mode(target) == 0o640


def test_trajectory_save_is_readable_by_the_group(tmp_path: Path, umask_022: None) -> None:
    from nonmin import library, simulate

    traj = simulate(library.get("A01_pendulum"), 0.01, dt=1e-3, t_eval=np.linspace(0, 0.01, 3))
    out = tmp_path / "run.npz"
    traj.save(out)
    assert _mode(out) == 0o644
