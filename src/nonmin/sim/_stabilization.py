"""Constraint stabilization: none, Baumgarte, and post-step projection in the mass metric.

Only ``A qdd + γ = 0`` is enforced by the dynamics, so ``φ`` and ``A qd + φ_t`` drift. Three
remedies, given as objects or registered names (:data:`STABILIZATIONS`):

* :class:`NoStabilization` (``"none"``).
* :class:`Baumgarte` (``"baumgarte"``): replaces the bias by ``γ + 2α (A qd + φ_t) + β² φ``
  (:func:`nonmin.core.baumgarte_bias`), i.e. enforces ``φ̈ + 2αφ̇ + β²φ = 0``.
* :class:`Projection` (``"projection"``): after every accepted step, Gauss–Newton iterations
  ``q ← q + Sᵀ(−A⁺φ)`` (:func:`nonmin.core.position_correction`, the minimum-kinetic-metric
  step onto φ = 0; the first ones at the full rank when A has no singular value below
  :data:`SINGULAR_CUT_RTOL`, otherwise without singular values below
  :data:`POSITION_CUT_RTOL`, whose φ components near a singular configuration are round-off;
  simplified steps that keep
  the A of the last linearization while they converge fast, :data:`CHORD_RATE`) until
  ``‖φ‖∞ ≤ tol``, then
  the velocity correction
  ``qd ← qd + Sᵀ(−A⁺(A qd + φ_t))`` (same formula as position_correction, applied to the
  velocity residual); for scleronomic constraints this is exactly the plastic
  impact map ``M̄⁻¹PM qd`` (:func:`nonmin.core.impact_map`, ERRATA "Drift"), and it also handles
  rheonomic rows. ``metric="euclidean"`` uses the identity instead of M (for comparison only:
  it drifts in energy).
"""

from __future__ import annotations

import math
from abc import ABC
from dataclasses import dataclass, replace
from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from ..core import _fast, forward_dynamics, solve_dynamics
from ..core.linalg import DEFAULT_RTOL
from ..errors import InputError
from ..model import ConstraintTerms, Model

__all__ = ["STABILIZATIONS", "Baumgarte", "NoStabilization", "Projection", "Stabilization"]

FloatArray = NDArray[np.float64]


class Stabilization(ABC):  # noqa: B024 - every method has a neutral default
    """Base class: a bias modification and/or a post-step projection (both optional)."""

    name: ClassVar[str] = ""

    def bias(self, ct: ConstraintTerms) -> FloatArray:
        """The acceleration bias passed to the dynamics (default: ``γ``)."""
        return ct.gamma

    def project(
        self,
        model: Model,
        t: float,
        q: FloatArray,
        qd: FloatArray,
        active: frozenset[str],
        rtol: float | None,
    ) -> tuple[FloatArray, FloatArray]:
        """Post-step correction of ``(q, qd)`` (default: none)."""
        return q, qd

    def project_sample(
        self,
        model: Model,
        t: float,
        q: FloatArray,
        qd: FloatArray,
        active: frozenset[str],
        rtol: float | None,
    ) -> tuple[FloatArray, FloatArray]:
        """Correction of an output sample taken from a continuous extension (default:
        :meth:`project`)."""
        return self.project(model, t, q, qd, active, rtol)


@dataclass(frozen=True)
class NoStabilization(Stabilization):
    """No stabilization: the constraints drift at the integrator's accuracy."""

    name: ClassVar[str] = "none"


@dataclass(frozen=True)
class Baumgarte(Stabilization):
    """Baumgarte terms ``γ + 2α (A qd + φ_t) + β² φ`` (gains in 1/s, ≥ 0)."""

    alpha: float = 10.0
    beta: float = 10.0

    name: ClassVar[str] = "baumgarte"

    def __post_init__(self) -> None:
        if not (self.alpha >= 0 and self.beta >= 0):
            raise InputError(f"Baumgarte: alpha and beta must be ≥ 0, got {self.alpha}, {self.beta}")

    def bias(self, ct: ConstraintTerms) -> FloatArray:
        return ct.gamma + 2.0 * self.alpha * ct.velocity + self.beta * self.beta * ct.phi


