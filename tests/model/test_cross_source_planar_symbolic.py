"""The same planar four-bar (absolute coordinates x, y, θ per bar, revolute joints, gravity,
a spring-damper and a crank torque) from two sources — the planar builder and SymPy (T and V
from centre-of-mass kinematics) — agrees to 1e-10 in M, C qd, f_g, f_passive, B, A, γ, φ and
energy."""

from __future__ import annotations

import numpy as np
import pytest

from nonmin.model.planar import PlanarBuilder
from nonmin.model.symbolic import SymbolicConstraint, SymbolicModel

AGREE = 1e-10

BARS = (("crank", 1.0, 1.0), ("coupler", 2.0, 2.2), ("rocker", 1.5, 1.6))  # name, mass, length
D = 2.0  # ground length
ANCHOR = (0.5, 1.5)  # spring anchor on the ground
K, L0, C_DAMP, G = 20.0, 0.3, 0.7, 9.81


def _planar():
    b = PlanarBuilder("fourbar_planar", gravity=(0.0, -G))
    for name, m, L in BARS:
        b.body(name, mass=m, inertia=m * L**2 / 12)
    L1, L2, L3 = (L for _, _, L in BARS)
    b.revolute("O", ("ground", (0.0, 0.0)), ("crank", (-L1 / 2, 0.0)))
    b.revolute("A", ("crank", (L1 / 2, 0.0)), ("coupler", (-L2 / 2, 0.0)))
    b.revolute("B", ("coupler", (L2 / 2, 0.0)), ("rocker", (L3 / 2, 0.0)))
    b.revolute("D", ("ground", (D, 0.0)), ("rocker", (-L3 / 2, 0.0)))
    b.spring("spring", ("ground", ANCHOR), ("coupler", (0.0, 0.0)), stiffness=K, rest_length=L0,
             damping=C_DAMP)
    b.actuator("motor", "O")
    return b.build()


def _symbolic():
    import sympy as sp
    qs = sp.symbols("x1 y1 th1 x2 y2 th2 x3 y3 th3")
    vs = sp.symbols("x1d y1d th1d x2d y2d th2d x3d y3d th3d")
    T = 0
    V = 0
    for i, (_, m, L) in enumerate(BARS):
        y = qs[3 * i + 1]
        xd, yd, thd = vs[3 * i : 3 * i + 3]
        T += m * (xd**2 + yd**2) / 2 + m * L**2 / 12 * thd**2 / 2
        V += m * G * y

    def point(i, sx):  # world position of local point (sx, 0) on bar i
        x, y, th = qs[3 * i : 3 * i + 3]
        return sp.Matrix([x + sx * sp.cos(th), y + sx * sp.sin(th)])

    L1, L2, L3 = (L for _, _, L in BARS)
    ground = lambda x, y: sp.Matrix([x, y])  # noqa: E731
    joints = [
        ("O", ground(0, 0) - point(0, -L1 / 2)),
        ("A", point(0, L1 / 2) - point(1, -L2 / 2)),
        ("B", point(1, L2 / 2) - point(2, L3 / 2)),
        ("D", ground(D, 0) - point(2, -L3 / 2)),
    ]
    d = point(1, 0) - ground(*ANCHOR)
    ell = sp.sqrt(d.dot(d))
    V += K * (ell - L0) ** 2 / 2
    grad = sp.Matrix([ell]).jacobian(qs)
    ell_dot = (grad * sp.Matrix(vs))[0]
    passive = list(-C_DAMP * ell_dot * grad.T)
    B = sp.zeros(9, 1)
    B[2, 0] = 1  # crank torque (reaction on the ground)
    return SymbolicModel.from_energy(
        "fourbar_symbolic",
        q=list(qs),
        qd=list(vs),
        T=T,
        V=V,
        constraints=[SymbolicConstraint.holonomic(n, list(e)) for n, e in joints],
        B=B,
        actuator_names=["motor"],
        passive=passive,
    )


@pytest.fixture(scope="module")
def pair():
    return _planar(), _symbolic()


def test_planar_builder_vs_sympy(pair) -> None:
    planar, symbolic = pair
    assert planar.n == symbolic.n == 9
    assert planar.constraint_names == symbolic.constraint_names
    rng = np.random.default_rng(11)
    for _ in range(4):
        q = rng.normal(size=9)
        qd = rng.normal(size=9)
        for name in ("mass_matrix", "conservative_force", "input_matrix"):
            np.testing.assert_allclose(
                getattr(planar, name)(q), getattr(symbolic, name)(q), atol=AGREE, err_msg=name
            )
        np.testing.assert_allclose(
            planar.coriolis_force(q, qd), symbolic.coriolis_force(q, qd), atol=AGREE
        )
        np.testing.assert_allclose(
            planar.passive_force(0.0, q, qd), symbolic.passive_force(0.0, q, qd), atol=AGREE
        )
        a = planar.constraint_terms(0.0, q, qd)
        b = symbolic.constraint_terms(0.0, q, qd)
        for field in ("A", "gamma", "phi", "velocity"):
            np.testing.assert_allclose(getattr(a, field), getattr(b, field), atol=AGREE, err_msg=field)
        np.testing.assert_allclose(
            planar.constraint_jacobian_dot(0.0, q, qd),
            symbolic.constraint_jacobian_dot(0.0, q, qd),
            atol=AGREE,
        )
        assert planar.potential_energy(q) == pytest.approx(symbolic.potential_energy(q), abs=AGREE)
        assert planar.energy(q, qd) == pytest.approx(symbolic.energy(q, qd), abs=AGREE)
