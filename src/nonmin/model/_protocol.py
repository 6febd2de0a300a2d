"""The one model protocol that every model source produces.

A :class:`Model` is an immutable description of a mechanical system in n dependent coordinates:

    M(q) qdd + C(q, qd) qd = f_g(q) + f_p(t, q, qd) + B(q) u + f_c,     A_act(t, q) qd + φ_t = 0

* ``M`` inertia (symmetric, positive definite on N(A); may be singular, e.g. quaternions),
* ``C`` the Christoffel-symbol Coriolis matrix (``dM/dt − 2C`` skew),
* ``f_g = −∂V/∂q`` all conservative forces (gravity and springs), ``V`` the potential energy,
* ``f_p`` passive non-conservative forces (dampers, friction); zero by default,
* ``B`` the input matrix, one column per named actuator (``f = B u``),
* named constraints (:class:`ConstraintSpec`): holonomic ``φ(q) = 0``, rheonomic
  ``φ(q, t) = 0``, nonholonomic ``A(q) qd = 0`` and unilateral ``gap(q) ≥ 0``.

Which constraints are active is *data* — a ``frozenset`` of constraint names passed to every
evaluation — so switching topology never changes n and never rebuilds the model.
Rows of the stacked constraint arrays follow the declaration order of ``model.constraints``,
restricted to the active names (:meth:`Model.row_slices`).

Acceleration-level form used everywhere: ``A qdd + γ = 0`` with
``γ = Ȧ qd + 2 φ_tq qd + φ_tt`` (``γ = Ȧ qd`` for scleronomic constraints; Pinocchio's γ).
Velocity residual: ``A qd + φ_t``; position residual: ``φ`` (zero rows for nonholonomic).
"""

from __future__ import annotations

import dataclasses
import functools
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar, Literal, NamedTuple, TypeVar, get_args

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..errors import InputError, NonFiniteError, ShapeError, UnknownNameError

FloatArray = NDArray[np.float64]

ConstraintKind = Literal["holonomic", "rheonomic", "nonholonomic", "unilateral"]
#: The constraint kinds a :class:`ConstraintSpec` may have.
CONSTRAINT_KINDS: tuple[str, ...] = get_args(ConstraintKind)

__all__ = [
    "CONSTRAINT_KINDS",
    "Accelerations",
    "ConstraintKind",
    "ConstraintSpec",
    "ConstraintTerms",
    "FrictionContact",
    "Geometry",
    "Model",
    "ModelTerms",
    "State",
]


@dataclass(frozen=True)
class FrictionContact:
    """A point contact with Coulomb friction: its unilateral normal constraint, its tangential
    (sticking) constraint and the friction coefficient.

    The tangential constraint is a one-row nonholonomic constraint whose velocity ``A_t q̇`` is
    the slip velocity; it is active while the contact sticks. While the contact slips, the
    simulator applies the force ``−μ s N`` along that row (``s`` the slip direction, ``N`` the
    normal force from the projection; ``docs/theory.md`` "Coulomb friction").

    Attributes
    ----------
    normal : str
        The unilateral constraint (gap ≥ 0).
    tangent : str
        The tangential (sticking) constraint.
    mu : float
        Coulomb's coefficient μ_f ≥ 0 (static = kinetic).
    """

    normal: str
    tangent: str
    mu: float


