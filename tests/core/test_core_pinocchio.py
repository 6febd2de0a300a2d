"""Pinocchio convention mapping: ``h = −nle``, ``adot_qd = γ`` (J qdd + γ = 0), ``f_c = Jᵀλ_c``.

Cross-implementation check of nonmin.core against Pinocchio's KKT ``forwardDynamics`` on its
sample manipulator with a point-contact (3-row frame Jacobian) constraint.
"""

from __future__ import annotations

import numpy as np
import pytest
from core_testlib import REF_RTOL, rel

from nonmin.core import forward_dynamics, solve_dynamics

pin = pytest.importorskip("pinocchio")

#: finite-difference check of γ = J̇ v (central difference in q along v)
FD_EPS, FD_RTOL = 1e-6, 1e-7


def _state(seed):
    model = pin.buildSampleModelManipulator()
    data = model.createData()
    rng = np.random.default_rng(seed)
    pin.seed(seed)
    q = pin.randomConfiguration(model)
    v = rng.standard_normal(model.nv)
    tau = rng.standard_normal(model.nv)
    return model, data, q, v, tau


def _jac(model, data, q, fid):
    pin.computeJointJacobians(model, data, q)
    pin.updateFramePlacements(model, data)
    return pin.getFrameJacobian(model, data, fid, pin.LOCAL_WORLD_ALIGNED)[:3].copy()


@pytest.mark.parametrize("seed", range(3))
def test_pinocchio_forward_dynamics_mapping(seed):
    model, data, q, v, tau = _state(seed)
    fid = model.nframes - 1
    J = _jac(model, data, q, fid)
    # γ = J̇ v: classical acceleration of the contact point at zero joint acceleration
    pin.forwardKinematics(model, data, q, v, np.zeros(model.nv))
    gamma = pin.getFrameClassicalAcceleration(model, data, fid, pin.LOCAL_WORLD_ALIGNED).linear
    gamma = np.array(gamma)
    Jp = _jac(model, data, pin.integrate(model, q, FD_EPS * v), fid)
    Jm = _jac(model, data, pin.integrate(model, q, -FD_EPS * v), fid)
    assert rel(gamma, (Jp - Jm) @ v / (2 * FD_EPS)) <= FD_RTOL  # γ = Ȧ qd
    pin.computeAllTerms(model, data, q, v)
    M = np.triu(data.M) + np.triu(data.M, 1).T  # older Pinocchio filled only the upper triangle
    nle = data.nle.copy()
    a = pin.forwardDynamics(model, data, q, v, tau, J, gamma).copy()
    lam = data.lambda_c.copy()
    sol = solve_dynamics(M, -nle, J, gamma, tau)  # h = −nle, adot_qd = γ, f = τ
    assert rel(sol.qdd, a) <= REF_RTOL
    assert rel(sol.f_c, J.T @ lam) <= REF_RTOL
    assert np.linalg.norm(J @ sol.qdd + gamma) <= REF_RTOL * np.linalg.norm(gamma)
    # redundant: the same contact twice (Pinocchio's KKT matrix is singular; nonmin is not)
    J2 = np.vstack([J, J])
    qdd2 = forward_dynamics(M, -nle, J2, np.concatenate([gamma, gamma]), tau)
    assert rel(qdd2, a) <= REF_RTOL
