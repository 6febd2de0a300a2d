"""The spinning top from two sources — the spatial builder (closed-form quaternion M, C) and
SymPy (T written from the angular velocity ω' = 2 G ε̇, C derived by differentiation) — agrees
to 1e-10 in M, C qd, f_g, A, γ and energy, on and off the unit sphere."""

from __future__ import annotations

import numpy as np
import pytest

from nonmin.library.top import top_model, top_state
from nonmin.model.symbolic import SymbolicConstraint, SymbolicModel

AGREE = 1e-10


def _sympy_top(mass, l, I1, I3, g) -> SymbolicModel:
    import sympy as sp
    x, y, z, e0, e1, e2, e3 = q = sp.symbols("x y z e0 e1 e2 e3")
    qd = sp.symbols("xd yd zd e0d e1d e2d e3d")
    G = sp.Matrix([[-e1, e0, e3, -e2], [-e2, -e3, e0, e1], [-e3, e2, -e1, e0]])
    E = sp.Matrix([[-e1, e0, -e3, e2], [-e2, e3, e0, -e1], [-e3, -e2, e1, e0]])
    R = E * G.T
    w = 2 * G * sp.Matrix(qd[3:])
    J = sp.diag(I1, I1, I3)
    v = sp.Matrix(qd[:3])
    T = mass * (v.T * v)[0] / 2 + (w.T * J * w)[0] / 2
    V = mass * g * z
    r = sp.Matrix([x, y, z])
    tip = r + R * sp.Matrix([0, 0, -l])  # the tip is at −l on the body axis from the COM
    cons = [
        SymbolicConstraint.holonomic("top.norm", (e0**2 + e1**2 + e2**2 + e3**2 - 1) / 2),
        SymbolicConstraint.holonomic("tip", list(tip)),  # φ = p_b − p_a (a = ground)
    ]
    return SymbolicModel.from_energy("top_sympy", q=list(q), qd=list(qd), T=T, V=V, constraints=cons)


@pytest.fixture(scope="module")
def pair():
    p = dict(mass=0.5, l=0.1, transverse_inertia=2.5e-3, axial_inertia=3.0e-3, g=9.81)
    spatial = top_model(**p, tilt=0.3)
    symbolic = _sympy_top(p["mass"], p["l"], p["transverse_inertia"], p["axial_inertia"], p["g"])
    return spatial, symbolic


def test_top_spatial_vs_sympy(pair) -> None:
    spatial, symbolic = pair
    assert spatial.constraint_names == symbolic.constraint_names
    s = top_state(spatial, spin=30.0, precession=2.0)
    rng = np.random.default_rng(3)
    states = [(s.q, s.qd)] + [
        (s.q + 0.1 * rng.normal(size=7), rng.normal(size=7)) for _ in range(3)
    ]
    for q, qd in states:
        np.testing.assert_allclose(spatial.mass_matrix(q), symbolic.mass_matrix(q), atol=AGREE)
        np.testing.assert_allclose(
            spatial.coriolis_matrix(q, qd), symbolic.coriolis_matrix(q, qd), atol=AGREE
        )
        np.testing.assert_allclose(
            spatial.coriolis_force(q, qd), symbolic.coriolis_force(q, qd), atol=AGREE
        )
        np.testing.assert_allclose(
            spatial.conservative_force(q), symbolic.conservative_force(q), atol=AGREE
        )
        a = spatial.constraint_terms(0.0, q, qd)
        b = symbolic.constraint_terms(0.0, q, qd)
        for field in ("A", "gamma", "phi", "velocity"):
            np.testing.assert_allclose(getattr(a, field), getattr(b, field), atol=AGREE)
        np.testing.assert_allclose(
            spatial.constraint_jacobian_dot(0.0, q, qd),
            symbolic.constraint_jacobian_dot(0.0, q, qd),
            atol=AGREE,
        )
        assert spatial.energy(q, qd) == pytest.approx(symbolic.energy(q, qd), abs=AGREE)
