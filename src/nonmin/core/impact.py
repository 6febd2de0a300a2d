"""Impact map at constraint activation (not in the paper; see ERRATA "Beyond the paper").

Plastic impact (restitution 0): ``qd⁺ = M̄⁻¹ P M qd⁻``, impulse ``M (qd⁺ − qd⁻) = −S M qd⁻``.
It equals the classical mass-orthogonal projection ``(I − M⁻¹Aᵀ(AM⁻¹Aᵀ)⁺A) qd⁻``, does not
depend on μ, works for rank-deficient A and M singular off N(A), and loses exactly Carnot's
energy ``½ (qd⁻ − qd⁺)ᵀ M (qd⁻ − qd⁺)``. With Newton's restitution coefficient e:
``qd⁺ = qd⁻ + (1 + e)(qd⁺_plastic − qd⁻)``, so ``A qd⁺ = −e A qd⁻``.
The same map is the post-step velocity correction onto ``A qd = 0`` in the mass metric.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from .. import _validation as V
from . import _fast
from .dynamics import _optimal_mu
from .linalg import FloatArray, cho_solve, cholesky, matvec, range_basis, resolve_rtol

__all__ = ["impact_map"]


def impact_map(
    M: ArrayLike,
    A: ArrayLike,
    qd_minus: ArrayLike,
    *,
    restitution: float = 0.0,
    mu: ArrayLike | None = None,
    rtol: float | None = None,
) -> FloatArray:
    """Post-impact velocity when the constraints ``A qd = 0`` become active.

    Not in the paper: ERRATA, "Impact map at constraint activation" (plastic map
    ``qd⁺ = M̄⁻¹PM qd⁻``, extended with Newton's restitution).

    Parameters
    ----------
    M : array_like, shape (..., n, n)
        Inertia matrix (positive definite on N(A)).
    A : array_like, shape (..., m, n)
        Constraint matrix of the constraints active *after* the impact.
    qd_minus : array_like, shape (..., n)
        Pre-impact velocity.
    restitution : float, default 0.0
        Newton coefficient of restitution ``e ∈ [0, 1]``; 0 is plastic.
    mu : float or array_like, optional
        Virtual mass (the result does not depend on it).
    rtol : float, optional
        Rank tolerance.

    Returns
    -------
    qd_plus : ndarray, shape (..., n)
        ``qd⁻ + (1 + e)(M̄⁻¹PM qd⁻ − qd⁻)``.

    Examples
    --------
    >>> import numpy as np
    >>> from nonmin.core import impact_map
    >>> impact_map(np.eye(2), [[0.0, 1.0]], [1.0, -2.0]).round(12).tolist()
    [1.0, 0.0]
    """
    Mm = V.symmetric(M, "M")
    n = Mm.shape[-1]
    Am = V.matrix(A, "A", None, n)
    v = V.vector(qd_minus, "qd_minus", n)
    e = V.nonnegative_float(restitution, "restitution", 1.0)
    mu_v = None if mu is None else V.positive_scalar_or_batch(mu, "mu")
    if n and _fast.engine_on():  # engine/src/core_dynamics.cpp: impact_map
        out = _fast.engine_solver_kernel(0, Mm, Am, v, mu_v, e, resolve_rtol(rtol))
        if out is not None:
            return out
    basis = range_basis(Am, rtol)
    Q = basis.range_projector()
    P = np.eye(n) - Q
    PM = P @ Mm
    PMP = PM @ P
    mu_a = _optimal_mu(PMP, Mm, basis.rank) if mu_v is None else mu_v
    L = cholesky(PMP + np.asarray(mu_a)[..., None, None] * Q)
    plastic = cho_solve(L, matvec(PM, v))
    return v + (1.0 + e) * (plastic - v)