#: Position iterations of :class:`Projection` stop when every holonomic row satisfies
#: ``|φ_i| ≤ ROUNDOFF_FLOOR · (1 + Σ_j |A_ij q_j|)`` — the size of φ_i's own round-off (φ is a
#: difference of terms of size ``Σ_j |A_ij q_j|``), so another Gauss–Newton step could not reduce
#: it. It spares the iteration that only detected the floor (measured: crossed four-bar, RK4,
#: dt = 1e-2 s: 3.6 → 2.x solves per projection) and leaves ‖φ‖∞ at the same 1e-16…1e-15.
ROUNDOFF_FLOOR = 4.0 * float(np.finfo(np.float64).eps)


#: Relative singular-value cutoff of the first Gauss–Newton steps of :class:`Projection`.
#: Near a singular configuration some singular values of the equilibrated A are of the order of
#: the distance to it (measured: 1e-7…1.5e-6 relative on A02 N = 40 at a step end 1.6e-6 s
#: from a horizontal configuration), and the components of φ along them are round-off
#: (1e-16…1e-15 there): the full-rank step divides that noise by them and moves q by ~1e-9
#: along the branch-switching directions, 100 × farther than q is from the exact solution. As
#: the tangent space turns by (that move)/(distance to the configuration), the velocity
#: correction then tilts qd by ~1e-3 and the next RK4 step kicks the energy (+24.5 J in one
#: step at RK4 dt = 2e-3). So the steps first use this cutoff (directions with smaller singular
#: values keep the integrator's position); it is kept only while it converges, i.e. when the
#: residual along those directions is at the round-off floor. If the iterations stall above
#: the floor there (a real residual along them), they continue at the full rank.
#: This cutoff applies when A has a singular value below :data:`SINGULAR_CUT_RTOL` (next to a
#: singular configuration); otherwise the first steps use :data:`SINGULAR_CUT_RTOL` (and so
#: take the full rank).
POSITION_CUT_RTOL = 1e-2

#: Cutoff of the first Gauss–Newton steps of :class:`Projection` when no singular value of the
#: equilibrated A lies below it (whatever the size of the residual). Singular values between
#: this and :data:`POSITION_CUT_RTOL` belong to ill-conditioned but regular configurations of
#: long chains (A02 N = 40: σ_min/σ_max ≤ 0.024 everywhere, below 1e-2 for a third of the
#: motion) as well as to the approach of a singular configuration. A real residual along them
#: is one the cut steps could not reduce (they stalled and went on at the full rank after a
#: wasted step and a truncated SVD). A round-off residual (at its floor
#: ``ROUNDOFF_FLOOR · (1 + Σ_j |A_ij q_j|)``) was cut at :data:`POSITION_CUT_RTOL` until
#: 2026-11-26; that cut lay inside A02 N = 40's singular values, so the certified LQ could not
#: decide it and every such projection ran a 242 × 243 SVD (7.4 ms per RK4 step at dt = 2e-3
#: against 0.58 ms now; DOP853 rtol 1e-10 over 20 s 4.5 → 0.66 s CPU, energy 1.84e-7 →
#: 1.82e-7 J). The singularity-aware step placement (:class:`~nonmin.sim.RK4`'s ``passages``)
#: keeps step ends out of the neighbourhood where that noise mattered. Measured with it (A02
#: N = 2, RK4 steps ending 1e-7…1e-4 s from a horizontal configuration, 30 start times each,
#: dt 1e-3 and 2e-3): the same energy errors as with the round-off cut (8.4e-12…9.7e-12 J
#: against 8.6e-12…9.3e-12 J; 2.8e-10 J both); issue 18's targets 1 and 2 unchanged to
#: round-off. With ``passages=False`` the steps that end 1e-6 s from the configuration scatter
#: either way (dt 1e-3: 7.7e-10 → 2.4e-6 J at most; dt 2e-3: 1.6e-5 → 1.3e-6 J).
SINGULAR_CUT_RTOL = 1e-4



#: Rank tolerance (at least) of the velocity step when an output sample taken from a
#: continuous extension (DOPRI5's, or the quintic Hermite interpolant of a fixed step) is
#: projected. The interpolant's velocity is accurate to its order in every direction; at a
#: sample next to a singular instant the directions of A's vanishing singular values are set
#: by round-off in q, and projecting the velocity off them tilts it by O(1) × the angle
#: between the two branch tangents (measured before: a crossed four-bar sample at a change
#: point 5.6e-3 m/s off, +1.6e-5 J, where the step ends were exact). Left unprojected, those
#: directions keep the interpolant's error instead (≤ the step's).
SAMPLE_VELOCITY_RTOL = SINGULAR_CUT_RTOL


