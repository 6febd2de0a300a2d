"""Symbolic (SymPy) source: derived terms against finite differences and closed forms,
parameters, every constraint kind, errors, the missing-dependency path."""

from __future__ import annotations

import sys

import numpy as np
import pytest

from nonmin.errors import InputError, MissingDependencyError, ModelError, UnknownNameError
from nonmin.model import Model
from nonmin.model.symbolic import SymbolicConstraint, SymbolicModel

FD_STEP = 1e-6
FD_TOL = 1e-7


def _fd(f, x, h=FD_STEP):
    return np.array([(f(x + h * e) - f(x - h * e)) / (2 * h) for e in np.eye(x.size)]).T


@pytest.fixture(scope="module")
def slider_pendulum() -> SymbolicModel:
    """A cart (x) with a pendulum (θ), in (x, θ, xp, yp) with the bob's position as extra
    coordinates tied by two holonomic rows; a rheonomic drive of the cart, a nonholonomic
    row and a unilateral floor; a damper, an input and outputs."""
    import sympy as sp
    x, th, xp, yp = sp.symbols("x theta xp yp")
    xd, thd, xpd, ypd = sp.symbols("xd thetad xpd ypd")
    t = sp.Symbol("t")
    M_, m, I, L, g, c = sp.symbols("M m I L g c")
    T = (M_ * xd**2 + m * (xpd**2 + ypd**2) + I * thd**2) / 2
    V = m * g * yp
    cons = [
        SymbolicConstraint.holonomic("rod", [xp - x - L * sp.sin(th), yp + L * sp.cos(th)]),
        SymbolicConstraint.rheonomic("drive", x - sp.Rational(1, 10) * sp.sin(3 * t)),
        SymbolicConstraint.nonholonomic("nh", [sp.cos(th), 0, 0, x]),
        SymbolicConstraint.unilateral("floor", yp + 2 * L),
    ]
    return SymbolicModel.from_energy(
        "slider_pendulum",
        q=[x, th, xp, yp],
        qd=[xd, thd, xpd, ypd],
        T=T,
        V=V,
        constraints=cons,
        params={M_: 2.0, m: 0.5, "I": 0.01, L: 0.7, g: 9.81, c: 0.3},
        t=t,
        B=sp.Matrix([1, 0, 0, 0]),
        actuator_names=["push"],
        passive=[-c * xd, 0, 0, 0],
        outputs={"bob": [xp, yp], "speed": sp.sqrt(xpd**2 + ypd**2)},
    )


def test_protocol_and_names(slider_pendulum: SymbolicModel) -> None:
    m = slider_pendulum
    assert isinstance(m, Model)
    assert m.coordinate_names == ("x", "theta", "xp", "yp")
    assert m.constraint_names == ("rod", "drive", "nh", "floor")
    assert [c.kind for c in m.constraints] == ["holonomic", "rheonomic", "nonholonomic", "unilateral"]
    assert m.default_active == {"rod", "drive", "nh"}
    assert m.num_rows(m.constraint_names) == 5
    q = np.array([0.1, 0.4, 0.5, -0.6])
    np.testing.assert_allclose(m.mass_matrix(q), np.diag([2.0, 0.01, 0.5, 0.5]))
    np.testing.assert_allclose(m.conservative_force(q), [0, 0, 0, -0.5 * 9.81])
    assert m.potential_energy(q) == pytest.approx(0.5 * 9.81 * -0.6)
    np.testing.assert_allclose(m.input_matrix(q), [[1], [0], [0], [0]])
    np.testing.assert_allclose(m.passive_force(0.0, q, np.array([2.0, 0, 0, 0])), [-0.6, 0, 0, 0])
    out = m.outputs(0.0, q, np.array([0, 0, 3.0, 4.0]))
    np.testing.assert_allclose(out["bob"], [0.5, -0.6])
    assert float(out["speed"]) == pytest.approx(5.0)