@dataclass(frozen=True)
class ConstraintSpec:
    """Name, kind and number of rows of one constraint of a model.

    Attributes
    ----------
    name : str
        Unique name within the model (used in active sets, events and transitions).
    kind : {"holonomic", "rheonomic", "nonholonomic", "unilateral"}
        ``holonomic``: ``φ(q) = 0``, ``A = ∂φ/∂q``; ``rheonomic``: ``φ(q, t) = 0`` (driving
        constraints); ``nonholonomic``: ``A(q) qd = 0`` with no position-level φ;
        ``unilateral``: ``gap(q) ≥ 0`` (contact), an equality ``gap = 0`` while active.
    dim : int
        Number of scalar rows (≥ 1).
    description : str
        Free text (joint type, bodies it connects, ...).
    """

    name: str
    kind: ConstraintKind
    dim: int
    description: str = ""

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name:
            raise InputError(f"constraint name must be a non-empty string, got {self.name!r}")
        if self.kind not in CONSTRAINT_KINDS:
            raise InputError(
                f"constraint {self.name!r}: kind must be one of {CONSTRAINT_KINDS}, got {self.kind!r}"
            )
        if not isinstance(self.dim, int | np.integer) or self.dim < 1:
            raise InputError(f"constraint {self.name!r}: dim must be an integer ≥ 1, got {self.dim!r}")

    @property
    def has_position_level(self) -> bool:
        """True when the constraint has a position-level residual φ (all but nonholonomic)."""
        return self.kind != "nonholonomic"


class ConstraintTerms(NamedTuple):
    """Stacked constraint quantities of the active constraints at one state.

    Attributes
    ----------
    A : ndarray, shape (m, n)
        Constraint matrix (``∂φ/∂q`` for holonomic rows).
    gamma : ndarray, shape (m,)
        Acceleration bias: ``A qdd + γ = 0`` (``γ = Ȧ qd`` for scleronomic rows).
    phi : ndarray, shape (m,)
        Position residual φ (gap for unilateral rows; 0 for nonholonomic rows).
    velocity : ndarray, shape (m,)
        Velocity residual ``A qd + φ_t``.
    holonomic : ndarray of bool, shape (m,)
        Rows that have a position-level residual.
    """

    A: FloatArray
    gamma: FloatArray
    phi: FloatArray
    velocity: FloatArray
    holonomic: NDArray[np.bool_]


class ModelTerms(NamedTuple):
    """Everything the core kernels need at one state ``(t, q, qd, active)``.

    Attributes
    ----------
    M : ndarray, shape (n, n)
    h : ndarray, shape (n,)
        ``f_g − C qd`` (paper's h).
    f_passive : ndarray, shape (n,)
        Dampers and other passive non-conservative forces.
    B : ndarray, shape (n, k)
    constraints : ConstraintTerms
    """

    M: FloatArray
    h: FloatArray
    f_passive: FloatArray
    B: FloatArray
    constraints: ConstraintTerms


class Accelerations(NamedTuple):
    """Result of :meth:`Model.forward_dynamics` at one state or a batch of states.

    Attributes
    ----------
    qdd : ndarray, shape (..., n)
        Accelerations.
    f_c : ndarray, shape (..., n)
        Generalized constraint forces (``Aᵀλ``, computed without multipliers).
    rank : ndarray of int, shape (...)
        Numerical rank of the active constraint matrix.
    """

    qdd: FloatArray
    f_c: FloatArray
    rank: NDArray[np.intp]


@dataclass(frozen=True)
class State:
    """Explicit state of a (hybrid) mechanical system: time, coordinates, velocities, mode.

    Attributes
    ----------
    t : float
    q : ndarray, shape (n,)
    qd : ndarray, shape (n,)
    active : frozenset of str
        Names of the active constraints.
    """

    t: float
    q: FloatArray
    qd: FloatArray
    active: frozenset[str]

    def replace(self, **changes: Any) -> State:
        """Return a copy with some fields replaced."""
        return dataclasses.replace(self, **changes)


@dataclass(frozen=True)
class Geometry:
    """Mesh-free geometry of a configuration, for plots and animations.

    Attributes
    ----------
    dim : int
        2 (planar) or 3 (spatial).
    segments : ndarray, shape (s, 2, dim)
        Line segments (links), drawn as bars.
    points : ndarray, shape (p, dim)
        Points (joints, masses, contact points).
    frames : ndarray, shape (f, dim + 1, dim)
        Optional body frames: origin followed by the dim axis unit vectors (3D only used).
    labels : tuple of str
        Optional labels of the points.
    """

    dim: int
    segments: FloatArray
    points: FloatArray = field(default_factory=lambda: np.zeros((0, 2)))
    frames: FloatArray = field(default_factory=lambda: np.zeros((0, 3, 2)))
    labels: tuple[str, ...] = ()


