"""Paths of the robot description files shipped with nonmin (``nonmin/data/robots``)."""

from __future__ import annotations

from pathlib import Path

from ...errors import UnknownNameError

__all__ = ["data_path"]

_ROOT = Path(__file__).resolve().parents[2] / "data" / "robots"


def data_path(name: str) -> Path:
    """Path of a shipped robot file, e.g. ``data_path("arm3.urdf")``.

    Raises
    ------
    UnknownNameError
        If no such file is shipped; the message lists the available files.
    """
    p = _ROOT / name
    if not p.is_file():
        known = sorted(x.name for x in _ROOT.glob("*") if x.is_file())
        raise UnknownNameError(f"no robot file {name!r} in {_ROOT}; available: {known}")
    return p
