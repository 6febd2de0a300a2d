"""Robots (TreeProgram on dual numbers) against Pinocchio and a reduced-coordinate model.

* ∂q̈/∂q, ∂q̈/∂v, ∂q̈/∂τ of a UR5 and a Panda whose tool is held at a point (3 closure rows)
  or welded (6 rows) against Pinocchio's analytical ``computeConstraintDynamicsDerivatives``
  (KKT derivatives, Carpentier & Mansard) at several states: fixed base, so q = Pinocchio's
  configuration and q̇ = v.
* The robot four-bar (fourbar.urdf closed by a planar point, 1 DOF) at its hanging
  equilibrium: the eigenvalue of the tangent-space linearization against the reduced model in
  the crank angle θ — M_r = Jᵀ M J and K_r = −d/dθ (Jᵀ g(q(θ))) with q(θ) the closed loop solved
  by Newton and J = ∂q/∂θ from the implicit-function theorem (Pinocchio's M and gravity; the
  stiffness by a central difference of the reduced generalized force, so the reference knows
  nothing of nonmin's derivative code).
"""

import numpy as np
import pytest

import nonmin
from nonmin.linear import dynamics_derivatives

pin = pytest.importorskip("pinocchio")

#: Asked agreement with Pinocchio's analytical derivatives (relative to the largest entry).
PIN_RTOL = 1e-7


def _ur5_point():
    from nonmin.errors import MissingDependencyError
    from nonmin.model.robots import pinocchio_point_constraint, ur5_point_closure

    try:
        model, state = ur5_point_closure()
    except MissingDependencyError as exc:
        pytest.skip(str(exc))
    return model, state.q, pinocchio_point_constraint(model)


def _arm_closure(arm, closure):
    from nonmin.errors import MissingDependencyError
    from nonmin.model.robots import example_robot_closure, pinocchio_frame_constraint

    try:
        model, state = example_robot_closure(arm, closure)
    except MissingDependencyError as exc:
        pytest.skip(str(exc))
    return model, state.q, pinocchio_frame_constraint(model)


@pytest.mark.parametrize(
    ("arm", "closure"), [("ur5", "point"), ("panda", "point"), ("panda", "weld")]
)
def test_arm_closure_derivatives_match_pinocchio(arm, closure):
    """UR5 and Panda (9 coordinates: 7 joints, 2 finger slides) with the tool held by a point
    (3 rows) or a weld (6 rows; Pinocchio's CONTACT_6D rows differ from nonmin's, the
    constrained accelerations and their derivatives do not)."""
    model, q0, cm = _arm_closure(arm, closure)
    pm = model.pinocchio_model
    pd = pm.createData()
    cms = pin.StdVec_RigidConstraintModel()
    cms.append(cm)
    cds = pin.StdVec_RigidConstraintData()
    cds.append(cm.createData())
    pin.initConstraintDynamics(pm, pd, cms, cds)
    prox = pin.ProximalSettings(1e-14, 1e-14, 1)
    rng = np.random.default_rng(7)
    A = model.constraint_jacobian(0.0, q0)
    Z = np.linalg.svd(A)[2][A.shape[0] :].T
    for trial in range(3):
        v = Z @ rng.standard_normal(Z.shape[1])  # admissible velocity
        tau = rng.standard_normal(pm.nv)
        ddq = pin.constraintDynamics(pm, pd, q0, v, tau, cms, cds, prox)
        ddq_dq, ddq_dv, ddq_dtau = (
            np.array(x)
            for x in pin.computeConstraintDynamicsDerivatives(pm, pd, cms, cds, prox)[:3]
        )
        d = dynamics_derivatives(model, q0, v, f=tau)
        assert np.allclose(d.qdd, ddq, rtol=1e-10, atol=1e-10 * (1 + np.abs(ddq).max()))
        for ours, theirs in ((d.dqdd_dq, ddq_dq), (d.dqdd_dqd, ddq_dv), (d.dqdd_df, ddq_dtau)):
            scale = max(1.0, float(np.abs(theirs).max()))
            assert np.abs(ours - theirs).max() <= PIN_RTOL * scale, trial


def test_engine_boundary_checks_name_the_argument():
    """The engine path leaves finiteness to the binding: a NaN still raises NonFiniteError
    naming the argument, a wrong shape ShapeError; lists are accepted."""
    model, q0, _ = _ur5_point()
    d = dynamics_derivatives(model, list(q0), None, f=np.zeros(model.n))
    assert d.dqdd_dq.shape == (6, 6) and d.dqdd_du.shape == (6, model.k)
    assert np.allclose(d.dqdd_du, d.dqdd_df @ model.input_matrix(q0), atol=1e-12)
    for kw, name in (({"qd": np.full(6, np.nan)}, "qd"), ({"f": np.r_[0, 0, np.inf, 0, 0, 0]}, "f")):
        with pytest.raises(nonmin.errors.NonFiniteError, match=name):
            dynamics_derivatives(model, q0, **kw)
    bad = q0.copy()
    bad[1] = np.nan
    with pytest.raises(nonmin.errors.NonFiniteError, match="q must"):
        dynamics_derivatives(model, bad)
    with pytest.raises(nonmin.errors.ShapeError, match="f must"):
        dynamics_derivatives(model, q0, f=np.zeros(5))