#: Simplified (chord) Gauss–Newton steps of :class:`Projection`: the corrections reuse the A of
#: the last linearization as long as each one reduces ``‖φ‖∞`` at least this much (their rate is
#: about (distance moved) · (curvature) / σ_min, ~1e-6 after a step); otherwise A is taken
#: afresh at the current q (a full Gauss–Newton step). The compiled engine then solves with
#: the factorization it already holds: one factorization per projection instead of ~2.
CHORD_RATE = 0.1


def _correction(
    M: FloatArray, A: FloatArray, r: FloatArray, rtol: float | None, ranks: list[int] | None = None
) -> FloatArray:
    """Minimum mass-metric correction ``Δ = Sᵀ(−A⁺r)``: minimizes ``½ΔᵀMΔ`` s.t. ``AΔ = −r``.

    With ``ranks`` (a list) the rank of A the correction used is appended to it (from the
    compiled kernel when it evaluates the correction, else from :func:`solve_dynamics`'s
    factorization).

    This is :func:`nonmin.core.position_correction`; it is evaluated through the (compiled when
    available) dynamics kernel: with ``f + h = 0`` and bias ``r``,
    ``forward_dynamics = M̄⁻¹[(μI − PM)(−A⁺r)] = x − P M̄⁻¹ M x`` with ``x = −A⁺r`` (because
    ``M̄ x = μ x`` for ``x ∈ R(Aᵀ)`` and ``M̄⁻¹P = PM̄⁻¹``) — the same formula, same rank policy.
    With ``M = I`` it is the Euclidean correction ``−A⁺r``.
    """
    if ranks is None:
        return forward_dynamics(M, np.zeros(M.shape[0]), A, r, rtol=rtol)
    fast = _fast.solve(M, np.zeros(M.shape[0]), A, r, None, None, rtol, _fast.QDD_RANK)
    if fast is not None:
        ranks.append(fast[1])
        return np.asarray(fast[0])
    sol = solve_dynamics(M, np.zeros(M.shape[0]), A, r, rtol=rtol)  # (forward_dynamics' path)
    ranks.append(int(sol.rank))
    return sol.qdd


def _first_step(M: FloatArray, A: FloatArray, phi: FloatArray, full: float) -> tuple[float, FloatArray]:
    """Cutoff and correction of the first Gauss–Newton step at a state with residual ``phi``
    (the rule of :data:`SINGULAR_CUT_RTOL`; ``full``: the rank tolerance of the simulation).
    The step at :data:`SINGULAR_CUT_RTOL` is kept if it had the full rank; otherwise (next to a
    singular configuration) the step at :data:`POSITION_CUT_RTOL` is taken."""
    cut = max(SINGULAR_CUT_RTOL, full)
    ranks: list[int] = []
    dq = _correction(M, A, phi, cut, ranks)
    if ranks[0] == A.shape[0]:
        return cut, dq  # no singular value below the cutoff: the full-rank step
    cut = max(POSITION_CUT_RTOL, full)  # next to a singular configuration
    return cut, _correction(M, A, phi, cut)


