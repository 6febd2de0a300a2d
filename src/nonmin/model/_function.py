"""Model source 4: hand-written functions, for users who already have M, C, A in code."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from ..errors import InputError, ModelError, NonFiniteError, NonminError, ShapeError
from ._protocol import ConstraintSpec, ConstraintTerms, FloatArray, Geometry, Model

__all__ = ["FunctionConstraint", "FunctionModel"]


def _call(fn: Callable[..., Any], name: str, shape: tuple[int, ...], *args: Any) -> FloatArray:
    """Call a user function of the model; its exceptions and non-numeric or non-finite
    results become nonmin errors naming it (a simulation adds the time)."""
    try:
        raw = fn(*args)
    except NonminError:
        raise
    except Exception as exc:
        raise ModelError(f"user function {name} raised {type(exc).__name__}: {exc}") from exc
    try:
        out = np.asarray(raw, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ShapeError(f"{name} must return numbers of shape {shape}, got {type(raw).__name__}: {exc}") from None
    if out.shape != shape:
        if out.size == int(np.prod(shape)):
            out = out.reshape(shape)
        else:
            raise ShapeError(f"{name} must return shape {shape}, got shape {out.shape}")
    if not np.isfinite(out).all():
        bad = tuple(int(i) for i in np.argwhere(~np.isfinite(out))[0])
        raise NonFiniteError(f"{name} returned a non-finite value at index {bad}: {out[bad]!r}")
    return out


@dataclass(frozen=True)
class FunctionConstraint:
    """A constraint given by user functions. Build it with the named constructors.

    All callables take ``(t, q)`` or ``(t, q, qd)`` so that one signature serves every kind.
    """

    spec: ConstraintSpec
    jacobian: Callable[[float, FloatArray], ArrayLike]
    bias: Callable[[float, FloatArray, FloatArray], ArrayLike]
    residual: Callable[[float, FloatArray], ArrayLike] | None = None
    time_derivative: Callable[[float, FloatArray], ArrayLike] | None = None

    @classmethod
    def holonomic(
        cls,
        name: str,
        phi: Callable[[FloatArray], ArrayLike],
        jacobian: Callable[[FloatArray], ArrayLike],
        adot_qd: Callable[[FloatArray, FloatArray], ArrayLike],
        *,
        dim: int = 1,
        description: str = "",
    ) -> FunctionConstraint:
        """``φ(q) = 0`` with ``A = ∂φ/∂q`` and ``Ȧ qd``."""
        return cls(
            spec=ConstraintSpec(name, "holonomic", dim, description),
            jacobian=lambda t, q: jacobian(q),
            bias=lambda t, q, qd: adot_qd(q, qd),
            residual=lambda t, q: phi(q),
        )

    @classmethod
    def unilateral(
        cls,
        name: str,
        gap: Callable[[FloatArray], ArrayLike],
        jacobian: Callable[[FloatArray], ArrayLike],
        adot_qd: Callable[[FloatArray, FloatArray], ArrayLike],
        *,
        description: str = "",
    ) -> FunctionConstraint:
        """``gap(q) ≥ 0`` (one row); an equality ``gap = 0`` while active."""
        return cls(
            spec=ConstraintSpec(name, "unilateral", 1, description),
            jacobian=lambda t, q: jacobian(q),
            bias=lambda t, q, qd: adot_qd(q, qd),
            residual=lambda t, q: gap(q),
        )

    @classmethod
    def nonholonomic(
        cls,
        name: str,
        matrix: Callable[[FloatArray], ArrayLike],
        adot_qd: Callable[[FloatArray, FloatArray], ArrayLike],
        *,
        dim: int = 1,
        description: str = "",
    ) -> FunctionConstraint:
        """Pfaffian ``A(q) qd = 0`` with no position-level form."""
        return cls(
            spec=ConstraintSpec(name, "nonholonomic", dim, description),
            jacobian=lambda t, q: matrix(q),
            bias=lambda t, q, qd: adot_qd(q, qd),
        )

    @classmethod
    def rheonomic(
        cls,
        name: str,
        phi: Callable[[float, FloatArray], ArrayLike],
        jacobian: Callable[[float, FloatArray], ArrayLike],
        phi_t: Callable[[float, FloatArray], ArrayLike],
        gamma: Callable[[float, FloatArray, FloatArray], ArrayLike],
        *,
        dim: int = 1,
        description: str = "",
    ) -> FunctionConstraint:
        """``φ(q, t) = 0``; ``A = ∂φ/∂q``, ``φ_t = ∂φ/∂t``, ``γ = Ȧ qd + 2 φ_tq qd + φ_tt``."""
        return cls(
            spec=ConstraintSpec(name, "rheonomic", dim, description),
            jacobian=jacobian,
            bias=gamma,
            residual=phi,
            time_derivative=phi_t,
        )


@dataclass(frozen=True)
class FunctionModel(Model):
    """A model from hand-written functions of ``q`` (and ``qd``).

    Parameters
    ----------
    name : str
    coordinate_names : tuple of str
        One name per coordinate (n = its length).
    mass : callable ``q -> M``, shape (n, n)
    coriolis : callable ``(q, qd) -> C``, shape (n, n)
        Christoffel-symbol Coriolis matrix.
    conservative : callable ``q -> f_g``, shape (n,)
        ``−∂V/∂q``.
    potential : callable ``q -> V``
    constraints : tuple of FunctionConstraint
    default_active : frozenset of str, optional
        Defaults to every non-unilateral constraint.
    actuator_names : tuple of str
    input_matrix_fn : callable ``q -> B``, shape (n, k), optional
    passive : callable ``(t, q, qd) -> f_p``, optional
    outputs_fn : callable ``(t, q, qd) -> dict``, optional
    geometry_fn : callable ``q -> Geometry``, optional
    params : dict
        Free parameters, for the user's bookkeeping (``replace(params=...)`` does not
        re-evaluate closures).

    Examples
    --------
    A point pendulum of length 1 in Cartesian coordinates (x, y):

    >>> import numpy as np
    >>> from nonmin.model import FunctionModel, FunctionConstraint
    >>> rod = FunctionConstraint.holonomic(
    ...     "rod", phi=lambda q: [0.5 * (q @ q - 1.0)], jacobian=lambda q: q[None, :],
    ...     adot_qd=lambda q, qd: [qd @ qd])
    >>> pend = FunctionModel(
    ...     name="pendulum", coordinate_names=("x", "y"), mass=lambda q: np.eye(2),
    ...     coriolis=lambda q, qd: np.zeros((2, 2)), conservative=lambda q: [0.0, -9.81],
    ...     potential=lambda q: 9.81 * q[1], constraints=(rod,))
    >>> pend.n, pend.constraint_names
    (2, ('rod',))
    """

    name: str
    coordinate_names: tuple[str, ...]
    mass: Callable[[FloatArray], ArrayLike]
    coriolis: Callable[[FloatArray, FloatArray], ArrayLike]
    conservative: Callable[[FloatArray], ArrayLike]
    potential: Callable[[FloatArray], float]
    function_constraints: tuple[FunctionConstraint, ...] = ()
    default_active_names: frozenset[str] | None = None
    actuator_names: tuple[str, ...] = ()
    input_matrix_fn: Callable[[FloatArray], ArrayLike] | None = None
    passive: Callable[[float, FloatArray, FloatArray], ArrayLike] | None = None
    outputs_fn: Callable[[float, FloatArray, FloatArray], dict[str, Any]] | None = None
    geometry_fn: Callable[[FloatArray], Geometry] | None = None
    params: dict[str, Any] = field(default_factory=dict)

    def __init__(
        self,
        name: str,
        coordinate_names: Iterable[str],
        mass: Callable[[FloatArray], ArrayLike],
        coriolis: Callable[[FloatArray, FloatArray], ArrayLike],
        conservative: Callable[[FloatArray], ArrayLike],
        potential: Callable[[FloatArray], float],
        constraints: Iterable[FunctionConstraint] = (),
        default_active: Iterable[str] | None = None,
        actuator_names: Iterable[str] = (),
        input_matrix_fn: Callable[[FloatArray], ArrayLike] | None = None,
        passive: Callable[[float, FloatArray, FloatArray], ArrayLike] | None = None,
        outputs_fn: Callable[[float, FloatArray, FloatArray], dict[str, Any]] | None = None,
        geometry_fn: Callable[[FloatArray], Geometry] | None = None,
        params: dict[str, Any] | None = None,
    ) -> None:
        cons = tuple(constraints)
        for c in cons:
            if not isinstance(c, FunctionConstraint):
                raise InputError(
                    f"constraints must be FunctionConstraint values, got {type(c).__name__}"
                )
        names = [c.spec.name for c in cons]
        if len(set(names)) != len(names):
            raise InputError(f"constraint names must be unique, got {names}")
        coords = tuple(coordinate_names)
        if not coords:
            raise InputError("coordinate_names must name at least one coordinate")
        if isinstance(coordinate_names, str) or not all(isinstance(c, str) for c in coords):
            raise InputError(f"coordinate_names must be a sequence of strings, got {coordinate_names!r}")
        if len(set(coords)) != len(coords):
            dup = sorted({c for c in coords if coords.count(c) > 1})
            raise InputError(f"coordinate_names must be unique (q0.<name>, plots and files use them), "
                             f"got {dup} more than once")  # fmt: skip
        for fname, fn in (("mass", mass), ("coriolis", coriolis), ("conservative", conservative),
                          ("potential", potential), ("input_matrix_fn", input_matrix_fn),
                          ("passive", passive), ("outputs_fn", outputs_fn), ("geometry_fn", geometry_fn)):
            if fn is not None and not callable(fn):
                raise InputError(f"{fname} must be a callable, got {type(fn).__name__}")
        s = object.__setattr__
        s(self, "name", str(name))
        s(self, "coordinate_names", coords)
        s(self, "mass", mass)
        s(self, "coriolis", coriolis)
        s(self, "conservative", conservative)
        s(self, "potential", potential)
        s(self, "function_constraints", cons)
        dflt = (
            frozenset(c.spec.name for c in cons if c.spec.kind != "unilateral")
            if default_active is None
            else frozenset(default_active)
        )
        s(self, "default_active_names", dflt)
        s(self, "actuator_names", tuple(actuator_names))
        s(self, "input_matrix_fn", input_matrix_fn)
        s(self, "passive", passive)
        s(self, "outputs_fn", outputs_fn)
        s(self, "geometry_fn", geometry_fn)
        s(self, "params", dict(params or {}))
        if self.k and input_matrix_fn is None:
            raise InputError("actuator_names given but no input_matrix_fn")
        self.resolve_active(dflt)

    # dataclasses.replace calls __init__ with field names; map them back
    def replace(self, **changes: Any) -> FunctionModel:
        kw: dict[str, Any] = {
            "name": self.name,
            "coordinate_names": self.coordinate_names,
            "mass": self.mass,
            "coriolis": self.coriolis,
            "conservative": self.conservative,
            "potential": self.potential,
            "constraints": self.function_constraints,
            "default_active": self.default_active_names,
            "actuator_names": self.actuator_names,
            "input_matrix_fn": self.input_matrix_fn,
            "passive": self.passive,
            "outputs_fn": self.outputs_fn,
            "geometry_fn": self.geometry_fn,
            "params": self.params,
        }
        unknown = set(changes) - set(kw)
        if unknown:
            raise InputError(f"replace(): unknown field(s) {sorted(unknown)}; known: {sorted(kw)}")
        kw.update(changes)
        return FunctionModel(**kw)

    @property
    def constraints(self) -> tuple[ConstraintSpec, ...]:  # type: ignore[override]
        return tuple(c.spec for c in self.function_constraints)

    @property
    def default_active(self) -> frozenset[str]:  # type: ignore[override]
        return self.default_active_names or frozenset()

    @property
    def has_outputs(self) -> bool:  # type: ignore[override]
        return self.outputs_fn is not None

    def mass_matrix(self, q: ArrayLike) -> FloatArray:
        n = self.n
        return _call(self.mass, "mass", (n, n), np.asarray(q, dtype=float))

    def coriolis_matrix(self, q: ArrayLike, qd: ArrayLike) -> FloatArray:
        n = self.n
        return _call(self.coriolis, "coriolis", (n, n), np.asarray(q, float), np.asarray(qd, float))

    def conservative_force(self, q: ArrayLike) -> FloatArray:
        return _call(self.conservative, "conservative", (self.n,), np.asarray(q, dtype=float))

    def potential_energy(self, q: ArrayLike) -> float:
        return float(_call(self.potential, "potential", (), np.asarray(q, dtype=float)))

    def passive_force(self, t: float, q: ArrayLike, qd: ArrayLike) -> FloatArray:
        if self.passive is None:
            return np.zeros(self.n)
        return _call(self.passive, "passive", (self.n,), t, np.asarray(q, float), np.asarray(qd, float))

    def input_matrix(self, q: ArrayLike) -> FloatArray:
        if self.input_matrix_fn is None:
            return np.zeros((self.n, 0))
        return _call(self.input_matrix_fn, "input_matrix_fn", (self.n, self.k), np.asarray(q, float))

    def constraint_terms(
        self, t: float, q: ArrayLike, qd: ArrayLike, active: Iterable[str] | None = None
    ) -> ConstraintTerms:
        act = self.resolve_active(active)
        qv = np.asarray(q, dtype=float)
        v = np.asarray(qd, dtype=float)
        n = self.n
        As, gs, ps, vs, hs = [], [], [], [], []
        for c in self.function_constraints:
            if c.spec.name not in act:
                continue
            d = c.spec.dim
            nm = c.spec.name
            A = _call(c.jacobian, f"constraint {nm!r} jacobian", (d, n), t, qv)
            As.append(A)
            gs.append(_call(c.bias, f"constraint {nm!r} bias", (d,), t, qv, v))
            if c.residual is not None:
                ps.append(_call(c.residual, f"constraint {nm!r} residual", (d,), t, qv))
                hs.append(np.ones(d, dtype=bool))
            else:
                ps.append(np.zeros(d))
                hs.append(np.zeros(d, dtype=bool))
            vel = A @ v
            if c.time_derivative is not None:
                vel = vel + _call(c.time_derivative, f"constraint {nm!r} phi_t", (d,), t, qv)
            vs.append(vel)
        if not As:
            return ConstraintTerms(
                np.zeros((0, n)), np.zeros(0), np.zeros(0), np.zeros(0), np.zeros(0, dtype=bool)
            )
        return ConstraintTerms(
            np.vstack(As), np.concatenate(gs), np.concatenate(ps), np.concatenate(vs), np.concatenate(hs)
        )

    def outputs(self, t: float, q: ArrayLike, qd: ArrayLike) -> dict[str, FloatArray]:
        if self.outputs_fn is None:
            return {}
        raw = self.outputs_fn(t, np.asarray(q, float), np.asarray(qd, float))
        return {k: np.asarray(v, dtype=float) for k, v in raw.items()}

    def geometry(self, q: ArrayLike) -> Geometry | None:
        return None if self.geometry_fn is None else self.geometry_fn(np.asarray(q, float))
