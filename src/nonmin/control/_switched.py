"""A controller chosen by the active constraint set (topology-dependent control)."""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

from numpy.typing import ArrayLike

from ..errors import InputError, UnknownNameError
from ..model import Model
from ._common import ControlInfo, FloatArray
from ._protocol import Controller

__all__ = ["Switched"]


@dataclass(frozen=True, eq=False)
class Switched(Controller):
    """Dispatch to one controller per active constraint set.

    Parameters
    ----------
    model : Model
        Used to resolve active sets (``None`` means the model's default).
    modes : mapping of (iterable of str) to Controller
        Active set → controller. Keys are normalized to frozensets of constraint names.
    default : Controller, optional
        Used for active sets not in ``modes``; without it such a set raises
        :class:`~nonmin.errors.UnknownNameError`.

    The state is a tuple with one entry per mode (then the default); only the controller in
    charge is updated after each accepted step.
    """

    model: Model
    modes: Mapping[Any, Controller]
    default: Controller | None = None

    def __post_init__(self) -> None:
        norm: dict[frozenset[str], Controller] = {}
        for key, ctrl in dict(self.modes).items():
            act = self.model.resolve_active(key)
            if not isinstance(ctrl, Controller):
                raise InputError(f"modes[{sorted(act)}] must be a Controller, got {type(ctrl).__name__}")
            norm[act] = ctrl
        if self.default is not None and not isinstance(self.default, Controller):
            raise InputError(f"default must be a Controller, got {type(self.default).__name__}")
        if not norm and self.default is None:
            raise InputError("Switched needs at least one mode or a default controller")
        object.__setattr__(self, "modes", norm)
        object.__setattr__(self, "_order", tuple(norm))

    def select(self, active: Iterable[str] | None = None) -> tuple[int, Controller]:
        """Index (in the state tuple) and controller in charge for an active set."""
        act = self.model.resolve_active(active)
        order: tuple[frozenset[str], ...] = self._order  # type: ignore[attr-defined]
        if act in self.modes:
            return order.index(act), self.modes[act]
        if self.default is None:
            raise UnknownNameError(
                f"Switched: no controller for active set {sorted(act)}; modes: "
                f"{[sorted(k) for k in order]} and no default"
            )
        return len(order), self.default

    def _controllers(self) -> list[Controller]:
        ctrls = list(self.modes.values())
        if self.default is not None:
            ctrls.append(self.default)
        return ctrls

    def initial_state(self) -> tuple[Any, ...]:
        """One initial state per mode (then the default)."""
        return tuple(c.initial_state() for c in self._controllers())

    def _sub(self, state: Any, i: int, ctrl: Controller) -> Any:
        if isinstance(state, tuple) and len(state) == len(self._controllers()):
            return state[i]
        return ctrl.initial_state()

    def __call__(
        self, t: float, q: ArrayLike, qd: ArrayLike, state: Any = None, *, active: Iterable[str] | None = None
    ) -> FloatArray:
        """Actuator forces of the controller in charge."""
        i, ctrl = self.select(active)
        return ctrl(t, q, qd, self._sub(state, i, ctrl), active=active)

    def update(
        self, t: float, q: ArrayLike, qd: ArrayLike, state: Any, *, active: Iterable[str] | None = None
    ) -> tuple[Any, ...]:
        """Update the state of the controller in charge only."""
        i, ctrl = self.select(active)
        st = state if isinstance(state, tuple) and len(state) == len(self._controllers()) else self.initial_state()
        new = list(st)
        new[i] = ctrl.update(t, q, qd, st[i], active=active)
        return tuple(new)

    def engine_controller(self, model: Any, program: Any, active: frozenset[str]) -> Any | None:
        """The compiled form of the controller in charge of ``active`` (each run of the engine
        has one active set), or None (called back)."""
        from ._engine import compile_controller

        return compile_controller(self, model, program, active)

    def engine_state(self, state: Any, compiled: Any) -> Any:
        """The state tuple with the compiled mode's slot advanced over the steps it took."""
        from ._engine import merge_state

        return merge_state(state, compiled, self.model.k)

    def info(
        self, t: float, q: ArrayLike, qd: ArrayLike, state: Any = None, *, active: Iterable[str] | None = None
    ) -> ControlInfo:
        """``info`` of the controller in charge (which must provide one)."""
        i, ctrl = self.select(active)
        fn = getattr(ctrl, "info", None)
        if fn is None:
            raise InputError(f"{type(ctrl).__name__} has no info() method")
        return fn(t, q, qd, self._sub(state, i, ctrl), active=active)  # type: ignore[no-any-return]