@dataclass(frozen=True)
class Projection(Stabilization):
    """Post-step projection onto ``φ = 0`` and ``A qd + φ_t = 0`` in the mass metric.

    Parameters
    ----------
    tol : float, default 0.0
        Stop the position iterations when ``‖φ‖∞ ≤ tol`` (absolute, in the units of φ). The
        iterations also stop when ``‖φ‖∞`` no longer halves (round-off floor), so the default 0
        means "converge to round-off". Near a change point this matters: the null space of A
        turns by ``(distance to the manifold)/σ_min(A)``, so a residual of 1e-12 where
        ``σ_min ~ 1e-5`` tilts the projected velocity by ~1e-4 and can kick the energy
        (measured on the crossed four-bar: +2 J with tol=1e-12, 5e-7 J with round-off).
    max_iter : int
        Linearizations (Gauss–Newton steps with A taken afresh) at most; the simplified steps
        between them, each of which must reduce ``‖φ‖∞`` by :data:`CHORD_RATE`, are not counted
        (usually one linearization and one or two simplified steps follow a step).
    velocity : bool
        Also project the velocity.
    metric : {"mass", "euclidean"}
        Metric of the projection; ``"mass"`` (default) is the physically right one.
    velocity_rtol : float, optional
        Rank tolerance of A for the *velocity* step (default: the simulation's ``rank_rtol``).
        Within ``σ_min/σ_max < velocity_rtol`` of a change point the velocity is projected onto
        the larger null space that contains both branch tangents, instead of onto a direction
        that round-off in q decides. Useful with error-controlled methods (measured on the
        crossed four-bar with dopri5 at rtol 1e-10 and rank_rtol 1e-10: with 1e-4 the first
        change point is passed in 72 steps with 6e-10 error; without, the step collapses to
        3e-11 s — the adaptive rank tolerance of :func:`simulate` now cures that too); harmful
        with fixed-step RK4 (2 J energy kick), so not the default.
    energy : bool, default False
        Also hold the total energy ``E = T(q, q̇) + V(q)`` at its initial value (conservative
        systems only: no controller, input, damper, driver, event or contact; :func:`simulate`
        refuses those it can see). After the velocity step q̇ is scaled by
        ``α = √((E₀ − V(q))/T(q, q̇))``: the mass-metric projection of q̇ onto the energy level
        set (the gradient of E in q̇ is M q̇), which keeps ``A q̇ = 0``. Skipped where it would
        change T by more than :data:`ENERGY_MAX_CHANGE` (a turning point, T → 0): a later
        step corrects it. The energy error then stays at round-off over any horizon (the
        phase error still grows); measured in ``docs/theory.md``.
    energy_level : float, optional
        The level E₀ to hold (J); default: the energy of the projected initial state, which
        :func:`simulate` fills in.
    """

    tol: float = 0.0
    max_iter: int = 10
    velocity: bool = True
    metric: str = "mass"
    velocity_rtol: float | None = None
    energy: bool = False
    energy_level: float | None = None

    name: ClassVar[str] = "projection"

    def __post_init__(self) -> None:
        if self.metric not in ("mass", "euclidean"):
            raise InputError(f"Projection: metric must be 'mass' or 'euclidean', got {self.metric!r}")
        if not (self.tol >= 0 and self.max_iter >= 0):
            raise InputError(f"Projection: need tol ≥ 0 and max_iter ≥ 0, got {self.tol}, {self.max_iter}")

    def velocity_rank_rtol(self, rtol: float | None) -> float | None:
        """Rank tolerance of the velocity step given the simulation's ``rtol`` (None: core
        default); the compiled engine uses the same rule."""
        return rtol if self.velocity_rtol is None else max(self.velocity_rtol, rtol or 0.0)

    def project_sample(
        self,
        model: Model,
        t: float,
        q: FloatArray,
        qd: FloatArray,
        active: frozenset[str],
        rtol: float | None,
    ) -> tuple[FloatArray, FloatArray]:
        """:meth:`project` with the velocity step's rank tolerance raised to
        :data:`SAMPLE_VELOCITY_RTOL` (for samples from a continuous extension)."""
        vel = max(self.velocity_rank_rtol(rtol) or DEFAULT_RTOL, SAMPLE_VELOCITY_RTOL)
        return replace(self, velocity_rtol=vel).project(model, t, q, qd, active, rtol)

    def project(
        self,
        model: Model,
        t: float,
        q: FloatArray,
        qd: FloatArray,
        active: frozenset[str],
        rtol: float | None,
    ) -> tuple[FloatArray, FloatArray]:
        if not active:
            return q, qd
        M = model.mass_matrix(q)
        ct = model.constraint_terms(t, q, qd, active)
        hol = ct.holonomic
        eye = np.eye(q.shape[0]) if self.metric == "euclidean" else None
        if hol.any():
            prev = np.inf
            aq = np.abs(q)
            full = DEFAULT_RTOL if rtol is None else float(rtol)
            cut = max(POSITION_CUT_RTOL, full)  # first without the near-singular directions
            A_lin: FloatArray | None = None  # A of the last linearization
            fresh = False  # the last step was a Gauss–Newton step (A taken at its q)
            lin_count = 0
            while True:
                phi = ct.phi[hol]
                err = float(np.max(np.abs(phi)))
                if err <= self.tol or err == 0.0:
                    break  # converged
                floor = ROUNDOFF_FLOOR * (1.0 + np.abs(ct.A[hol]) @ aq)
                if np.all(np.abs(phi) <= floor):
                    break  # every row at its round-off level: one more iteration cannot help
                # Gauss–Newton first, at the full rank, and when a chord step was not fast
                relin = A_lin is None or cut == full
                if A_lin is not None and err > (0.5 if fresh else CHORD_RATE) * prev:
                    if fresh:  # a Gauss–Newton step stalled
                        if cut == full and err >= prev:
                            break  # no progress at the full rank: round-off floor reached
                        # with the cutoff: a real residual along the cut directions; at the full
                        # rank and still decreasing: far from φ = 0 near a singular
                        # configuration (a poor linearization) — Gauss–Newton again
                        cut = full
                    elif err > 0.5 * prev:  # a chord step without real progress: the residual lies
                        cut = full  # along the cut directions, which no step at the cut reaches
                    relin = True
                if relin:
                    if lin_count >= self.max_iter:
                        break
                    lin_count += 1
                    A_lin = ct.A[hol]
                fresh = relin
                assert A_lin is not None
                prev = err
                # M at the uncorrected q: the corrections are at the integrator's error level,
                # so the metric change is of second order
                Mq = M if eye is None else eye
                if lin_count == 1 and fresh and cut > max(SINGULAR_CUT_RTOL, full):
                    cut, dq = _first_step(Mq, A_lin, phi, full)  # (A_lin: this q's A)
                else:
                    dq = _correction(Mq, A_lin, phi, cut)
                q = q + dq
                ct = model.constraint_terms(t, q, qd, active)
        if self.velocity and ct.A.shape[0]:
            qd = qd + _correction(M if eye is None else eye, ct.A, ct.velocity,
                                  self.velocity_rank_rtol(rtol))  # fmt: skip
        if self.energy and self.energy_level is not None:
            qd = energy_scale(float(self.energy_level), model.potential_energy(q), model.kinetic_energy(q, qd), qd)
        return q, qd


