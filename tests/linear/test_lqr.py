"""The LQR regulator on the tangent space: an inverted four-bar on a cart is stabilized, and
the design of a pendulum equals the classical LQR of its reduced model (closed form of the
Riccati equation for a double integrator with stiffness)."""

import sys
from pathlib import Path

import numpy as np
import pytest
import scipy.linalg

import nonmin
from nonmin.linear import LQR
from nonmin.model.planar import PlanarBuilder

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "examples"))


def test_inverted_four_bar_on_a_cart_is_stabilized():
    from lqr_cart_four_bar import cart_four_bar, upright_guess

    model = cart_four_bar()
    eq = nonmin.equilibrium(model, upright_guess(model))
    q_star = eq.q.copy()
    q_star[0::3] -= eq.q[0]
    m = nonmin.modes(model, q_star)
    assert not m.stable  # upright: divergent
    lqr = LQR(model, q_star, weight_q=10.0, weight_qd=1.0, weight_u=0.1)
    d = lqr.design()
    assert d.system.A.shape == (4, 4)
    assert np.all(d.closed_loop_eigenvalues.real < 0)
    assert lqr.design() is d  # designed once per active set
    q0 = upright_guess(model, lean=0.15)
    traj = nonmin.simulate(model, (0.0, 3.0), q0, controller=lqr, method="rk4", dt=5e-3)
    err = np.abs(traj.q - q_star).max(axis=1)
    assert err[0] > 0.1 and err[-1] < 5e-3  # slowest closed-loop pole −1.8 /s
    # the controller's output is u* − K x of the design
    x = d.system.from_dependent(traj.q[-1], traj.qd[-1])
    assert np.allclose(lqr(0.0, traj.q[-1], traj.qd[-1]), d.u_ff - d.K @ x)


def test_pendulum_lqr_equals_the_reduced_model_lqr():
    """Point pendulum (Cartesian, rod of length L) pushed by a horizontal force at the bob,
    regulated about the inverted position: the reduced model in the tangent coordinate
    z = x (arc length to first order) is z̈ = (g/L) z + u/m, so the gain is the LQR gain of
    (A, B) = ([[0, 1], [g/L, 0]], [[0], [1/m]]) with the projected weights."""
    m_, L, g = 0.7, 1.3, 9.81
    b = PlanarBuilder("pendulum", gravity=(0.0, -g))
    b.point_mass("bob", mass=m_, points=["P"])
    b.rod("rod", ("ground", (0.0, 0.0)), "P", length=L)
    b.force("push", "P", direction=(1.0, 0.0))
    model = b.build()
    q_star = np.array([0.0, L])
    lqr = LQR(
        model, q_star, weight_q=np.diag([4.0, 9.0]), weight_qd=np.diag([0.5, 2.0]), weight_u=0.3
    )
    d = lqr.design()
    s = float(d.system.Zq[0, 0])  # ±1: the tangent basis vector is (±1, 0)
    assert abs(abs(s) - 1.0) <= 1e-12
    A = np.array([[0.0, 1.0], [g / L, 0.0]])
    B = np.array([[0.0], [s / m_]])  # z = s x
    X = scipy.linalg.solve_continuous_are(A, B, np.diag([4.0, 0.5]), np.array([[0.3]]))
    K = np.linalg.solve([[0.3]], B.T @ X)
    assert np.allclose(d.K, K, rtol=1e-10, atol=1e-12)
    assert np.allclose(d.u_ff, 0.0, atol=1e-12)


def test_lqr_rejects_bad_targets():
    mech = nonmin.library.a01_pendulum()
    with pytest.raises(nonmin.errors.InputError, match="no actuators"):
        LQR(mech.model, [0.0, -1.0])


def test_lqr_redesigns_when_the_active_set_changes():
    """A pole on a cart with an optional lock (a weld of pole to cart): 4 tangent states free,
    2 locked; the controller designs once per active set and both loops are stable."""
    b = PlanarBuilder("cart_pole_lock", gravity=(0.0, -9.81))
    b.body("cart", mass=1.0, inertia=0.05, points={"hinge": (0.0, 0.0)})
    b.body("pole", mass=0.3, inertia=0.3 * 0.8**2 / 12, points={"foot": (-0.4, 0.0)})
    b.prismatic("rail", ("ground", (0.0, 0.0)), ("cart", (0.0, 0.0)), axis=(1.0, 0.0))
    b.revolute("hinge", "hinge", "foot")
    b.weld("lock", ("cart", (0.0, 0.0)), ("pole", (-0.4, 0.0)), angle=np.pi / 2, active=False)
    b.actuator("push", "rail")
    model = b.build()
    q_star = np.array([0.0, 0.0, 0.0, 0.0, 0.4, np.pi / 2])
    lqr = LQR(model, q_star, weight_q=5.0, weight_qd=0.5, weight_u=0.1)
    free = model.resolve_active(None)
    locked = free | {"lock"}
    d_free, d_locked = lqr.design(free), lqr.design(locked)
    assert d_free.system.A.shape == (4, 4) and d_locked.system.A.shape == (2, 2)
    assert np.all(d_free.closed_loop_eigenvalues.real < 0) and np.all(d_locked.closed_loop_eigenvalues.real < 0)
    q = q_star + np.array([0.05, 0.0, 0.0, 0.05, 0.0, 0.0])
    u_free = lqr(0.0, q, np.zeros(6), active=free)
    u_locked = lqr(0.0, q, np.zeros(6), active=locked)
    assert np.isfinite(u_free).all() and np.isfinite(u_locked).all() and not np.allclose(u_free, u_locked)
    assert lqr.design(locked) is d_locked
