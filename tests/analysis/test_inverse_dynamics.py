"""nonmin.inverse_dynamics on closed chains against independent KKT / null-space solves.

References written here, not taken from nonmin: the KKT system of the constrained equations of
motion with the inputs as unknowns (``[Aᵀ  B] [λ; u] = M q̈ − h``) and the null-space form
``Zᵀ B u = Zᵀ (M q̈ − h)`` with an orthonormal basis Z of N(A) from SciPy. Motions come from
the forward dynamics with a known input, so the exact answer is known.
"""

from __future__ import annotations

import numpy as np
import pytest
from closed_chains import admissible_velocity, five_bar, three_rrr
from scipy.linalg import null_space

import nonmin
from nonmin.errors import InputError, ShapeError

TOL = 1e-9


def _terms(model, q, qd):
    mt = model.evaluate(0.0, q, qd)
    return mt.M, mt.h + mt.f_passive, mt.constraints.A, mt.constraints.gamma, mt.B


def _kkt_inputs(M, g, A, B, qdd):
    """u and λ from [Aᵀ B][λ; u] = M q̈ − g (least squares; unique when the stack has full
    column rank)."""
    K = np.hstack([A.T, B])
    sol, *_ = np.linalg.lstsq(K, M @ qdd - g, rcond=None)
    return sol[A.shape[0] :], A.T @ sol[: A.shape[0]]


def _nullspace_min_norm(M, g, A, B, qdd, W=None):
    Z = null_space(A)
    if W is None:
        return np.linalg.pinv(Z.T @ B) @ (Z.T @ (M @ qdd - g))
    Li = np.linalg.inv(np.linalg.cholesky(W)).T
    return Li @ np.linalg.pinv(Z.T @ B @ Li) @ (Z.T @ (M @ qdd - g))


@pytest.mark.parametrize("build", [five_bar, three_rrr], ids=["5-bar", "3-RRR"])
def test_fully_actuated_closed_chain_recovers_the_input(build) -> None:
    model, state = build()
    rng = np.random.default_rng(1)
    q = state.q
    for _ in range(4):
        qd = admissible_velocity(model, q, rng)
        u0 = rng.normal(size=model.k)
        M, g, A, _, B = _terms(model, q, qd)
        qdd = model.forward_dynamics(q, qd, f=B @ u0).qdd
        res = nonmin.inverse_dynamics(model, q, qd, qdd)
        assert res.ok and res.fully_actuated and res.redundancy == 0, res.message
        assert res.dof == model.k
        np.testing.assert_allclose(res.u, u0, atol=TOL * max(1.0, np.abs(u0).max()))
        u_kkt, fc_kkt = _kkt_inputs(M, g, A, B, qdd)
        np.testing.assert_allclose(res.u, u_kkt, atol=TOL)
        np.testing.assert_allclose(res.f_c, fc_kkt, atol=TOL * max(1.0, np.abs(fc_kkt).max()))
        # the computed u reproduces q̈ and f_c in the forward dynamics
        fwd = model.forward_dynamics(q, qd, f=B @ res.u)
        np.testing.assert_allclose(fwd.qdd, qdd, atol=TOL * max(1.0, np.abs(qdd).max()))
        np.testing.assert_allclose(fwd.f_c, res.f_c, atol=TOL * max(1.0, np.abs(res.f_c).max()))


def test_redundantly_actuated_3rrr_min_norm_and_weighted() -> None:
    model, state = three_rrr(redundant=True)
    rng = np.random.default_rng(2)
    q = state.q
    qd = admissible_velocity(model, q, rng)
    M, g, A, _, B = _terms(model, q, qd)
    assert B.shape[1] == 6
    u0 = rng.normal(size=6)
    qdd = model.forward_dynamics(q, qd, f=B @ u0).qdd
    res = nonmin.inverse_dynamics(model, q, qd, qdd)
    assert res.ok and res.fully_actuated and res.redundancy == 3
    np.testing.assert_allclose(res.u, _nullspace_min_norm(M, g, A, B, qdd), atol=TOL)
    assert np.linalg.norm(res.u) < np.linalg.norm(u0)  # minimum norm among the family
    # the paper's Γ = (PB)⁺ directly
    P, _ = nonmin.core.nullspace_projector(A)
    _, Gamma = nonmin.core.actuation_projectors(B, P)
    np.testing.assert_allclose(res.u, Gamma @ P @ (M @ qdd - g), atol=TOL)
    # weighted: the knees cost 100× more
    W = np.diag([1.0, 1.0, 1.0, 100.0, 100.0, 100.0])
    # columns of B are ordered base0, knee0, base1, knee1, ...
    order = list(model.actuator_names)
    w = np.array([100.0 if a.startswith("knee") else 1.0 for a in order])
    resw = nonmin.inverse_dynamics(model, q, qd, qdd, weight=w)
    np.testing.assert_allclose(resw.u, _nullspace_min_norm(M, g, A, B, qdd, np.diag(w)), atol=TOL)
    assert resw.ok
    knees = np.array([a.startswith("knee") for a in order])
    assert np.abs(resw.u[knees]).sum() < np.abs(res.u[knees]).sum()
    for r in (res, resw):
        np.testing.assert_allclose(model.forward_dynamics(q, qd, f=B @ r.u).qdd, qdd, atol=1e-8)
    assert W.shape == (6, 6)


