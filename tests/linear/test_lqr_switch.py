"""LQR through a switch of the active set inside one run: a pin released (below) and a contact
closing (``test_lqr_redesigns_when_a_contact_closes_inside_a_run``, the 4-dof arm against
Pinocchio-derived hand designs).

A pole stands upright on a cart pushed along a rail by one force; a weld ``lock`` holds the
pole to the cart. The run starts locked with the cart 0.3 m off target (2 tangent states:
the pair moves as one body), and an event releases the lock at t = 1.5 s: from then on the
pole is a free inverted pendulum on the cart (4 tangent states), kicked by the cart's
acceleration. The one ``LQR`` controller meets the new active set at its first call after the
release, re-linearizes there and re-solves the Riccati equation; the run must be stable on both
sides of the switch.

The designs are checked against designs done by hand on each topology, from the textbook
equations in the cart position x and the pole's lean φ from upright (pole of mass m,
half-length l, centroidal inertia I; cart mass M):

* locked:  (M + m) ẍ = u;
* free:    (M + m) ẍ − m l φ̈ = u,   −m l ẍ + (I + m l²) φ̈ = m g l φ;

mapped to nonmin's tangent coordinates by δq = J (δx, δφ) (J the columns ∂q/∂x, ∂q/∂φ), the
weights projected the same way (Jᵀ W J); the Riccati gains must agree to 1e-9.
"""

import numpy as np
import pytest
import scipy.linalg

import nonmin
from nonmin.linear import LQR
from nonmin.model.planar import PlanarBuilder
from nonmin.sim import Deactivate, Event

M_CART, M_POLE, L_POLE, G = 1.0, 0.3, 0.8, 9.81
T_RELEASE = 1.5
WQ, WV, RU = 5.0, 0.5, 0.1


def _model():
    b = PlanarBuilder("cart_pole_lock", gravity=(0.0, -G))
    b.body("cart", mass=M_CART, inertia=0.05, points={"hinge": (0.0, 0.0)})
    b.body(
        "pole", mass=M_POLE, inertia=M_POLE * L_POLE**2 / 12, points={"foot": (-L_POLE / 2, 0.0)}
    )
    b.prismatic("rail", ("ground", (0.0, 0.0)), ("cart", (0.0, 0.0)), axis=(1.0, 0.0))
    b.revolute("hinge", "hinge", "foot")
    b.weld(
        "lock", ("cart", (0.0, 0.0)), ("pole", (-L_POLE / 2, 0.0)), angle=np.pi / 2, active=False
    )
    b.actuator("push", "rail")
    return b.build()


def _hand_gain(design, locked):
    """The Riccati gain of the hand-derived model, in nonmin's tangent coordinates."""
    l, m, M = L_POLE / 2, M_POLE, M_CART
    I = m * L_POLE**2 / 12
    jx = np.array([1.0, 0.0, 0.0, 1.0, 0.0, 0.0])  # ∂q/∂x
    jphi = np.array([0.0, 0.0, 0.0, -l, 0.0, 1.0])  # ∂q/∂φ (COM at x − l sin φ, l cos φ)
    if locked:
        J = jx[:, None]
        Mh, Kh, Bh = np.array([[M + m]]), np.zeros((1, 1)), np.array([1.0])
    else:
        J = np.column_stack([jx, jphi])
        Mh = np.array([[M + m, -m * l], [-m * l, I + m * l * l]])
        Kh = np.array([[0.0, 0.0], [0.0, m * G * l]])  # generalized force of gravity ∂/∂φ
        Bh = np.array([1.0, 0.0])
    k = J.shape[1]
    A = np.block([[np.zeros((k, k)), np.eye(k)], [np.linalg.solve(Mh, Kh), np.zeros((k, k))]])
    B = np.concatenate([np.zeros(k), np.linalg.solve(Mh, Bh)])[:, None]
    W = scipy.linalg.block_diag(WQ * J.T @ J, WV * J.T @ J)
    X = scipy.linalg.solve_continuous_are(A, B, W, np.array([[RU]]))
    K_hand = np.linalg.solve([[RU]], B.T @ X)  # u = −K_hand (δx, δφ, δẋ, δφ̇)
    sys = design.system
    T = scipy.linalg.block_diag(sys.Zq.T @ J, sys.Zv.T @ J)  # x_nonmin = T x_hand
    return K_hand @ np.linalg.inv(T)