def test_ur5_term_tangents_match_central_differences():
    model, q0, _ = _ur5_point()
    rng = np.random.default_rng(3)
    qd = rng.standard_normal(model.n)
    dq, dv = rng.standard_normal(model.n), rng.standard_normal(model.n)
    t = nonmin.linear.term_tangents(model, q0, qd, dq, dv)
    h = 1e-5

    def ev(s):
        return model.evaluate(0.0, q0 + s * dq, qd + s * dv)

    p, m = ev(h), ev(-h)
    for key, fp, fm in (
        ("M", p.M, m.M), ("h", p.h, m.h), ("A", p.constraints.A, m.constraints.A),
        ("gamma", p.constraints.gamma, m.constraints.gamma), ("phi", p.constraints.phi, m.constraints.phi),
    ):  # fmt: skip
        fd = (np.asarray(fp) - np.asarray(fm)) / (2 * h)
        assert np.abs(t["d" + key][0] - fd).max() <= 1e-7 * max(1.0, float(np.abs(fd).max())), key


def _reduced_fourbar_omega(model, q_eq):
    """ω of the reduced 1-DOF model (crank angle) about q_eq: see the module docstring."""
    pm = model.pinocchio_model
    pd = pm.createData()
    ic = 0  # the crank is the first coordinate (actuated joint "crank")

    def close(theta, q):
        q = q.copy()
        q[ic] = theta
        for _ in range(50):
            phi = model.constraint_residual(0.0, q)
            if np.abs(phi).max() < 1e-14:
                break
            A = model.constraint_jacobian(0.0, q)
            dep = [i for i in range(model.n) if i != ic]
            q[dep] -= np.linalg.solve(A[:, dep], phi)
        return q

    def jac(q):
        A = model.constraint_jacobian(0.0, q)
        dep = [i for i in range(model.n) if i != ic]
        J = np.zeros(model.n)
        J[ic] = 1.0
        J[dep] = -np.linalg.solve(A[:, dep], A[:, ic])
        return J

    def g_red(theta):
        q = close(theta, q_eq)
        g = -pin.computeGeneralizedGravity(pm, pd, q)
        return float(jac(q) @ g)

    th = q_eq[ic]
    J = jac(q_eq)
    M = pin.crba(pm, pd, q_eq)
    M = np.triu(M) + np.triu(M, 1).T
    m_r = float(J @ M @ J)
    h = 1e-5
    k_r = -(g_red(th + h) - g_red(th - h)) / (2 * h)
    return np.sqrt(k_r / m_r) if k_r > 0 else -np.sqrt(-k_r / m_r), g_red(th)


def test_robot_fourbar_mode_matches_the_reduced_model():
    from nonmin.model.robots import fourbar

    model, state = fourbar("planar_point")
    eq = nonmin.equilibrium(model, state.q)
    assert eq.converged
    m = nonmin.modes(model, eq.q)
    assert m.frequencies.shape == (1,)
    omega_ref, g_at_eq = _reduced_fourbar_omega(model, eq.q)
    assert abs(g_at_eq) <= 1e-9
    if omega_ref > 0:
        assert abs(m.frequencies[0] - omega_ref) <= 1e-6 * omega_ref
        assert m.stable
    else:  # an unstable equilibrium: a real pair ±|ω|
        assert np.allclose(np.sort(m.eigenvalues.real), [omega_ref, -omega_ref], rtol=1e-6)


@pytest.mark.parametrize(
    ("arm", "closure"), [("ur5", "point"), ("panda", "point"), ("panda", "weld")]
)
def test_analytic_rnea_derivatives_match_dual_path(arm, closure):
    """Trees without quaternions take ∂(M a − g) from the analytic RNEA derivatives
    (rnea_derivatives, engine backend); the NumPy backend takes every term's tangent from the
    dual-number evaluation (evaluate_tangent): the two agree to 1e-10 relative, with inputs,
    configurations off the closure and velocities off the constraint's null space (these arms
    have no joint damping: its ∂/∂q̇ term is the diagonal added in residual_tangents)."""
    model, q0, _ = _arm_closure(arm, closure)
    rng = np.random.default_rng(11)
    for _ in range(2):
        q = q0 + 0.1 * rng.standard_normal(model.n)
        qd = rng.standard_normal(model.n)
        f = rng.standard_normal(model.n)
        u = rng.standard_normal(model.k) if model.k else None
        ours = dynamics_derivatives(model, q, qd, f=f, u=u)
        dual = dynamics_derivatives(model, q, qd, f=f, u=u, backend="numpy")
        for key in ("dqdd_dq", "dqdd_dqd", "dqdd_df", "dfc_dq", "dfc_dqd"):
            a, b = getattr(ours, key), getattr(dual, key)
            assert np.abs(a - b).max() <= 1e-10 * max(1.0, float(np.abs(b).max())), key
