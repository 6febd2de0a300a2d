"""Registry of named mechanisms.

Each mechanism is a function returning a :class:`Mechanism` (model + consistent initial state
+ benchmark horizon + description + literature reference). Register it with the
:func:`register` decorator in a module of this package and import that module from
``nonmin/library/__init__.py``::

    from ._registry import Mechanism, register

    @register("A04_bricard")
    def a04_bricard(*, t_final: float = 10.0) -> Mechanism:
        \"\"\"Bricard's mechanism (IFToMM A04). Source: ...\"\"\"
        model = ...
        return Mechanism(model=model, state=..., t_final=t_final,
                         description="...", reference="...")

Rules: parameters are keyword-only with defaults (``get(name, **params)`` passes them through
and rejects unknown keywords); the returned state must be consistent
(:func:`nonmin.model.consistent`); the docstring names the source; ``model.outputs(t, q, qd)``
returns what the benchmark asks for.
"""

from __future__ import annotations

import inspect
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, TypeVar

from ..errors import InputError, NonminError, UnknownNameError
from ..model import Model, State

__all__ = ["Mechanism", "get", "names", "register"]


@dataclass(frozen=True)
class Mechanism:
    """A named mechanism: model, consistent initial state and benchmark data.

    Attributes
    ----------
    model : Model
    state : State
        Consistent initial state (``φ(q0) = 0``, ``A qd0 + φ_t = 0`` for the active set).
    t_final : float
        Benchmark horizon (s).
    description : str
    reference : str
        Literature source of the problem and its reference solution.
    name : str
        Registry name.
    params : dict
        The parameters it was built with.
    """

    model: Model
    state: State
    t_final: float
    description: str
    reference: str
    name: str = ""
    params: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        try:
            tf = float(self.t_final)
        except (TypeError, ValueError):
            tf = math.nan
        if not (math.isfinite(tf) and tf > 0.0):
            raise InputError(f"t_final must be a positive finite horizon [s], got {self.t_final!r}")


F = TypeVar("F", bound=Callable[..., Mechanism])

_REGISTRY: dict[str, Callable[..., Mechanism]] = {}


def register(name: str) -> Callable[[F], F]:
    """Decorator registering a mechanism factory under ``name`` (unique)."""

    def deco(fn: F) -> F:
        if name in _REGISTRY and _REGISTRY[name] is not fn:
            raise InputError(f"mechanism name {name!r} is already registered")
        _REGISTRY[name] = fn
        return fn

    return deco


def names() -> tuple[str, ...]:
    """Registered mechanism names, sorted."""
    return tuple(sorted(_REGISTRY))


def get(name: str, **params: Any) -> Mechanism:
    """Build the mechanism ``name`` with keyword parameters ``params``.

    Raises
    ------
    UnknownNameError
        If ``name`` is not registered.
    InputError
        If a parameter is not accepted by that mechanism.
    """
    try:
        fn = _REGISTRY[name]
    except KeyError:
        raise UnknownNameError(f"unknown mechanism {name!r}; known: {list(names())}") from None
    accepted = {
        p.name
        for p in inspect.signature(fn).parameters.values()
        if p.kind in (inspect.Parameter.KEYWORD_ONLY, inspect.Parameter.POSITIONAL_OR_KEYWORD)
    }
    unknown = set(params) - accepted
    if unknown:
        raise InputError(
            f"mechanism {name!r}: unknown parameter(s) {sorted(unknown)}; accepted: {sorted(accepted)}"
        )
    try:
        mech = fn(**params)
    except NonminError as exc:
        if not params:
            raise
        try:  # the same error, naming the mechanism and the parameters that led to it
            named = type(exc)(f"mechanism {name!r} with parameters {params!r}: {exc}")
        except TypeError:  # an error type with more arguments
            raise exc from None
        raise named from None
    except (TypeError, ValueError, ArithmeticError) as exc:
        raise InputError(
            f"mechanism {name!r}: cannot build it with parameters {params!r}: "
            f"{type(exc).__name__}: {exc}"
        ) from None
    if not mech.name:
        object.__setattr__(mech, "name", name)
    if not mech.params:
        object.__setattr__(mech, "params", dict(params))
    return mech
