"""The controller protocol: controllers are values with explicit state.

A controller is an immutable object built for one model. It is called on its own or by the
simulator as ``u = controller(t, q, qd, state, active=...)`` and returns the actuator forces
``u`` (shape ``(k,)``, one per column of ``B``). Anything that evolves (integral terms, a
reference generator's phase, saturation bookkeeping) lives in ``state``: the controller
provides :meth:`Controller.initial_state` and the pure update :meth:`Controller.update`,
which the simulator calls after every accepted step.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Iterable
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["Controller"]


class Controller(ABC):
    """Abstract base of controllers (see module docstring)."""

    def initial_state(self) -> Any:
        """Controller state at the start of a run (``None`` for static controllers)."""
        return None

    @abstractmethod
    def __call__(
        self,
        t: float,
        q: ArrayLike,
        qd: ArrayLike,
        state: Any = None,
        *,
        active: Iterable[str] | None = None,
    ) -> NDArray[np.float64]:
        """Actuator forces ``u``, shape (k,), at ``(t, q, qd)`` with the given active constraints."""

    def update(
        self,
        t: float,
        q: ArrayLike,
        qd: ArrayLike,
        state: Any,
        *,
        active: Iterable[str] | None = None,
    ) -> Any:
        """Next controller state after an accepted step ending at ``(t, q, qd)``; pure."""
        return state

    def engine_controller(self, model: Any, program: Any, active: frozenset[str]) -> Any | None:
        """The compiled engine's form of this controller for the active set ``active``, or
        None (default): the engine then calls the controller back at every evaluation.

        ``program`` is the model's compiled program (:meth:`nonmin.model.Model.engine_program`).
        A compiled form must compute the same ``u`` as :meth:`__call__` to round-off.
        """
        return None

    def engine_state(self, state: Any, compiled: Any) -> Any:
        """The controller state after the accepted steps that ``compiled`` (what
        :meth:`engine_controller` returned) took: what :meth:`update` over those steps would
        have given."""
        return state
