"""Validation of rigid-body inertia tensors (used by the builder and by the model itself)."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from ...errors import ModelError
from .._protocol import FloatArray

__all__ = ["INERTIA_RTOL", "check_inertia"]

#: Relative tolerance of the inertia checks (symmetry, triangle inequality).
INERTIA_RTOL = 1e-9


def check_inertia(inertia: ArrayLike, name: str = "inertia") -> FloatArray:
    """Validate a rigid-body inertia tensor about the centre of mass.

    It must be a finite symmetric 3 × 3 matrix with positive principal moments that satisfy
    the triangle inequality ``I_i + I_j ≥ I_k`` (every physical mass distribution does).
    A 3-vector is read as the diagonal.

    Raises
    ------
    ModelError
        If the tensor is not physical.
    """
    try:
        J = np.asarray(inertia, dtype=float)
    except (TypeError, ValueError):
        raise ModelError(f"{name} must be a 3×3 matrix or 3-vector, got {inertia!r}") from None
    if J.shape == (3,):
        J = np.diag(J)
    if J.shape != (3, 3):
        raise ModelError(f"{name} must have shape (3, 3) or (3,), got shape {J.shape}")
    if not np.isfinite(J).all():
        raise ModelError(f"{name} must be finite, got {J.tolist()}")
    scale = float(np.max(np.abs(J))) or 1.0
    if np.max(np.abs(J - J.T)) > INERTIA_RTOL * scale:
        raise ModelError(f"{name} must be symmetric, got {J.tolist()}")
    J = 0.5 * (J + J.T)
    lam = np.linalg.eigvalsh(J)
    if lam[0] <= 0.0:
        raise ModelError(
            f"{name} must be positive definite (principal moments > 0), got principal moments "
            f"{lam.tolist()}"
        )
    if lam[0] + lam[1] < lam[2] * (1.0 - INERTIA_RTOL):
        raise ModelError(
            f"{name} violates the triangle inequality I1 + I2 ≥ I3 of a physical body: "
            f"principal moments {lam.tolist()}"
        )
    return J