def test_constraint_derivatives_against_finite_differences(slider_pendulum: SymbolicModel) -> None:
    m = slider_pendulum
    rng = np.random.default_rng(0)
    q, qd = rng.normal(size=(2, 4))
    t = 0.37
    allc = m.constraint_names
    ct = m.constraint_terms(t, q, qd, active=allc)
    hol = ["rod", "drive", "floor"]
    A_h = m.constraint_terms(t, q, qd, active=hol).A
    np.testing.assert_allclose(
        A_h, _fd(lambda x: m.constraint_terms(t, x, qd, active=hol).phi, q), atol=FD_TOL
    )
    # velocity residual = dφ/dt along (qd, 1) for the position-level rows
    def phi_along(s):
        return m.constraint_terms(t + s, q + s * qd, qd, active=hol).phi

    vel_fd = (phi_along(FD_STEP) - phi_along(-FD_STEP)) / (2 * FD_STEP)
    np.testing.assert_allclose(m.constraint_terms(t, q, qd, active=hol).velocity, vel_fd, atol=FD_TOL)
    # γ = d(A qd + φ_t)/dt at fixed qd (qdd = 0), all rows
    def vel_along(s):
        return m.constraint_terms(t + s, q + s * qd, qd, active=allc).velocity

    gamma_fd = (vel_along(FD_STEP) - vel_along(-FD_STEP)) / (2 * FD_STEP)
    np.testing.assert_allclose(ct.gamma, gamma_fd, atol=FD_TOL)
    Ad = m.constraint_jacobian_dot(t, q, qd, active=allc)
    Ad_fd = (
        m.constraint_jacobian(t + FD_STEP, q + FD_STEP * qd, allc)
        - m.constraint_jacobian(t - FD_STEP, q - FD_STEP * qd, allc)
    ) / (2 * FD_STEP)
    np.testing.assert_allclose(Ad, Ad_fd, atol=FD_TOL)
    np.testing.assert_array_equal(ct.holonomic, [True, True, True, False, True])
    # closed forms: drive φ_tt term and the nonholonomic row
    np.testing.assert_allclose(ct.phi[2], q[0] - 0.1 * np.sin(3 * t))
    np.testing.assert_allclose(ct.gamma[2], 0.9 * np.sin(3 * t))
    np.testing.assert_allclose(ct.A[3], [np.cos(q[1]), 0, 0, q[0]])
    np.testing.assert_allclose(ct.gamma[3], -np.sin(q[1]) * qd[1] * qd[0] + qd[0] * qd[3])


@pytest.fixture(scope="module")
def double_pendulum() -> SymbolicModel:
    import sympy as sp
    a, b = sp.symbols("a b")
    ad, bd = sp.symbols("ad bd")
    m1, m2, l1, l2, g = sp.symbols("m1 m2 l1 l2 g")
    x1, y1 = l1 * sp.sin(a), -l1 * sp.cos(a)
    x2, y2 = x1 + l2 * sp.sin(b), y1 - l2 * sp.cos(b)
    v = lambda e: sp.diff(e, a) * ad + sp.diff(e, b) * bd  # noqa: E731
    T = m1 * (v(x1) ** 2 + v(y1) ** 2) / 2 + m2 * (v(x2) ** 2 + v(y2) ** 2) / 2
    V = g * (m1 * y1 + m2 * y2)
    return SymbolicModel.from_energy(
        "dp", q=[a, b], qd=[ad, bd], T=T, V=V,
        params={m1: 1.0, m2: 2.0, l1: 0.5, l2: 0.8, g: 9.81},
    )


def test_christoffel_and_gradient(double_pendulum: SymbolicModel) -> None:
    m = double_pendulum
    rng = np.random.default_rng(1)
    q, qd = rng.normal(size=(2, 2))
    C = m.coriolis_matrix(q, qd)
    Md = (m.mass_matrix(q + FD_STEP * qd) - m.mass_matrix(q - FD_STEP * qd)) / (2 * FD_STEP)
    S = Md - 2 * C
    np.testing.assert_allclose(S + S.T, 0.0, atol=FD_TOL)
    grad = _fd(lambda x: np.atleast_1d(qd @ m.mass_matrix(x) @ qd), q)[0]
    np.testing.assert_allclose(C @ qd, Md @ qd - 0.5 * grad, atol=FD_TOL)
    fg_fd = -_fd(lambda x: np.atleast_1d(m.potential_energy(x)), q)[0]
    np.testing.assert_allclose(m.conservative_force(q), fg_fd, atol=FD_TOL)
    # closed form of the double pendulum: M12 = m2 l1 l2 cos(a − b)
    np.testing.assert_allclose(m.mass_matrix(q)[0, 1], 2.0 * 0.5 * 0.8 * np.cos(q[0] - q[1]))


def test_replace_params_without_recompiling(double_pendulum: SymbolicModel) -> None:
    import sympy as sp
    m = double_pendulum
    q = np.array([0.3, -0.2])
    m2 = m.replace(params={"m2": 4.0})
    assert m2.compiled is m.compiled  # no re-derivation, no re-lambdify
    assert m2.params["m2"] == 4.0 and m.params["m2"] == 2.0
    np.testing.assert_allclose(m2.mass_matrix(q)[1, 1], 4.0 * 0.8**2)
    sym = sp.Symbol("l2")
    m3 = m.replace(params={sym: 1.0})
    np.testing.assert_allclose(m3.mass_matrix(q)[1, 1], 2.0 * 1.0)
    with pytest.raises(UnknownNameError, match="unknown parameter 'mass'"):
        m.replace(params={"mass": 1.0})
    with pytest.raises(InputError, match="unknown field"):
        m.replace(colour="red")