def _as_vector(x: ArrayLike, name: str, n: int) -> FloatArray:
    arr = np.asarray(x, dtype=np.float64)
    if arr.shape != (n,):
        raise ShapeError(f"{name} must have shape ({n},), got shape {arr.shape}")
    return arr


#: Active sets a model keeps validated, and their row slices and engine masks (each cleared
#: when exceeded; a run uses a handful).
_MAX_ACTIVE_SETS = 256

_T = TypeVar("_T")


class _ConstraintIndex:
    """A model's constraints by name, derived once per model (a model is immutable): the names
    in row order, their set, the active sets validated so far, and per validated active set its
    row slices and engine mask."""

    __slots__ = ("masks", "name_set", "names", "slices", "valid")

    def __init__(self, constraints: tuple[ConstraintSpec, ...]) -> None:
        self.names = tuple(c.name for c in constraints)
        self.name_set = frozenset(self.names)
        self.valid: set[frozenset[str]] = set()
        self.slices: dict[frozenset[str], dict[str, slice]] = {}
        self.masks: dict[frozenset[str], NDArray[np.uint8]] = {}


def _kept(cache: dict[frozenset[str], _T], active: frozenset[str], build: Callable[[], _T]) -> _T:
    """``cache[active]``, built on the first request (the cache is cleared when full)."""
    hit = cache.get(active)
    if hit is None:
        if len(cache) >= _MAX_ACTIVE_SETS:
            cache.clear()
        hit = cache[active] = build()
    return hit


