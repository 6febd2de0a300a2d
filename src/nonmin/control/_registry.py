"""Named controller factories, for scenario files (``[controller] type = ...``) and ``nonmin list``.

Each factory takes the model first and keyword arguments that are plain data (numbers, lists,
strings, tables), so that a TOML table can describe it.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

from numpy.typing import ArrayLike

from ..errors import UnknownNameError
from ..model import Model
from ._force import ForceControl
from ._regulator import Regulator
from ._tracking import Tracker

__all__ = ["CONTROLLERS", "get", "names"]


def _regulator(model: Model, *, target: ArrayLike, Kp: ArrayLike = 1.0, Kd: ArrayLike = 1.0, **kw: Any) -> Regulator:
    """The corrected paper regulator ``f_∥ = −P(f_g + Kp e + Kd qd)`` (see :class:`Regulator`)."""
    return Regulator(model, target, Kp, Kd, **kw)


def _tracker(model: Model, *, reference: ArrayLike, Kp: ArrayLike = 1.0, Kd: ArrayLike = 1.0, **kw: Any) -> Tracker:
    """Trajectory tracking on the projected dynamics (a constant reference from a file)."""
    return Tracker(model, reference, Kp, Kd, **kw)


def _hybrid_force(
    model: Model,
    *,
    target: ArrayLike,
    forces: Mapping[str, Any],
    Kp: ArrayLike = 1.0,
    Kd: ArrayLike = 1.0,
    u_min: ArrayLike | None = None,
    u_max: ArrayLike | None = None,
    **kw: Any,
) -> ForceControl:
    """Hybrid position/force control (:class:`ForceControl`): a :class:`Regulator` in N(A) plus commanded constraint
    forces ``{constraint name: force}`` (corrected eq. (fc_fp)), see :class:`ForceControl`."""
    motion = Regulator(model, target, Kp, Kd, **kw)
    return ForceControl(motion, dict(forces), u_min=u_min, u_max=u_max)


#: Controller factories by name (the ``[controller] type`` of scenario files).
CONTROLLERS: dict[str, Callable[..., Any]] = {
    "regulator": _regulator,
    "tracker": _tracker,
    "force_control": _hybrid_force,
    # the name before 0.3, kept so that older scenario files still load
    "hybrid_force": _hybrid_force,
}


def names() -> tuple[str, ...]:
    """Registered controller names."""
    return tuple(sorted(CONTROLLERS))


def get(name: str) -> Callable[..., Any]:
    """The factory ``factory(model, **kwargs)`` registered under ``name``."""
    try:
        return CONTROLLERS[name]
    except KeyError:
        raise UnknownNameError(f"unknown controller {name!r}; known: {list(names())}") from None