def test_under_actuated_motion_achievable_or_not() -> None:
    """5-bar with one motor: only motions in a 1-D family of accelerations are achievable."""
    model, state = five_bar(actuated=("act1",))
    rng = np.random.default_rng(3)
    q = state.q
    qd = admissible_velocity(model, q, rng)
    A, B = _terms(model, q, qd)[2::2]
    qdd_ok = model.forward_dynamics(q, qd, f=B @ [0.7]).qdd
    res = nonmin.inverse_dynamics(model, q, qd, qdd_ok)
    assert res.ok and not res.fully_actuated and res.rank_pb == 1 and res.dof == 2
    np.testing.assert_allclose(res.u, [0.7], atol=TOL)
    # another consistent motion (with a torque at O2 that is not available)
    model2, _ = five_bar(actuated=("act1", "act4"))
    B2 = model2.input_matrix(q)
    qdd_bad = model.forward_dynamics(q, qd, f=B2 @ [0.7, 0.5]).qdd
    bad = nonmin.inverse_dynamics(model, q, qd, qdd_bad)
    assert bad.consistent and not bad.achievable and not bad.ok
    assert "not achievable" in bad.message and "rank(PB) = 1" in bad.message
    # least-squares u: the unproduced force is orthogonal to R(PB)
    P, _ = nonmin.core.nullspace_projector(A)
    assert abs((P @ B)[:, 0] @ bad.f_unproduced) < 1e-9 * np.linalg.norm(bad.f_unproduced)
    # an explicit actuation matrix overrides the model's
    ok2 = nonmin.inverse_dynamics(model, q, qd, qdd_bad, actuation=B2)
    assert ok2.ok
    np.testing.assert_allclose(ok2.u, [0.7, 0.5], atol=TOL)


def test_inconsistent_acceleration_is_reported() -> None:
    model, state = five_bar()
    rng = np.random.default_rng(4)
    q = state.q
    qd = admissible_velocity(model, q, rng)
    qdd = model.forward_dynamics(q, qd).qdd + 0.1 * rng.normal(size=model.n)
    res = nonmin.inverse_dynamics(model, q, qd, qdd)
    assert not res.consistent and not res.ok
    assert "not consistent" in res.message
    assert np.linalg.norm(res.constraint_residual) > 1e-3


def test_bad_input_is_typed() -> None:
    model, state = five_bar()
    z = np.zeros(model.n)
    with pytest.raises(ShapeError, match="qdd"):
        nonmin.inverse_dynamics(model, state.q, z, z[:3])
    with pytest.raises(ShapeError, match="actuation"):
        nonmin.inverse_dynamics(model, state.q, z, z, actuation=np.zeros((3, 2)))
    with pytest.raises(InputError, match="positive definite"):
        nonmin.inverse_dynamics(model, state.q, z, z, weight=[1.0, -1.0])


def test_a_trajectory_of_states_is_stacked() -> None:
    model, state = three_rrr()
    rng = np.random.default_rng(6)
    q = np.tile(state.q, (4, 1))
    qd = np.array([admissible_velocity(model, state.q, rng) for _ in range(4)])
    u0 = rng.normal(size=(4, model.k))
    B = model.input_matrix(state.q)
    qdd = np.array(
        [model.forward_dynamics(state.q, v, f=B @ u).qdd for v, u in zip(qd, u0, strict=True)]
    )
    qdd[2] += 0.1  # one inconsistent state
    res = nonmin.inverse_dynamics(model, q, qd, qdd, t=np.arange(4.0))
    assert res.u.shape == (4, model.k) and res.f_c.shape == (4, model.n)
    np.testing.assert_array_equal(res.ok, [True, True, False, True])
    assert res.message.startswith("state 2: qdd is not consistent")
    for i in (0, 1, 3):
        one = nonmin.inverse_dynamics(model, q[i], qd[i], qdd[i], t=float(i))
        np.testing.assert_array_equal(res.u[i], one.u)
        np.testing.assert_allclose(res.u[i], u0[i], atol=TOL)
    with pytest.raises(ShapeError, match="qdd"):
        nonmin.inverse_dynamics(model, q, qd, qdd[:2])
