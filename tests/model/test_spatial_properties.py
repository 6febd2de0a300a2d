"""Property tests (hypothesis) of the quaternion inertia block and its Christoffel matrix."""

from __future__ import annotations

import numpy as np
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from nonmin.model.spatial import SpatialBuilder, rotation_matrix
from nonmin.model.spatial._quaternion import G_matrix

finite = st.floats(-2.0, 2.0, allow_nan=False)
vec4 = arrays(np.float64, 4, elements=finite)
moments = st.tuples(st.floats(0.1, 1.0), st.floats(0.1, 1.0), st.floats(0.0, 1.0))


def _body(I):
    a, b, t = I
    c = min(a + b, t * (a + b) + abs(a - b))  # keep the triangle inequality
    c = max(c, abs(a - b) + 1e-3)
    m = SpatialBuilder("one").add_body("b", mass=2.0, inertia=[a, b, c]).build()
    return m, np.diag([a, b, c])


@given(e=vec4, ed=vec4, v=vec4, I=moments)
def test_quaternion_block_properties(e, ed, v, I) -> None:
    if np.linalg.norm(e) < 0.1:
        e = e + np.array([1.0, 0.0, 0.0, 0.0])
    model, J = _body(I)
    q = np.concatenate(([0.1, 0.2, 0.3], e))
    qd = np.concatenate(([1.0, -1.0, 0.5], ed))
    M = model.mass_matrix(q)[3:, 3:]
    scale = 1.0 + np.linalg.norm(e) ** 2 * (1 + np.linalg.norm(ed)) ** 2
    # symmetric, positive semi-definite, singular exactly along ε
    np.testing.assert_allclose(M, M.T, atol=1e-13 * scale)
    np.testing.assert_allclose(M @ e, 0.0, atol=1e-12 * scale)
    lam = np.linalg.eigvalsh(M)
    assert lam[0] > -1e-12 * scale
    # on the tangent space, eigenvalues are 4‖ε‖² × principal moments
    np.testing.assert_allclose(
        np.sort(lam[1:]), np.sort(4 * np.linalg.norm(e) ** 2 * np.diag(J)), rtol=1e-9, atol=1e-12
    )
    # exact Ṁ (G is linear) and the skew-symmetry of Ṁ − 2C
    G, Gd = G_matrix(e), G_matrix(ed)
    Mdot = 4 * (Gd.T @ J @ G + G.T @ J @ Gd)
    C = model.coriolis_matrix(q, qd)[3:, 3:]
    S = Mdot - 2 * C
    np.testing.assert_allclose(S + S.T, 0.0, atol=1e-12 * scale)
    # Christoffel symmetry C(q, a) b = C(q, b) a
    qv = np.concatenate(([0.0, 0.0, 0.0], v))
    np.testing.assert_allclose(
        model.coriolis_matrix(q, qd) @ qv, model.coriolis_matrix(q, qv) @ qd, atol=1e-12 * scale
    )
    # rotation of a unit quaternion is orthonormal
    R = rotation_matrix(e / np.linalg.norm(e))
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-13)
