"""The crossed four-bar built with the planar builder and as a FunctionModel (φ written by hand,
A and Ȧ qd derived with SymPy) agree to 1e-10 in M, C qd, f_g, A, γ, φ and energy."""

from __future__ import annotations

import numpy as np
import pytest

from nonmin.library import crossed_four_bar
from nonmin.model import FunctionConstraint, FunctionModel

AGREE = 1e-10
G = 9.81


def _function_four_bar() -> FunctionModel:
    import sympy as sp
    q = sp.symbols("x1 y1 t1 x2 y2 t2 x3 y3 t3")
    qd = sp.symbols("xd1 yd1 td1 xd2 yd2 td2 xd3 yd3 td3")
    x1, y1, t1, x2, y2, t2, x3, y3, t3 = q
    c, s = sp.cos, sp.sin
    # φ = p_a − p_b for each pin (crank 1 m, coupler 2 m, rocker 1 m, ground 2 m)
    joints = {
        "A": [-(x1 - c(t1) / 2), -(y1 - s(t1) / 2)],
        "B": [x1 + c(t1) / 2 - (x2 - c(t2)), y1 + s(t1) / 2 - (y2 - s(t2))],
        "C": [x2 + c(t2) - (x3 + c(t3) / 2), y2 + s(t2) - (y3 + s(t3) / 2)],
        "D": [x3 - c(t3) / 2 - 2, y3 - s(t3) / 2],
    }
    cons = []
    for name, phi in joints.items():
        Phi = sp.Matrix(phi)
        J = Phi.jacobian(q)
        gamma = (J * sp.Matrix(qd)).jacobian(q) * sp.Matrix(qd)
        f_phi = sp.lambdify([q], list(Phi), "numpy")
        f_J = sp.lambdify([q], J, "numpy")
        f_g = sp.lambdify([q, qd], list(gamma), "numpy")
        cons.append(
            FunctionConstraint.holonomic(
                name,
                phi=lambda qq, f=f_phi: np.array(f(qq), dtype=float),
                jacobian=lambda qq, f=f_J: np.array(f(qq), dtype=float),
                adot_qd=lambda qq, vv, f=f_g: np.array(f(qq, vv), dtype=float),
                dim=2,
            )
        )
    masses = np.array([1.0, 2.0, 1.0])
    inertias = np.array([1.0 / 12, 2.0 * 4 / 12, 1.0 / 12])
    Mdiag = np.array([[m, m, i] for m, i in zip(masses, inertias)]).ravel()
    fg = np.zeros(9)
    fg[[1, 4, 7]] = -G * masses
    return FunctionModel(
        name="four_bar_fn",
        coordinate_names=[str(v) for v in q],
        mass=lambda qq: np.diag(Mdiag),
        coriolis=lambda qq, vv: np.zeros((9, 9)),
        conservative=lambda qq: fg,
        potential=lambda qq: float(G * masses @ qq[[1, 4, 7]]),
        constraints=cons,
    )


@pytest.fixture(scope="module")
def models():
    # built when a test asks, not when the module is collected (by every xdist worker)
    return crossed_four_bar().model, _function_four_bar()


@pytest.mark.parametrize("seed", range(5))
def test_planar_and_function_sources_agree(seed, models):
    PL, FN = models
    rng = np.random.default_rng(seed)
    q = rng.uniform(-2, 2, 9)
    qd = rng.standard_normal(9)
    t = 0.0
    np.testing.assert_allclose(PL.mass_matrix(q), FN.mass_matrix(q), atol=AGREE)
    np.testing.assert_allclose(PL.coriolis_force(q, qd), FN.coriolis_force(q, qd), atol=AGREE)
    np.testing.assert_allclose(PL.conservative_force(q), FN.conservative_force(q), atol=AGREE)
    a, b = PL.constraint_terms(t, q, qd), FN.constraint_terms(t, q, qd)
    for field in ("A", "gamma", "phi", "velocity"):
        np.testing.assert_allclose(getattr(a, field), getattr(b, field), atol=AGREE, err_msg=field)
    assert PL.energy(q, qd) == pytest.approx(FN.energy(q, qd), abs=AGREE)
    ea, eb = PL.evaluate(t, q, qd), FN.evaluate(t, q, qd)
    np.testing.assert_allclose(ea.h, eb.h, atol=AGREE)
