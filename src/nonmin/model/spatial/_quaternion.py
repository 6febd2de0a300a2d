"""Unit-quaternion kinematics used by the spatial source (Euler parameters).

Convention
----------
A quaternion is ``ε = (e0, e1, e2, e3) = (w, x, y, z)`` with scalar part first (Hamilton
convention). It rotates body-frame vectors into the world frame: ``v_world = R(ε) v_body`` with

    R(ε) = (e0² − eᵀe) I + 2 e eᵀ + 2 e0 ẽ = E(ε) G(ε)ᵀ,          e = (e1, e2, e3),

    E(ε) = [−e, e0 I + ẽ],   G(ε) = [−e, e0 I − ẽ]      (3 × 4, linear in ε),

``ẽ`` the cross-product matrix. For a unit quaternion the angular velocity is
``ω = 2 E ε̇`` (world frame) and ``ω' = 2 G ε̇`` (body frame); ``G ε = E ε = 0`` and
``G Gᵀ = E Eᵀ = ‖ε‖² I``. Because G is linear, ``G(a) b = −G(b) a`` for any a, b in R⁴.

The formula for ``R(ε)`` is used for every ε (not only unit ones): it is quadratic, so
``R(ε) s = [εᵀ Q_a(s) ε]_a`` with constant symmetric 4 × 4 matrices ``Q_a(s)``
(:func:`point_tensor`), which gives the exact Jacobian ``∂(R s)/∂ε = 2 Q(s) ε`` and its time
derivative ``2 Q(s) ε̇`` used by every joint.

Rigid-body kinetic energy: ``T = ½ m ṙᵀṙ + ½ ω'ᵀ J ω' = ½ ṙᵀ(m I)ṙ + ½ ε̇ᵀ (4 Gᵀ J G) ε̇``,
so the rotational block of the inertia matrix is ``M_ε = 4 G(ε)ᵀ J G(ε)`` (singular: ``M_ε ε
= 0``). Its Christoffel Coriolis matrix (derived from ``∂M_ε/∂ε``, G linear) is

    C_ε(ε, ε̇) = 4 G(ε̇)ᵀ J G(ε) + 4 H(J G(ε) ε̇),     H(a) = [[0, −aᵀ], [a, −ã]],

where ``H(a)`` (4 × 4, skew) is defined by ``G(v)ᵀ a = H(a) v``. Then
``dM_ε/dt − 2 C_ε = 4(Gᵀ J Ġ − Ġᵀ J G) − 8 H`` is skew and ``C_ε ε̇ = 8 Ġᵀ J G ε̇``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ...errors import ModelError

FloatArray = NDArray[np.float64]

__all__ = [
    "ROTATION_TENSOR",
    "E_matrix",
    "G_matrix",
    "H_matrix",
    "point_tensor",
    "quaternion_from_axis_angle",
    "quaternion_from_rotation_matrix",
    "rotation_matrix",
    "skew",
]


def skew(a: ArrayLike) -> FloatArray:
    """Cross-product matrix ``ã`` with ``ã b = a × b``, shape (3, 3)."""
    x, y, z = np.asarray(a, dtype=float)
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def G_matrix(e: ArrayLike) -> FloatArray:
    """``G(ε) = [−e, e0 I − ẽ]``, shape (3, 4): body angular velocity ``ω' = 2 G ε̇``."""
    e0, e1, e2, e3 = np.asarray(e, dtype=float)
    return np.array(
        [[-e1, e0, e3, -e2], [-e2, -e3, e0, e1], [-e3, e2, -e1, e0]],
    )


def E_matrix(e: ArrayLike) -> FloatArray:
    """``E(ε) = [−e, e0 I + ẽ]``, shape (3, 4): world angular velocity ``ω = 2 E ε̇``."""
    e0, e1, e2, e3 = np.asarray(e, dtype=float)
    return np.array(
        [[-e1, e0, -e3, e2], [-e2, e3, e0, -e1], [-e3, -e2, e1, e0]],
    )


def H_matrix(a: ArrayLike) -> FloatArray:
    """``H(a) = [[0, −aᵀ], [a, −ã]]``, shape (4, 4), skew, with ``G(v)ᵀ a = H(a) v``."""
    av = np.asarray(a, dtype=float)
    H = np.zeros((4, 4))
    H[0, 1:] = -av
    H[1:, 0] = av
    H[1:, 1:] = -skew(av)
    return H