def test_lqr_redesigns_at_a_release_inside_a_run():
    model = _model()
    q_star = np.array([0.0, 0.0, 0.0, 0.0, L_POLE / 2, np.pi / 2])
    lqr = LQR(model, q_star, weight_q=WQ, weight_qd=WV, weight_u=RU)
    free = model.resolve_active(None)
    locked = free | {"lock"}

    # the designs equal the hand designs on each topology
    d_locked, d_free = lqr.design(locked), lqr.design(free)
    assert d_locked.system.A.shape == (2, 2) and d_free.system.A.shape == (4, 4)
    for d, is_locked in ((d_locked, True), (d_free, False)):
        K_ref = _hand_gain(d, is_locked)
        assert np.allclose(d.K, K_ref, rtol=1e-9, atol=1e-9 * np.abs(K_ref).max())
        assert np.allclose(d.u_ff, 0.0, atol=1e-12)
        assert np.all(d.closed_loop_eigenvalues.real < 0)
    assert not nonmin.modes(model, q_star).stable  # the free pole alone falls

    # one run through the release: the controller is a fresh LQR (designs made during the run)
    ctl = LQR(model, q_star, weight_q=WQ, weight_qd=WV, weight_u=RU)
    q0 = q_star + np.array([0.3, 0.0, 0.0, 0.3, 0.0, 0.0])
    release = Event(lambda t, q, qd, fc: t - T_RELEASE, direction=1, transition=Deactivate("lock"),
                    name="release")  # fmt: skip
    traj = nonmin.simulate(model, (0.0, 8.0), q0, active=locked, controller=ctl, events=[release],
                           method="rk4", dt=2e-3)  # fmt: skip
    assert [e.name for e in traj.events] == ["release"]
    assert abs(traj.events[0].t - T_RELEASE) <= 1e-9
    assert set(ctl._cache) == {locked, free}  # re-linearized at the switch, once per set
    t = traj.t
    err = np.abs(traj.q - q_star).max(axis=1)
    lean = np.abs(traj.q[:, 5] - np.pi / 2)
    before, after = t < T_RELEASE, t > T_RELEASE
    assert lean[before].max() <= 1e-9  # locked: the pole stays upright on the cart
    assert err[before][-1] < 0.5 * err[0]  # converging before the switch
    assert lean[after].max() > 1e-3  # the release kicks the pole...
    assert err[-1] < 1e-3 * err[0]  # ...and the free design balances it and brings the cart home
    # after the switch the controller's force is the free design's u* − K x
    x = d_free.system.from_dependent(traj.q[-1], traj.qd[-1])
    assert np.allclose(ctl(t[-1], traj.q[-1], traj.qd[-1], active=free), d_free.u_ff - d_free.K @ x)
    # the locked design alone cannot hold the free pole (it ignores the lean): unstable
    A, B = d_free.system.A, d_free.system.B
    K_lock_on_free = np.zeros((1, 4))
    Zl, Zf = d_locked.system.Zq, d_free.system.Zq
    K_lock_on_free[:, :2] = d_locked.K[:, :1] @ (Zl.T @ Zf)
    K_lock_on_free[:, 2:] = d_locked.K[:, 1:] @ (Zl.T @ Zf)
    assert np.linalg.eigvals(A - B @ K_lock_on_free).real.max() > 0