def test_from_mass_matrix_agrees_with_from_energy(double_pendulum: SymbolicModel) -> None:
    import sympy as sp
    a, b = sp.symbols("a b")
    m1, m2, l1, l2, g = sp.symbols("m1 m2 l1 l2 g")
    M = sp.Matrix(
        [
            [(m1 + m2) * l1**2, m2 * l1 * l2 * sp.cos(a - b)],
            [m2 * l1 * l2 * sp.cos(a - b), m2 * l2**2],
        ]
    )
    V = -g * ((m1 + m2) * l1 * sp.cos(a) + m2 * l2 * sp.cos(b))
    mm = SymbolicModel.from_mass_matrix(
        "dp2", q=[a, b], M=M, V=V, params={"m1": 1.0, "m2": 2.0, "l1": 0.5, "l2": 0.8, "g": 9.81}
    )
    rng = np.random.default_rng(2)
    for _ in range(3):
        q, qd = rng.normal(size=(2, 2))
        e = double_pendulum
        np.testing.assert_allclose(mm.mass_matrix(q), e.mass_matrix(q), atol=1e-12)
        np.testing.assert_allclose(mm.coriolis_force(q, qd), e.coriolis_force(q, qd), atol=1e-12)
        np.testing.assert_allclose(mm.conservative_force(q), e.conservative_force(q), atol=1e-12)
        assert mm.energy(q, qd) == pytest.approx(e.energy(q, qd), abs=1e-12)


def test_bad_input() -> None:
    import sympy as sp
    x, xd, k = sp.symbols("x xd k")
    with pytest.raises(ModelError, match="homogeneous quadratic"):
        SymbolicModel.from_energy("bad", q=[x], qd=[xd], T=xd**2 / 2 + xd, V=0)
    with pytest.raises(ModelError, match="homogeneous quadratic"):
        SymbolicModel.from_energy("bad", q=[x], qd=[xd], T=xd**4, V=0)
    with pytest.raises(ModelError, match=r"symbol\(s\) \['k'\]"):
        SymbolicModel.from_energy("bad", q=[x], qd=[xd], T=xd**2 / 2, V=k * x**2)
    with pytest.raises(ModelError, match="symmetric"):
        y = sp.Symbol("y")
        SymbolicModel.from_mass_matrix("bad", q=[x, y], M=[[1, x], [0, 1]], V=0)
    with pytest.raises(ModelError, match="duplicate constraint"):
        c = SymbolicConstraint.holonomic("c", x)
        SymbolicModel.from_energy("bad", q=[x], qd=[xd], T=xd**2 / 2, V=0, constraints=[c, c])
    with pytest.raises(ModelError, match="actuator_names"):
        SymbolicModel.from_energy("bad", q=[x], qd=[xd], T=xd**2 / 2, V=0, B=[1])
    m = SymbolicModel.from_energy(
        "ok", q=[x], qd=[xd], T=xd**2 / 2, V=k * x**2 / 2, params={k: 2.0}
    )
    with pytest.raises(UnknownNameError):
        m.constraint_terms(0.0, [0.0], [0.0], active=["nope"])
    assert m.constraint_terms(0.0, [0.0], [0.0]).A.shape == (0, 1)


def test_missing_sympy_names_the_extra(monkeypatch: pytest.MonkeyPatch) -> None:
    import sympy as sp
    x, xd = sp.symbols("x xd")
    monkeypatch.setitem(sys.modules, "sympy", None)  # makes `import sympy` fail
    with pytest.raises(MissingDependencyError, match=r"nonmin\[sympy\]"):
        SymbolicModel.from_energy("p", q=[x], qd=[xd], T=xd**2 / 2, V=0)


def test_pickle_round_trip(slider_pendulum: SymbolicModel) -> None:
    """Models travel to worker processes: the compiled functions are rebuilt on unpickling."""
    import pickle

    m = slider_pendulum.replace(params={"m": 0.7})
    m2 = pickle.loads(pickle.dumps(m))
    rng = np.random.default_rng(5)
    q, qd = rng.normal(size=(2, 4))
    np.testing.assert_array_equal(m2.mass_matrix(q), m.mass_matrix(q))
    a = m.constraint_terms(0.2, q, qd, active=m.constraint_names)
    b = m2.constraint_terms(0.2, q, qd, active=m.constraint_names)
    np.testing.assert_array_equal(a.A, b.A)
    np.testing.assert_array_equal(a.gamma, b.gamma)
    assert m2.params == m.params