def rotation_matrix(e: ArrayLike) -> FloatArray:
    """``R(ε) = E(ε) G(ε)ᵀ`` (body → world; a rotation when ‖ε‖ = 1), shape (3, 3)."""
    return E_matrix(e) @ G_matrix(e).T


def _rotation_tensor() -> FloatArray:
    # R_ab(ε) = Σ_jk T[a, b, j, k] ε_j ε_k with T symmetric in (j, k).
    T = np.zeros((3, 3, 4, 4))
    for a in range(3):
        T[a, a, 0, 0] += 1.0
        for i in range(1, 4):
            T[a, a, i, i] -= 1.0
        for b in range(3):
            T[a, b, a + 1, b + 1] += 1.0
            T[a, b, b + 1, a + 1] += 1.0
    levi = np.zeros((3, 3, 3))
    levi[0, 1, 2] = levi[1, 2, 0] = levi[2, 0, 1] = 1.0
    levi[0, 2, 1] = levi[2, 1, 0] = levi[1, 0, 2] = -1.0
    for a in range(3):
        for b in range(3):
            for c in range(3):
                # 2 e0 ẽ_ab, ẽ_ab = −Σ_c ϵ_abc e_c
                T[a, b, 0, c + 1] -= levi[a, b, c]
                T[a, b, c + 1, 0] -= levi[a, b, c]
    return T


#: Constant tensor with ``R(ε)_ab = Σ_jk T[a, b, j, k] ε_j ε_k``, shape (3, 3, 4, 4).
ROTATION_TENSOR: FloatArray = _rotation_tensor()
ROTATION_TENSOR.setflags(write=False)


def point_tensor(s: ArrayLike) -> FloatArray:
    """``Q(s)``, shape (3, 4, 4), with ``R(ε) s = εᵀ Q_a(s) ε`` for each world component a."""
    return np.einsum("abjk,b->ajk", ROTATION_TENSOR, np.asarray(s, dtype=float))


def quaternion_from_axis_angle(axis: ArrayLike, angle: float) -> FloatArray:
    """Unit quaternion ``(cos(θ/2), sin(θ/2) u)`` of a rotation by ``angle`` about ``axis``.

    Raises
    ------
    ModelError
        If the axis has zero length.
    """
    u = np.asarray(axis, dtype=float).reshape(3)
    nu = float(np.linalg.norm(u))
    if not np.isfinite(nu) or nu == 0.0:
        raise ModelError(f"axis must be a finite non-zero 3-vector, got {u.tolist()}")
    u = u / nu
    return np.concatenate(([np.cos(0.5 * angle)], np.sin(0.5 * angle) * u))


def quaternion_from_rotation_matrix(R: ArrayLike) -> FloatArray:
    """Unit quaternion (w ≥ 0) of a rotation matrix (Shepperd's method), shape (4,)."""
    Rm = np.asarray(R, dtype=float).reshape(3, 3)
    tr = float(np.trace(Rm))
    cands = np.array([tr, Rm[0, 0], Rm[1, 1], Rm[2, 2]])
    i = int(np.argmax(cands))
    if i == 0:
        w = 0.5 * np.sqrt(1.0 + tr)
        q = np.array(
            [w, (Rm[2, 1] - Rm[1, 2]) / (4 * w), (Rm[0, 2] - Rm[2, 0]) / (4 * w),
             (Rm[1, 0] - Rm[0, 1]) / (4 * w)]
        )
    else:
        a = i - 1
        b, c = (a + 1) % 3, (a + 2) % 3
        v = 0.5 * np.sqrt(max(1.0 + 2.0 * Rm[a, a] - tr, 0.0))
        q = np.zeros(4)
        q[a + 1] = v
        q[0] = (Rm[c, b] - Rm[b, c]) / (4 * v)
        q[b + 1] = (Rm[b, a] + Rm[a, b]) / (4 * v)
        q[c + 1] = (Rm[c, a] + Rm[a, c]) / (4 * v)
    if q[0] < 0:
        q = -q
    return q / np.linalg.norm(q)