def test_lqr_redesigns_when_a_contact_closes_inside_a_run():
    """The 4-dof arm of ``serial_arm`` (all joints actuated) is regulated to a configuration
    where its end effector rests on the ground (``ee_contact``, gap 0). It starts 1.5 cm above
    and moving down: the free design (8 states) drives it, the contact closes by a plastic
    impact, the one LQR re-designs for the contact set (6 states) and holds the arm there.

    Hand designs from Pinocchio (nothing of nonmin's derivative code): free, M δq̈ = −G δq + δu
    (G = ∂g/∂q, ``computeGeneralizedGravityDerivatives``; tangent basis I); in contact, on
    y with δq = Z y (Z an orthonormal basis of N(a), a = ∂z_ee/∂q from the frame Jacobian):
    ZᵀMZ ÿ = −Zᵀ(G − λ H)Z y + Zᵀ δu, with the contact force λ = (a aᵀ)⁻¹ a g at the
    feed-forward u* = Z Zᵀ g and H = ∂aᵀ/∂q by a central difference of Pinocchio's Jacobian."""
    pin = pytest.importorskip("pinocchio")
    from nonmin.model.robots import serial_arm

    model, state = serial_arm()
    q_star = state.q.copy()
    free = model.resolve_active(None)
    contact = free | {"ee_contact"}
    wq, wv, ru = 10.0, 1.0, 0.1
    ctl = LQR(model, q_star, weight_q=wq, weight_qd=wv, weight_u=ru)

    pm = model.pinocchio_model
    pd = pm.createData()
    fid = pm.getFrameId("ee")
    n = pm.nv

    def a_row(q):
        pin.computeJointJacobians(pm, pd, q)
        pin.updateFramePlacements(pm, pd)
        J = pin.getFrameJacobian(pm, pd, fid, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)
        return np.array(J[2])

    M = pin.crba(pm, pd, q_star)
    M = np.triu(M) + np.triu(M, 1).T
    g = np.array(pin.computeGeneralizedGravity(pm, pd, q_star))
    G = np.array(pin.computeGeneralizedGravityDerivatives(pm, pd, q_star))

    def hand_gain(M_r, K_r, B_r, k):
        A = np.block(
            [[np.zeros((k, k)), np.eye(k)], [-np.linalg.solve(M_r, K_r), np.zeros((k, k))]]
        )
        B = np.vstack([np.zeros((k, n)), np.linalg.solve(M_r, B_r)])
        W = scipy.linalg.block_diag(wq * np.eye(k), wv * np.eye(k))
        X = scipy.linalg.solve_continuous_are(A, B, W, ru * np.eye(n))
        return np.linalg.solve(ru * np.eye(n), B.T @ X)

    d_free = ctl.design(free)
    assert np.allclose(d_free.system.Zq, np.eye(n))
    K_free = hand_gain(M, G, np.eye(n), n)
    assert np.allclose(d_free.K, K_free, rtol=1e-8, atol=1e-8 * np.abs(K_free).max())
    assert np.allclose(d_free.u_ff, g, atol=1e-10)

    a = a_row(q_star)
    Z = np.linalg.svd(a[None, :])[2][1:].T
    lam = float(a @ g / (a @ a))
    h = 1e-6
    H = np.array([(a_row(q_star + h * e) - a_row(q_star - h * e)) / (2 * h) for e in np.eye(n)])
    H = 0.5 * (H + H.T)
    K_hand_y = hand_gain(Z.T @ M @ Z, Z.T @ (G - lam * H) @ Z, Z.T, n - 1)
    d_con = ctl.design(contact)
    T = Z.T @ d_con.system.Zq  # y = T z
    K_con = K_hand_y @ scipy.linalg.block_diag(T, T)
    assert np.allclose(d_con.K, K_con, rtol=1e-6, atol=1e-6 * np.abs(K_con).max())
    assert np.allclose(d_con.u_ff, Z @ (Z.T @ g), atol=1e-10)

    # the run: 1.5 cm above, moving down; a fresh controller designs as the sets come
    ctl = LQR(model, q_star, weight_q=wq, weight_qd=wv, weight_u=ru)
    up = a / np.linalg.norm(a)
    traj = nonmin.simulate(model, (0.0, 3.0), q_star + 0.05 * up, -1.0 * up, controller=ctl,
                           method="rk4", dt=1e-3)  # fmt: skip
    assert [e.name for e in traj.events] == ["impact:ee_contact"]
    t_hit = traj.events[0].t
    assert set(ctl._cache) == {free, contact}
    err = np.abs(traj.q - q_star).max(axis=1)
    assert err[-1] < 1e-4 * err[0]
    i_end = traj.constraint_names.index("ee_contact")
    assert traj.active_mask[-1, i_end] and traj.active_mask[traj.t > t_hit][:, i_end].all()
