"""Lazy matplotlib import (the only place nonmin imports matplotlib)."""

from __future__ import annotations

from typing import Any

from ..errors import missing_dependency


def pyplot() -> Any:
    """Return ``matplotlib.pyplot`` with the non-interactive Agg backend, or raise.

    Raises
    ------
    MissingDependencyError
        If matplotlib is not installed (extra ``plot``).
    """
    try:
        import matplotlib
    except ImportError:
        raise missing_dependency("matplotlib", "plot", "Plotting") from None
    if matplotlib.get_backend().lower() not in ("agg", "pdf", "svg", "cairo"):
        try:
            matplotlib.use("Agg", force=True)
        except Exception:  # pragma: no cover - backend already fixed by the user
            pass
    import matplotlib.pyplot as plt

    return plt