class Model(ABC):
    """Abstract base of every model source (planar, spatial, SymPy, functions, Pinocchio, MuJoCo).

    Subclasses are frozen dataclasses (so :meth:`replace` works) and implement the abstract
    methods for a *single* state (``q`` shape ``(n,)``). Everything else has a default that
    subclasses may override for speed (notably :meth:`evaluate`).

    Required attributes (dataclass fields or properties)
    -----------------------------------------------------
    name : str
    coordinate_names : tuple of str, length n
    constraints : tuple of ConstraintSpec
    actuator_names : tuple of str, length k
    default_active : frozenset of str
        The constraints active in the model's nominal mode (unilateral ones usually not).
    """

    name: str
    coordinate_names: tuple[str, ...]
    constraints: tuple[ConstraintSpec, ...]
    actuator_names: tuple[str, ...]
    default_active: frozenset[str]

    #: Whether outputs(...) is meaningful; set by sources with named outputs.
    has_outputs: ClassVar[bool] = False

    # ------------------------------------------------------------------ sizes and names
    @property
    def n(self) -> int:
        """Number of dependent coordinates."""
        return len(self.coordinate_names)

    @property
    def k(self) -> int:
        """Number of actuators (columns of B)."""
        return len(self.actuator_names)

    @functools.cached_property
    def _constraint_index(self) -> _ConstraintIndex:
        """The constraints by name (built on first use, kept with the model)."""
        return _ConstraintIndex(tuple(self.constraints))

    @property
    def constraint_names(self) -> tuple[str, ...]:
        """Names of all constraints, in row order."""
        return self._constraint_index.names

    def constraint(self, name: str) -> ConstraintSpec:
        """The :class:`ConstraintSpec` called ``name``."""
        for c in self.constraints:
            if c.name == name:
                return c
        raise UnknownNameError(
            f"model {self.name!r} has no constraint {name!r}; known: {list(self.constraint_names)}"
        )

    @property
    def friction_contacts(self) -> tuple[FrictionContact, ...]:
        """The point contacts with Coulomb friction (none by default)."""
        return ()

    def resolve_active(self, active: Iterable[str] | str | None) -> frozenset[str]:
        """Validate an active set; ``None`` means :attr:`default_active`.

        Raises
        ------
        UnknownNameError
            If a name is not a constraint of the model.
        """
        if active is None:
            return frozenset(self.default_active)
        index = self._constraint_index
        if type(active) is frozenset and active in index.valid:  # (validated before)
            return active
        if isinstance(active, str):
            active = (active,)
        names = frozenset(active)
        if not names <= index.name_set:
            unknown = names - index.name_set
            raise UnknownNameError(
                f"active: unknown constraint name(s) {sorted(unknown)} for model {self.name!r}; "
                f"known: {list(self.constraint_names)}"
            )
        if len(index.valid) >= _MAX_ACTIVE_SETS:
            index.valid.clear()
        index.valid.add(names)
        return names

    def row_slices(self, active: Iterable[str] | None = None) -> dict[str, slice]:
        """Row range of each active constraint in the stacked arrays."""
        act = self.resolve_active(active)

        def build() -> dict[str, slice]:
            out: dict[str, slice] = {}
            i = 0
            for c in self.constraints:
                if c.name in act:
                    out[c.name] = slice(i, i + c.dim)
                    i += c.dim
            return out

        rows = _kept(self._constraint_index.slices, act, build)
        return dict(rows)  # (a copy: the caller's to change)

    def active_mask(self, active: Iterable[str] | str | None = None) -> NDArray[np.uint8]:
        """The active set as the engine's mask: 1 for each active constraint, in
        :attr:`constraints` order, shape (number of constraints,)."""
        act = self.resolve_active(active)
        return _kept(self._constraint_index.masks, act,
                     lambda: np.array([c.name in act for c in self.constraints], dtype=np.uint8)).copy()  # fmt: skip

    def num_rows(self, active: Iterable[str] | None = None) -> int:
        """Number of stacked constraint rows m for an active set."""
        act = self.resolve_active(active)
        return sum(c.dim for c in self.constraints if c.name in act)

    # ------------------------------------------------------------------ dynamics (abstract)
    @abstractmethod
    def mass_matrix(self, q: ArrayLike) -> FloatArray:
        """Inertia matrix ``M(q)``, shape (n, n)."""

    @abstractmethod
    def coriolis_matrix(self, q: ArrayLike, qd: ArrayLike) -> FloatArray:
        """Christoffel-symbol Coriolis matrix ``C(q, qd)``, shape (n, n)."""

    @abstractmethod
    def conservative_force(self, q: ArrayLike) -> FloatArray:
        """``f_g(q) = −∂V/∂q`` (gravity and springs), shape (n,)."""

    @abstractmethod
    def potential_energy(self, q: ArrayLike) -> float:
        """Potential energy ``V(q)`` (gravity and springs)."""

    @abstractmethod
    def constraint_terms(
        self,
        t: float,
        q: ArrayLike,
        qd: ArrayLike,
        active: Iterable[str] | None = None,
    ) -> ConstraintTerms:
        """Stacked A, γ, φ, velocity residual of the active constraints (declaration order)."""

    # ------------------------------------------------------------------ dynamics (defaults)
    def coriolis_force(self, q: ArrayLike, qd: ArrayLike) -> FloatArray:
        """``C(q, qd) qd``, shape (n,)."""
        return self.coriolis_matrix(q, qd) @ np.asarray(qd, dtype=float)

    def passive_force(self, t: float, q: ArrayLike, qd: ArrayLike) -> FloatArray:
        """Passive non-conservative forces (dampers), shape (n,); zero by default."""
        return np.zeros(self.n)

    def input_matrix(self, q: ArrayLike) -> FloatArray:
        """Input matrix ``B(q)``, shape (n, k); empty by default."""
        return np.zeros((self.n, self.k))

    def kinetic_energy(self, q: ArrayLike, qd: ArrayLike) -> float:
        """``T = ½ qdᵀ M qd``."""
        v = np.asarray(qd, dtype=float)
        return 0.5 * float(v @ self.mass_matrix(q) @ v)

    def energy(self, q: ArrayLike, qd: ArrayLike) -> float:
        """Total mechanical energy ``T + V``."""
        return self.kinetic_energy(q, qd) + self.potential_energy(q)

    def constraint_jacobian(self, t: float, q: ArrayLike, active: Iterable[str] | None = None) -> FloatArray:
        """Stacked constraint matrix A of the active constraints, shape (m, n)."""
        return self.constraint_terms(t, q, np.zeros(self.n), active).A

    def constraint_bias(
        self, t: float, q: ArrayLike, qd: ArrayLike, active: Iterable[str] | None = None
    ) -> FloatArray:
        """``γ`` with ``A qdd + γ = 0`` (``Ȧ qd`` when scleronomic), shape (m,)."""
        return self.constraint_terms(t, q, qd, active).gamma

    def constraint_residual(self, t: float, q: ArrayLike, active: Iterable[str] | None = None) -> FloatArray:
        """Position residual φ (gap for unilateral rows, 0 for nonholonomic), shape (m,)."""
        return self.constraint_terms(t, q, np.zeros(self.n), active).phi

    def constraint_jacobian_dot(
        self, t: float, q: ArrayLike, qd: ArrayLike, active: Iterable[str] | None = None
    ) -> FloatArray:
        """The matrix ``Ȧ = dA/dt`` along ``qd``, shape (m, n).

        Default: exact for models whose ``γ`` is linear in ``Ȧ``: column j is
        ``(γ(qd + e_j) − γ(qd − e_j))/2`` evaluated at *fixed* q is not available in general,
        so the default differentiates A along qd with a central difference of step
        ``1e-6·(1 + ‖q‖)/‖qd‖`` (accuracy ~1e-9). Sources override it with the exact matrix.
        """
        qv = _as_vector(q, "q", self.n)
        v = _as_vector(qd, "qd", self.n)
        nv = float(np.linalg.norm(v))
        if nv == 0.0:
            return np.zeros((self.num_rows(active), self.n))
        eps = 1e-6 * (1.0 + float(np.linalg.norm(qv))) / nv
        Ap = self.constraint_jacobian(t + eps, qv + eps * v, active)
        Am = self.constraint_jacobian(t - eps, qv - eps * v, active)
        return (Ap - Am) / (2.0 * eps)

    def evaluate(
        self,
        t: float,
        q: ArrayLike,
        qd: ArrayLike,
        active: Iterable[str] | None = None,
    ) -> ModelTerms:
        """All terms the core needs at one state, in one call (override to share work)."""
        qv = _as_vector(q, "q", self.n)
        v = _as_vector(qd, "qd", self.n)
        M = self.mass_matrix(qv)
        h = self.conservative_force(qv) - self.coriolis_force(qv, v)
        return ModelTerms(
            M=M,
            h=h,
            f_passive=self.passive_force(t, qv, v),
            B=self.input_matrix(qv),
            constraints=self.constraint_terms(t, qv, v, active),
        )

    def engine_program(self) -> Any | None:
        """The model compiled once to a program of the engine (``nonmin._engine.Program``), or
        None.

        A source whose whole evaluation (``M``, ``h``, ``f_passive``, ``B``, ``A``, ``γ``, ``φ``,
        the velocity residual, the energies) the engine can run without calling Python returns
        it here: planar models (``PlanarProgram``), SymPy models (``TapeProgram``) and spatial
        models (``SpatialProgram``). The program covers every constraint; the active set is a
        mask (one entry per constraint, in :attr:`constraints` order) given to each
        evaluation. The default, None, means the engine evaluates the model through a Python
        callback of :meth:`evaluate`; results never depend on the choice beyond round-off.
        """
        return None

    def forward_dynamics(
        self,
        q: ArrayLike,
        qd: ArrayLike,
        *,
        t: ArrayLike = 0.0,
        active: Iterable[str] | str | None = None,
        f: ArrayLike | None = None,
        rtol: float | None = None,
        threads: int | None = None,
    ) -> Accelerations:
        """Accelerations and constraint forces at one state or a batch of states: model and
        kernel in one call (corrected eq. (ddq_sim); f_c by eq. (fc_R)).

        With a compiled program (:meth:`engine_program`) the whole batch runs in the engine,
        threaded over the machine's cores (``nonmin._engine.forward_batch``); otherwise each
        state is evaluated with :meth:`evaluate` and solved by :func:`nonmin.core.solve_dynamics`.
        Both give the same results to round-off.

        Parameters
        ----------
        q, qd : array_like, shape (..., n)
            Coordinates and velocities (any leading batch shape, the same for both).
        t : float or array_like, shape (...), default 0
            Time of each state (rheonomic constraints, drivers).
        active : iterable of str, optional
            Active constraints (default :attr:`default_active`), the same for every state.
        f : array_like, shape (..., n) or (n,), optional
            Applied generalized forces besides the model's own (e.g. ``B u``).
        rtol : float, optional
            Rank tolerance (default :data:`nonmin.core.DEFAULT_RTOL`).
        threads : int, optional
            Threads of the engine's batch (default: all cores).

        Returns
        -------
        Accelerations
            ``qdd`` and ``f_c``, shape (..., n); ``rank`` of the active A, shape (...).

        Raises
        ------
        ShapeError
            ``q``, ``qd``, ``t`` or ``f`` of the wrong shape.
        NonFiniteError, NotPositiveDefiniteError
            For the first state where the dynamics are not defined (its index is named).
        """
        from .._validation import as_float_array
        from ..core.linalg import DEFAULT_RTOL, SPD_RTOL, resolve_rtol
        from ..errors import NonminError

        n = self.n
        qa = as_float_array(q, "q")
        va = as_float_array(qd, "qd")
        if qa.ndim == 0 or qa.shape[-1] != n:
            raise ShapeError(f"q must have shape (..., {n}), got shape {qa.shape}")
        if va.shape != qa.shape:
            raise ShapeError(f"qd must have the shape of q {qa.shape}, got shape {va.shape}")
        batch = qa.shape[:-1]
        N = int(np.prod(batch, dtype=np.int64))
        try:
            ta = np.broadcast_to(as_float_array(t, "t"), batch).reshape(N)
        except ValueError as exc:
            if isinstance(exc, NonminError):
                raise
            raise ShapeError(f"t must be a scalar or have shape {batch}, got shape {np.shape(t)}") from None
        if not np.all(np.isfinite(ta)):
            raise NonFiniteError(f"t must be finite, got {t!r:.80}")
        fa = None
        if f is not None:
            fa = as_float_array(f, "f")
            if fa.shape not in ((n,), qa.shape):
                raise ShapeError(f"f must have shape ({n},) or {qa.shape}, got shape {fa.shape}")
            fa = np.ascontiguousarray(fa.reshape(-1, n))
        act = self.resolve_active(active)
        tol = DEFAULT_RTOL if rtol is None else resolve_rtol(rtol)
        Q = np.ascontiguousarray(qa.reshape(N, n))
        V = np.ascontiguousarray(va.reshape(N, n))
        prog = self.engine_program()
        if prog is not None:
            from .. import _engine  # type: ignore[attr-defined]
            from .._validation import SYMMETRY_RTOL

            qdd, fc, rank, status, bad = _engine.forward_batch(
                prog, np.ascontiguousarray(ta), Q, V, self.active_mask(act), fa, tol, SPD_RTOL,
                SYMMETRY_RTOL, 0.0, int(threads or 0), True,
            )
            if bad:
                i = int(np.flatnonzero(status)[0])
                self._raise_at(i, float(ta[i]), Q[i], V[i], act, None if fa is None else fa[min(i, len(fa) - 1)], tol)
                raise NonminError(f"forward_dynamics: the engine failed at state {i} (status {int(status[i])})")
            return Accelerations(qdd.reshape(qa.shape), fc.reshape(qa.shape), rank.astype(np.intp).reshape(batch))
        qdd = np.empty((N, n))
        fc = np.empty((N, n))
        rank = np.empty(N, dtype=np.intp)
        for i in range(N):
            sol = self._solve_one(float(ta[i]), Q[i], V[i], act, None if fa is None else fa[min(i, len(fa) - 1)], tol, i)
            qdd[i], fc[i], rank[i] = sol.qdd, sol.f_c, sol.rank
        return Accelerations(qdd.reshape(qa.shape), fc.reshape(qa.shape), rank.reshape(batch))

    def _solve_one(
        self, t: float, q: FloatArray, qd: FloatArray, act: frozenset[str], f: FloatArray | None, tol: float, i: int
    ) -> Any:
        """One state through :meth:`evaluate` and the core kernel; errors name the state."""
        from ..core.dynamics import solve_dynamics
        from ..errors import NonminError

        try:
            terms = self.evaluate(t, q, qd, act)
            g = terms.h + terms.f_passive if f is None else terms.h + terms.f_passive + f
            ct = terms.constraints
            return solve_dynamics(terms.M, g, ct.A, ct.gamma, rtol=tol)
        except NonminError as exc:
            raise type(exc)(f"forward_dynamics at state {i} (t = {t:g}): {exc}") from exc

    def _raise_at(
        self, i: int, t: float, q: FloatArray, qd: FloatArray, act: frozenset[str], f: FloatArray | None, tol: float
    ) -> None:
        """Re-run state i on the reference path, which raises the typed error naming it."""
        self._solve_one(t, q, qd, act, f, tol, i)

    # ------------------------------------------------------------------ extras
    def outputs(self, t: float, q: ArrayLike, qd: ArrayLike) -> dict[str, FloatArray]:
        """Named output quantities (e.g. what a benchmark asks for); empty by default."""
        return {}

    def geometry(self, q: ArrayLike) -> Geometry | None:
        """Mesh-free geometry for plots and animations; None if the source has none."""
        return None

    def replace(self, **changes: Any) -> Model:
        """A copy with some fields replaced (parameter variants). Sources are frozen dataclasses."""
        if not dataclasses.is_dataclass(self):
            raise TypeError(f"{type(self).__name__} does not support replace()")
        return dataclasses.replace(self, **changes)  # type: ignore[type-var]

    def state(
        self,
        q: ArrayLike,
        qd: ArrayLike | None = None,
        *,
        t: float = 0.0,
        active: Iterable[str] | None = None,
    ) -> State:
        """Build a validated :class:`State` (no assembly; see :func:`nonmin.model.assemble`)."""
        qv = _as_vector(q, "q", self.n).copy()
        v = np.zeros(self.n) if qd is None else _as_vector(qd, "qd", self.n).copy()
        if not (np.isfinite(qv).all() and np.isfinite(v).all()):
            from ..errors import NonFiniteError

            raise NonFiniteError("q and qd must be finite")
        return State(t=float(t), q=qv, qd=v, active=self.resolve_active(active))

    def describe(self) -> Mapping[str, Any]:
        """A plain summary (sizes, names, constraints) for printing and metadata.

        Built once per model (a model is immutable) and shared with every caller (and with the
        ``metadata["model"]`` of its trajectories): read it, do not modify it.
        """
        return self._description

    @functools.cached_property
    def _description(self) -> Mapping[str, Any]:
        return {
            "name": self.name,
            "type": type(self).__name__,
            "n": self.n,
            "coordinates": list(self.coordinate_names),
            "actuators": list(self.actuator_names),
            "constraints": [
                {"name": c.name, "kind": c.kind, "dim": c.dim, "description": c.description}
                for c in self.constraints
            ],
            "default_active": sorted(self.default_active),
        }
