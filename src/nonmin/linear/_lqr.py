"""LQR regulation of a constrained system about a rest configuration, designed on the
tangent-space linearization (:func:`nonmin.linear.linearize`) and run as a nonmin controller.

For the active set in force at each call the controller holds (computed once per active set,
when it is first met — the re-linearization after a topology switch):

* the operating point ``q*`` (the target, which must satisfy that set's position-level
  constraints) and the feed-forward ``u* = −Γ P g(q*, 0)`` with ``Γ = (PB)⁺`` (ERRATA 4), which
  makes ``q*`` an equilibrium when the actuation condition ``rank(PB) = n − r`` holds;
* the linearization ``ẋ = A x + B δu`` in tangent coordinates ``x = (Z_qᵀ (q − q*), Zᵀ q̇)``
  and the gain ``K = R⁻¹ Bᵀ X`` of the continuous algebraic Riccati equation
  ``Aᵀ X + X A − X B R⁻¹ Bᵀ X + W = 0`` (``scipy.linalg.solve_continuous_are``), with the state
  weight ``W = diag(Z_qᵀ W_q Z_q, Zᵀ W_v Z)`` from weights on the dependent coordinates, so the
  same weights serve every active set;

and returns ``u = u* − K x``.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..control._common import gain_matrix
from ..control._protocol import Controller
from ..errors import InfeasibleActuationError, InputError, ModelError
from ..model import Model
from ._derivatives import _vector
from ._linearize import LinearSystem, linearize

FloatArray = NDArray[np.float64]

__all__ = ["LQR", "LQRDesign"]


@dataclass(frozen=True)
class LQRDesign:
    """The design of :class:`LQR` for one active set.

    Attributes
    ----------
    system : LinearSystem
        Linearization at ``(q*, 0, u*)``.
    K : ndarray, shape (k, n_x)
        State feedback gain.
    X : ndarray, shape (n_x, n_x)
        Solution of the Riccati equation.
    u_ff : ndarray, shape (k,)
        Feed-forward holding q* at rest.
    closed_loop_eigenvalues : ndarray of complex, shape (n_x,)
        Eigenvalues of ``A − B K``.
    """

    system: LinearSystem
    K: FloatArray
    X: FloatArray
    u_ff: FloatArray
    closed_loop_eigenvalues: NDArray[np.complex128]


@dataclass(frozen=True)
class LQR(Controller):
    """Linear-quadratic regulator of a constrained system about a rest configuration.

    Parameters
    ----------
    model : Model
        Planar model or robot with actuators.
    q_target : array_like, shape (n,)
        Configuration to hold (on the manifold of every active set it will meet).
    weight_q, weight_qd : float, array_like of shape (n,) or (n, n)
        State weights on the dependent coordinates and velocities (projected onto the tangent
        space of each active set). Default 1 and 0.1.
    weight_u : float, array_like of shape (k,) or (k, k)
        Input weight R (default 1).
    u_target : array_like, shape (k,), optional
        Feed-forward; default ``u* = −(PB)⁺ P g(q*, 0)``.
    rtol : float, optional
        Rank tolerance.

    Notes
    -----
    Designs are computed lazily, once per active set, and kept in a private cache: the
    controller is otherwise immutable and its output depends only on ``(t, q, q̇, active)``.
    :meth:`design` returns the design for a given active set.
    """

    model: Model
    q_target: ArrayLike
    weight_q: Any = 1.0
    weight_qd: Any = 0.1
    weight_u: Any = 1.0
    u_target: ArrayLike | None = None
    rtol: float | None = None
    _cache: dict[frozenset[str], LQRDesign] = field(
        default_factory=dict, init=False, repr=False, compare=False
    )

    def __post_init__(self) -> None:
        if not isinstance(self.model, Model):
            raise InputError(f"model must be a nonmin Model, got {type(self.model).__name__}")
        n, k = self.model.n, self.model.k
        if k == 0:
            raise InputError(f"LQR: model {self.model.name!r} has no actuators")
        object.__setattr__(self, "q_target", _vector(self.q_target, "q_target", n).copy())
        object.__setattr__(self, "_Wq", gain_matrix(self.weight_q, "weight_q", n, allow_zero=True))
        object.__setattr__(
            self, "_Wv", gain_matrix(self.weight_qd, "weight_qd", n, allow_zero=True)
        )
        object.__setattr__(self, "_R", gain_matrix(self.weight_u, "weight_u", k))
        if self.u_target is not None:
            object.__setattr__(self, "u_target", _vector(self.u_target, "u_target", k).copy())

    def design(self, active: Iterable[str] | None = None) -> LQRDesign:
        """The linearization and gain for an active set (computed at its first use)."""
        import scipy.linalg

        act = self.model.resolve_active(active)
        got = self._cache.get(act)
        if got is not None:
            return got
        qs = np.asarray(self.q_target)
        n = self.model.n
        terms = self.model.evaluate(0.0, qs, np.zeros(n), act)
        phi = terms.constraints.phi[terms.constraints.holonomic]
        if phi.size and float(np.abs(phi).max()) > 1e-8 * (1.0 + float(np.abs(qs).max())):
            raise ModelError(
                f"LQR: q_target violates the position-level constraints of the active set {sorted(act)} "
                f"(max |φ| = {float(np.abs(phi).max()):.3g}); assemble it first (nonmin.assemble)"
            )
        if self.u_target is None:
            from ..core import range_basis

            P = range_basis(
                np.asarray(terms.constraints.A, dtype=float), self.rtol
            ).nullspace_projector()
            PB = P @ terms.B
            g = terms.h + terms.f_passive
            u_ff = -np.linalg.pinv(PB) @ (P @ g)
            if np.linalg.norm(P @ (g + terms.B @ u_ff)) > 1e-8 * (
                1.0 + float(np.linalg.norm(P @ g))
            ):
                raise InfeasibleActuationError(
                    f"LQR: the actuators cannot hold q_target at rest under {sorted(act)} "
                    "(P(g + B u) = 0 has no solution)"
                )
        else:
            u_ff = np.asarray(self.u_target, dtype=float)
        sys = linearize(
            self.model, qs, None, u=u_ff, inputs="actuators", active=act, rtol=self.rtol
        )
        W = np.zeros_like(sys.A)
        nz = sys.tangent_dim
        Wq = self._Wq  # type: ignore[attr-defined]
        Wv = self._Wv  # type: ignore[attr-defined]
        W[:nz, :nz] = sys.Zq.T @ Wq @ sys.Zq
        W[nz:, nz:] = sys.Zv.T @ Wv @ sys.Zv
        R = self._R  # type: ignore[attr-defined]
        try:
            X = scipy.linalg.solve_continuous_are(sys.A, sys.B, W, R)
        except (np.linalg.LinAlgError, ValueError) as exc:
            raise ModelError(
                f"LQR: no stabilizing solution of the Riccati equation for {sorted(act)} ({exc}); "
                "the linearization may not be stabilizable by these actuators"
            ) from None
        K = np.linalg.solve(R, sys.B.T @ X)
        d = LQRDesign(
            system=sys,
            K=K,
            X=X,
            u_ff=u_ff,
            closed_loop_eigenvalues=np.linalg.eigvals(sys.A - sys.B @ K).astype(np.complex128),
        )
        self._cache[act] = d
        return d

    def __call__(
        self,
        t: float,
        q: ArrayLike,
        qd: ArrayLike,
        state: Any = None,
        *,
        active: Iterable[str] | None = None,
    ) -> FloatArray:
        """Actuator forces ``u = u* − K x``, shape (k,)."""
        d = self.design(active)
        x = d.system.from_dependent(q, qd)
        return d.u_ff - d.K @ x