#: :class:`Projection` with ``energy=True`` scales q̇ only when that changes the kinetic energy by
#: at most this fraction (near a turning point, T → 0, the scaling is ill-conditioned).
ENERGY_MAX_CHANGE = 1e-2


def energy_scale(level: float, V: float, T: float, qd: FloatArray) -> FloatArray:
    """q̇ scaled onto the energy level ``T + V = level`` (``α = √((level − V)/T)``), or q̇ itself
    when ``|α² − 1| > ENERGY_MAX_CHANGE`` or T ≤ 0. The engine computes the same
    (``engine/src/sim_loop.cpp``, ``project``)."""
    if not (T > 0.0):
        return qd
    a2 = (level - V) / T
    if not (abs(a2 - 1.0) <= ENERGY_MAX_CHANGE):
        return qd
    return qd * math.sqrt(a2)


#: Constraint stabilizations by name (``stabilization=`` of :func:`nonmin.sim.simulate`).
STABILIZATIONS: dict[str, type[Stabilization]] = {
    "none": NoStabilization,
    "baumgarte": Baumgarte,
    "projection": Projection,
}


_BY_NAME: dict[str, Stabilization] = {}


def resolve_stabilization(spec: Stabilization | str | None) -> Stabilization:
    """An instance from an object or a registered name."""
    from ..errors import UnknownNameError

    if spec is None:
        return NoStabilization()
    if isinstance(spec, str):  # (before the ABC's isinstance, the slower test)
        if spec not in STABILIZATIONS:
            raise UnknownNameError(
                f"stabilization: unknown name {spec!r}; known: {sorted(STABILIZATIONS)}"
            )
        cls = STABILIZATIONS[spec]
        params = getattr(cls, "__dataclass_params__", None)
        if params is None or not params.frozen:  # (a class registered by a user: a new instance)
            return cls()
        hit = _BY_NAME.get(spec)
        if hit is None or type(hit) is not cls:  # frozen values: one default instance per name
            hit = _BY_NAME[spec] = cls()
        return hit
    if isinstance(spec, Stabilization):
        return spec
    raise InputError(
        f"stabilization must be a Stabilization object or one of {sorted(STABILIZATIONS)}, "
        f"got {type(spec).__name__}"
    )
