"""The same four-bar linkage from two sources — SymPy (T and V from centre-of-mass kinematics)
and hand-written functions (closed-form M, Christoffel C, f_g, A, Ȧ qd) — agrees to 1e-10."""

from __future__ import annotations

import numpy as np
import pytest

from nonmin.model import FunctionConstraint, FunctionModel
from nonmin.model.symbolic import SymbolicConstraint, SymbolicModel

#: Required agreement between sources.
AGREE = 1e-10

PARAMS = {"m1": 1.0, "m2": 2.0, "m3": 1.5, "l1": 1.0, "l2": 2.2, "l3": 1.6, "d": 2.0, "g": 9.81}


def _sympy_fourbar() -> SymbolicModel:
    """Absolute link angles θ1 (crank at the origin), θ2 (coupler), θ3 (rocker at (d, 0));
    uniform slender rods (I = m l²/12)."""
    import sympy as sp
    t1, t2, t3 = sp.symbols("theta1 theta2 theta3")
    w1, w2, w3 = sp.symbols("omega1 omega2 omega3")
    m1, m2, m3, l1, l2, l3, d, g = sp.symbols("m1 m2 m3 l1 l2 l3 d g")
    q = [t1, t2, t3]
    qd = [w1, w2, w3]

    def vel(e):
        return sum(sp.diff(e, qi) * vi for qi, vi in zip(q, qd))

    com = [
        (l1 / 2 * sp.cos(t1), l1 / 2 * sp.sin(t1)),
        (l1 * sp.cos(t1) + l2 / 2 * sp.cos(t2), l1 * sp.sin(t1) + l2 / 2 * sp.sin(t2)),
        (d + l3 / 2 * sp.cos(t3), l3 / 2 * sp.sin(t3)),
    ]
    masses = [m1, m2, m3]
    lengths = [l1, l2, l3]
    T = sum(
        m / 2 * (vel(x) ** 2 + vel(y) ** 2) + m * L**2 / 24 * w**2
        for (x, y), m, L, w in zip(com, masses, lengths, qd)
    )
    V = g * sum(m * y for (_, y), m in zip(com, masses))
    loop = [
        l1 * sp.cos(t1) + l2 * sp.cos(t2) - l3 * sp.cos(t3) - d,
        l1 * sp.sin(t1) + l2 * sp.sin(t2) - l3 * sp.sin(t3),
    ]
    return SymbolicModel.from_energy(
        "fourbar_sympy",
        q=q,
        qd=qd,
        T=T,
        V=V,
        constraints=[SymbolicConstraint.holonomic("loop", loop)],
        params=PARAMS,
    )


def _function_fourbar() -> FunctionModel:
    p = PARAMS
    m1, m2, m3, l1, l2, l3, d, g = (p[k] for k in ("m1", "m2", "m3", "l1", "l2", "l3", "d", "g"))
    a = m2 * l1 * l2 / 2  # M12 = a cos(θ1 − θ2)

    def mass(q):
        c12 = np.cos(q[0] - q[1])
        return np.array(
            [
                [m1 * l1**2 / 3 + m2 * l1**2, a * c12, 0.0],
                [a * c12, m2 * l2**2 / 3, 0.0],
                [0.0, 0.0, m3 * l3**2 / 3],
            ]
        )

    def coriolis(q, qd):
        s12 = np.sin(q[0] - q[1])
        return np.array([[0.0, a * s12 * qd[1], 0.0], [-a * s12 * qd[0], 0.0, 0.0], np.zeros(3)])

    def conservative(q):
        c1, c2, c3 = np.cos(q)
        return -g * np.array([(m1 / 2 + m2) * l1 * c1, m2 * l2 / 2 * c2, m3 * l3 / 2 * c3])

    def potential(q):
        s1, s2, s3 = np.sin(q)
        return g * ((m1 / 2 + m2) * l1 * s1 + m2 * l2 / 2 * s2 + m3 * l3 / 2 * s3)

    L = np.array([l1, l2, -l3])

    def phi(q):
        return [L @ np.cos(q) - d, L @ np.sin(q)]

    def jac(q):
        return np.array([-L * np.sin(q), L * np.cos(q)])

    def adot_qd(q, qd):
        return np.array([-(L * np.cos(q)) @ qd**2, -(L * np.sin(q)) @ qd**2])

    return FunctionModel(
        name="fourbar_functions",
        coordinate_names=("theta1", "theta2", "theta3"),
        mass=mass,
        coriolis=coriolis,
        conservative=conservative,
        potential=potential,
        constraints=(FunctionConstraint.holonomic("loop", phi, jac, adot_qd, dim=2),),
    )


@pytest.fixture(scope="module")
def models() -> tuple[SymbolicModel, FunctionModel]:
    return _sympy_fourbar(), _function_fourbar()


def test_fourbar_sympy_vs_functions(models) -> None:
    sym, fun = models
    assert sym.coordinate_names == fun.coordinate_names
    rng = np.random.default_rng(42)
    for _ in range(5):
        q = rng.uniform(-np.pi, np.pi, 3)
        qd = rng.normal(size=3)
        np.testing.assert_allclose(sym.mass_matrix(q), fun.mass_matrix(q), atol=AGREE)
        np.testing.assert_allclose(sym.coriolis_matrix(q, qd), fun.coriolis_matrix(q, qd), atol=AGREE)
        np.testing.assert_allclose(sym.coriolis_force(q, qd), fun.coriolis_force(q, qd), atol=AGREE)
        np.testing.assert_allclose(sym.conservative_force(q), fun.conservative_force(q), atol=AGREE)
        cs = sym.constraint_terms(0.0, q, qd)
        cf = fun.constraint_terms(0.0, q, qd)
        np.testing.assert_allclose(cs.A, cf.A, atol=AGREE)
        np.testing.assert_allclose(cs.gamma, cf.gamma, atol=AGREE)
        np.testing.assert_allclose(cs.phi, cf.phi, atol=AGREE)
        assert sym.potential_energy(q) == pytest.approx(fun.potential_energy(q), abs=AGREE)
        assert sym.energy(q, qd) == pytest.approx(fun.energy(q, qd), abs=AGREE)


def test_fourbar_accelerations_agree(models) -> None:
    """Same forward dynamics through nonmin's core from both sources."""
    from nonmin.core import forward_dynamics

    sym, fun = models
    rng = np.random.default_rng(7)
    q = rng.uniform(-np.pi, np.pi, 3)
    qd = rng.normal(size=3)
    out = []
    for mdl in (sym, fun):
        ev = mdl.evaluate(0.0, q, qd)
        out.append(forward_dynamics(ev.M, ev.h, ev.constraints.A, ev.constraints.gamma))
    np.testing.assert_allclose(out[0], out[1], atol=AGREE)
