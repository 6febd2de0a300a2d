"""Targets and references on the constraint manifold.

A controller in dependent coordinates needs a reference ``q*`` that satisfies the active
constraints: the closed loop of :class:`~nonmin.control.Regulator` rests where
``P(q)(q − q*) = 0``, i.e. at the point of the manifold nearest to ``q*`` (a critical point of
the Euclidean distance); reaching ``q*`` itself is only possible when ``q*`` is on the
manifold. This module projects targets onto the manifold (or rejects them), projects reference
velocities and accelerations onto the tangent space, and keeps quaternion targets from
unwinding.

Projection metrics
------------------
``"euclidean"``
    ``q⁺ = argmin ½‖q − q*‖²`` subject to ``φ(q) = 0`` — the rest point of the regulator, so
    projecting first changes nothing but makes ``e = q − q⁺`` vanish at the rest point.
``"mass"``
    ``q⁺ = argmin ½ (q − q*)ᵀ M(q) (q − q*)`` (metric frozen at each iterate) — the
    kinetic-energy metric, invariant to the choice of units of the coordinates.

Both are solved by Gauss–Newton iterations ``q ← q + Δ``,
``Δ = argmin ½ (q + Δ − q*)ᵀ W (q + Δ − q*)`` subject to ``φ + A Δ = 0``, which gives
``Δ = d + A⁺(−φ − A d)`` (Euclidean) or ``Δ = d + Sᵀ A⁺(−φ − A d)`` (mass metric,
:func:`nonmin.core.position_correction`), ``d = q* − q``.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike

from ..core import position_correction, pseudo_inverse, range_basis
from ..errors import AssemblyError, InputError, NonFiniteError, ShapeError
from ..model import Model
from ._common import FloatArray

Metric = Literal["euclidean", "mass"]
TargetPolicy = Literal["project", "reject"]

#: Tolerance on ‖φ‖ (relative to 1 + ‖q‖) for a target to count as on the manifold.
ON_MANIFOLD_TOL = 1e-9

__all__ = [
    "Reference",
    "align_quaternions",
    "project_acceleration",
    "project_configuration",
    "project_velocity",
]


def _vec(x: ArrayLike, name: str, n: int) -> FloatArray:
    arr = np.asarray(x, dtype=float)
    if arr.shape != (n,):
        raise ShapeError(f"{name} must have shape ({n},), got shape {arr.shape}")
    if not np.isfinite(arr).all():
        raise NonFiniteError(f"{name} must be finite, got {arr.tolist()}")
    return arr


def _holonomic_rows(
    model: Model, t: float, q: FloatArray, active: Iterable[str] | None
) -> tuple[FloatArray, FloatArray]:
    ct = model.constraint_terms(t, q, np.zeros(model.n), active)
    rows = np.asarray(ct.holonomic, dtype=bool)
    return ct.A[rows], ct.phi[rows]


def project_configuration(
    model: Model,
    q: ArrayLike,
    *,
    t: float = 0.0,
    active: Iterable[str] | None = None,
    metric: Metric = "euclidean",
    fixed: Sequence[int] = (),
    tol: float = 1e-12,
    max_iter: int = 100,
    rtol: float | None = None,
) -> FloatArray:
    """Nearest configuration to ``q`` that satisfies the active position-level constraints.

    Parameters
    ----------
    model : Model
    q : array_like, shape (n,)
        Desired configuration (possibly off the manifold).
    t : float
        Time (rheonomic constraints).
    active : iterable of str, optional
        Active constraints (default: the model's default active set). Nonholonomic rows have
        no position level and are ignored.
    metric : {"euclidean", "mass"}
        Distance minimized (see module docstring).
    fixed : sequence of int
        Coordinates to keep at their value in ``q`` (e.g. the pose of a grasped object): the
        other coordinates are assembled around them.
    tol : float
        Convergence tolerance on ``‖φ‖`` and on the step, relative to ``1 + ‖q‖``.
    max_iter : int
    rtol : float, optional
        Rank tolerance of the pseudo-inverses.

    Returns
    -------
    q_proj : ndarray, shape (n,)

    Raises
    ------
    AssemblyError
        If the iteration does not converge (no nearby feasible configuration, e.g. a target
        out of reach of a closed chain).
    """
    n = model.n
    target = _vec(q, "q", n)
    if metric not in ("euclidean", "mass"):
        raise InputError(f"metric must be 'euclidean' or 'mass', got {metric!r}")
    fix = np.asarray(list(fixed), dtype=int)
    if fix.size and (fix.min() < 0 or fix.max() >= n):
        raise InputError(f"fixed must hold coordinate indices in [0, {n}), got {fix.tolist()}")
    E = np.eye(n)[fix] if fix.size else np.zeros((0, n))
    x = target.copy()
    scale = 1.0 + float(np.linalg.norm(target))
    res = np.inf
    for it in range(max_iter):
        A, phi = _holonomic_rows(model, t, x, active)
        if fix.size:
            A = np.vstack([A, E])
            phi = np.concatenate([phi, x[fix] - target[fix]])
        if A.shape[0] == 0:
            return x
        res = float(np.linalg.norm(phi))
        if it == 0 and res <= tol * scale:
            return x  # the target itself is feasible
        d = target - x
        b = phi + A @ d  # want A δ = −b, δ = Δ − d
        if metric == "euclidean":
            delta = -range_basis(A, rtol).solve(b)
        else:
            delta = position_correction(model.mass_matrix(x), A, b, rtol=rtol)
        step = d + delta
        x = x + step
        if res <= tol * scale and float(np.linalg.norm(step)) <= 1e3 * tol * scale:
            break
    A, phi = _holonomic_rows(model, t, x, active)
    res = float(np.linalg.norm(phi)) if phi.size else 0.0
    if not np.isfinite(x).all() or res > 1e3 * tol * scale:
        raise AssemblyError(
            f"could not project the target onto the constraint manifold of {model.name!r} "
            f"(active = {sorted(model.resolve_active(active))}): ‖φ‖ = {res:.3g} after "
            f"{max_iter} Gauss–Newton iterations; the target may be out of reach"
        )
    return x


def check_on_manifold(
    model: Model, q: FloatArray, *, t: float, active: Iterable[str] | None, what: str = "target"
) -> None:
    """Raise :class:`AssemblyError` if ``q`` violates the active position constraints."""
    _, phi = _holonomic_rows(model, t, q, active)
    res = float(np.linalg.norm(phi)) if phi.size else 0.0
    if res > ON_MANIFOLD_TOL * (1.0 + float(np.linalg.norm(q))):
        raise AssemblyError(
            f"{what} is off the constraint manifold of {model.name!r} "
            f"(active = {sorted(model.resolve_active(active))}): ‖φ(q*)‖ = {res:.3g} > "
            f"{ON_MANIFOLD_TOL:g}·(1 + ‖q*‖); pass target_policy='project' to use the nearest "
            "feasible configuration"
        )


def project_velocity(
    model: Model, q: FloatArray, qd: FloatArray, *, t: float, active: Iterable[str] | None,
    rtol: float | None = None,
) -> FloatArray:
    """Nearest (Euclidean) velocity with ``A qd + φ_t = 0``: ``qd − A⁺ (A qd + φ_t)``."""
    ct = model.constraint_terms(t, q, qd, active)
    if ct.A.shape[0] == 0:
        return qd
    return qd - pseudo_inverse(ct.A, rtol) @ ct.velocity


def project_acceleration(
    model: Model, q: FloatArray, qd: FloatArray, qdd: FloatArray, *, t: float,
    active: Iterable[str] | None, rtol: float | None = None,
) -> FloatArray:
    """Nearest (Euclidean) acceleration with ``A qdd + γ = 0``."""
    ct = model.constraint_terms(t, q, qd, active)
    if ct.A.shape[0] == 0:
        return qdd
    return qdd - pseudo_inverse(ct.A, rtol) @ (ct.A @ qdd + ct.gamma)


def align_quaternions(
    q: FloatArray, q_star: FloatArray, blocks: Sequence[Sequence[int]]
) -> FloatArray:
    """Flip the sign of target quaternion blocks so that the error is the shortest rotation.

    A unit quaternion and its negative are the same rotation. With ``e = q − q*`` on the
    quaternion coordinates, a target on the far hemisphere (``⟨q, q*⟩ < 0``) would make the
    controller rotate the long way round (up to 360°, "unwinding"); replacing ``q*`` by
    ``−q*`` there makes the error the shortest rotation (at most 180°).

    Parameters
    ----------
    q, q_star : ndarray, shape (n,)
    blocks : sequence of 4-index sequences
        The coordinates of each unit quaternion in q.

    Returns
    -------
    q_star_aligned : ndarray, shape (n,)
    """
    if not blocks:
        return q_star
    out = q_star.copy()
    for b in blocks:
        idx = list(b)
        if float(q[idx] @ q_star[idx]) < 0.0:
            out[idx] = -q_star[idx]
    return out


def check_quaternion_blocks(blocks: Iterable[Iterable[int]], n: int) -> tuple[tuple[int, ...], ...]:
    """Validate quaternion index blocks (four distinct indices in ``[0, n)`` each)."""
    out = []
    for b in blocks:
        idx = tuple(int(i) for i in b)
        if len(idx) != 4 or len(set(idx)) != 4 or min(idx) < 0 or max(idx) >= n:
            raise InputError(
                f"quaternion_blocks: each block must hold 4 distinct coordinate indices in [0, {n}), got {idx}"
            )
        out.append(idx)
    return tuple(out)


@dataclass(frozen=True)
class Reference:
    """A desired motion ``t ↦ (q*(t), q̇*(t), q̈*(t))`` in dependent coordinates.

    Build it with :meth:`constant`, :meth:`polynomial`, :meth:`spline` or :meth:`from_functions`.
    Calling it returns the three arrays. Derivatives not given are taken by central differences
    with step :attr:`diff_step` (error ``O(h²)``). The first three are also values the compiled
    engine evaluates itself (:attr:`piecewise`); a reference from Python functions is called back
    by the engine (the rest of the controller stays compiled).

    Attributes
    ----------
    position : callable ``t -> q*``, shape (n,)
    velocity : callable ``t -> q̇*``, optional
    acceleration : callable ``t -> q̈*``, optional
    diff_step : float
        Step of the central differences.
    piecewise : tuple (x, c, hold) or None
        The same motion as a piecewise polynomial in scipy's ``PPoly`` layout (breakpoints ``x``
        of shape (p + 1,), coefficients ``c`` of shape (order, p, n) of ``(t − x_i)^(order−1−j)``;
        ``hold``: outside ``[x[0], x[-1]]`` the end value with zero derivatives, else the end
        pieces extend), for the engine; None for functions.
    """

    position: Callable[[float], ArrayLike]
    velocity: Callable[[float], ArrayLike] | None = None
    acceleration: Callable[[float], ArrayLike] | None = None
    diff_step: float = 1e-4
    piecewise: tuple[FloatArray, FloatArray, bool] | None = field(default=None, repr=False, compare=False)

    @classmethod
    def constant(cls, q_star: ArrayLike) -> Reference:
        """A set-point: ``q*(t) = q_star``, zero velocity and acceleration."""
        qs = np.asarray(q_star, dtype=float).copy()
        if qs.ndim != 1 or not np.isfinite(qs).all():
            raise InputError(f"q_star must be a finite vector, got {qs!r}")
        z = np.zeros_like(qs)
        return cls(lambda t: qs, lambda t: z, lambda t: z, piecewise=(np.array([0.0, 1.0]), qs[None, None, :], False))

    @classmethod
    def polynomial(cls, coefficients: ArrayLike) -> Reference:
        """``q*(t) = Σ_j c_j t^j`` with exact derivatives.

        Parameters
        ----------
        coefficients : array_like, shape (d + 1, n)
            ``c_0, …, c_d`` (increasing powers of t), one row per power.
        """
        c = np.asarray(coefficients, dtype=float)
        if c.ndim != 2 or c.shape[0] < 1 or not np.isfinite(c).all():
            raise ShapeError(f"coefficients must be a finite array of shape (d + 1, n), got {c!r}")
        c = c.copy()
        d = c.shape[0] - 1
        p1 = np.arange(1, d + 1, dtype=float)[:, None] * c[1:]  # the derivative's coefficients
        p2 = np.arange(1, d, dtype=float)[:, None] * p1[1:]

        def horner(p: FloatArray) -> Callable[[float], FloatArray]:
            def f(t: float) -> FloatArray:
                out = np.zeros(c.shape[1])
                for row in p[::-1]:
                    out = out * t + row
                return out

            return f

        return cls(horner(c), horner(p1), horner(p2), piecewise=(np.array([0.0, 1.0]), c[::-1, None, :].copy(), False))

    @classmethod
    def from_functions(
        cls,
        position: Callable[[float], ArrayLike],
        velocity: Callable[[float], ArrayLike] | None = None,
        acceleration: Callable[[float], ArrayLike] | None = None,
        *,
        diff_step: float = 1e-4,
    ) -> Reference:
        """From callables (missing derivatives by central differences)."""
        if not callable(position):
            raise InputError("position must be callable t -> q*(t)")
        return cls(position, velocity, acceleration, float(diff_step))

    @classmethod
    def spline(cls, t: ArrayLike, q: ArrayLike) -> Reference:
        """Clamped cubic spline through samples ``q[i]`` at times ``t[i]`` (zero end velocities).

        Outside ``[t[0], t[-1]]`` the reference holds the end points.
        """
        from scipy.interpolate import CubicSpline

        tt = np.asarray(t, dtype=float)
        qq = np.asarray(q, dtype=float)
        if tt.ndim != 1 or qq.ndim != 2 or qq.shape[0] != tt.shape[0] or tt.size < 2:
            raise ShapeError(f"spline needs t shape (s,), q shape (s, n), s ≥ 2; got {tt.shape}, {qq.shape}")
        cs = CubicSpline(tt, qq, bc_type="clamped")
        d1, d2 = cs.derivative(1), cs.derivative(2)
        lo, hi = float(tt[0]), float(tt[-1])

        def clamp(f: Callable[[float], ArrayLike], zero_outside: bool) -> Callable[[float], ArrayLike]:
            def g(s: float) -> ArrayLike:
                if zero_outside and (s < lo or s > hi):
                    return np.zeros(qq.shape[1])
                return np.asarray(f(min(max(s, lo), hi)), dtype=float)

            return g

        return cls(clamp(cs, False), clamp(d1, True), clamp(d2, True),
                   piecewise=(np.asarray(cs.x, dtype=float), np.asarray(cs.c, dtype=float), True))  # fmt: skip

    def __call__(self, t: float) -> tuple[FloatArray, FloatArray, FloatArray]:
        """``(q*, q̇*, q̈*)`` at time ``t``."""
        q = np.asarray(self.position(t), dtype=float)
        h = self.diff_step
        if self.velocity is not None:
            v = np.asarray(self.velocity(t), dtype=float)
        else:
            v = (np.asarray(self.position(t + h), float) - np.asarray(self.position(t - h), float)) / (2 * h)
        if self.acceleration is not None:
            a = np.asarray(self.acceleration(t), dtype=float)
        elif self.velocity is not None:
            a = (np.asarray(self.velocity(t + h), float) - np.asarray(self.velocity(t - h), float)) / (2 * h)
        else:
            a = (
                np.asarray(self.position(t + h), float) - 2 * q + np.asarray(self.position(t - h), float)
            ) / (h * h)
        return q, v, a
