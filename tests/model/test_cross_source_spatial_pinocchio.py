"""A spatial 3-link chain with skewed revolute axes and general inertias: the spatial
(unit-quaternion, absolute-coordinate) model agrees with Pinocchio's reduced-coordinate
articulated-body algorithm in joint accelerations (with joint torques through B) and in
kinetic and potential energy."""

from __future__ import annotations

import numpy as np
import pytest

from nonmin.core import forward_dynamics
from nonmin.model.spatial import (
    G_matrix,
    SpatialBuilder,
    quaternion_from_rotation_matrix,
    rotation_matrix,
)

pin = pytest.importorskip("pinocchio")

AGREE = 1e-10


def _pinocchio_chain(rng: np.random.Generator):
    model = pin.Model()
    joints = [pin.JointModelRX(), pin.JointModelRY(), pin.JointModelRZ()]
    offsets = [np.zeros(3), np.array([0.1, 0.0, -0.8]), np.array([0.0, 0.3, -0.6])]
    links = []
    parent = 0
    for i in range(3):
        jid = model.addJoint(parent, joints[i], pin.SE3(np.eye(3), offsets[i]), f"j{i}")
        lever = rng.normal(size=3) * 0.3
        Qr = np.linalg.qr(rng.normal(size=(3, 3)))[0]
        inertia = Qr @ np.diag(rng.uniform(0.05, 0.1, 3)) @ Qr.T
        mass = 1.0 + i
        model.appendBodyToJoint(jid, pin.Inertia(mass, lever, inertia), pin.SE3.Identity())
        links.append((jid, mass, lever, inertia))
        parent = jid
    return model, links


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_chain_spatial_vs_pinocchio(seed: int) -> None:
    rng = np.random.default_rng(seed)
    model, links = _pinocchio_chain(rng)
    data = model.createData()
    q = rng.normal(size=3)
    v = rng.normal(size=3) * 2.0
    pin.forwardKinematics(model, data, q, v)
    tau = rng.normal(size=3)
    ddq = pin.aba(model, data, q, v, tau)
    T = pin.computeKineticEnergy(model, data, q, v)
    V = pin.computePotentialEnergy(model, data, q)

    # the same chain, posed at q, in the spatial source
    b = SpatialBuilder("chain", gravity=model.gravity.linear)
    qd = []
    for i, (jid, mass, lever, inertia) in enumerate(links):
        pose = data.oMi[jid]
        R = pose.rotation
        e = quaternion_from_rotation_matrix(R)
        b.add_body(f"b{i}", mass=mass, inertia=inertia, position=pose.act(lever), quaternion=e)
        w, vo = data.v[jid].angular, data.v[jid].linear  # body-frame twist at the joint origin
        qd += [*(R @ (vo + np.cross(w, lever))), *(0.5 * G_matrix(e).T @ w)]
    axes = []
    for i, (jid, *_) in enumerate(links):
        pose = data.oMi[jid]
        u = pose.rotation @ np.eye(3)[i]
        axes.append(u)
        parent = "ground" if i == 0 else f"b{i - 1}"
        b.add_revolute(f"j{i}", parent, f"b{i}", point=pose.translation, axis=u)
        b.add_actuator(f"tau{i}", f"j{i}")
    sm = b.build()
    qs = sm.reference_configuration()
    qds = np.array(qd)
    ct = sm.constraint_terms(0.0, qs, qds)
    np.testing.assert_allclose(ct.phi, 0.0, atol=1e-13)
    np.testing.assert_allclose(ct.velocity, 0.0, atol=1e-12)
    assert sm.kinetic_energy(qs, qds) == pytest.approx(T, abs=AGREE)
    assert sm.potential_energy(qs) == pytest.approx(V, abs=AGREE)

    ev = sm.evaluate(0.0, qs, qds)
    qdd = forward_dynamics(ev.M, ev.h, ev.constraints.A, ev.constraints.gamma, ev.B @ tau)
    # joint accelerations from the absolute ones: θ̈_i = u_i·(ω̇_i − ω̇_{i−1}) (world frame)
    prev = np.zeros(3)
    theta_dd = []
    for i, u in enumerate(axes):
        e = qs[7 * i + 3 : 7 * i + 7]
        wdot = rotation_matrix(e) @ (2.0 * G_matrix(e) @ qdd[7 * i + 3 : 7 * i + 7])
        theta_dd.append(u @ (wdot - prev))
        prev = wdot
    np.testing.assert_allclose(theta_dd, ddq, atol=AGREE)
