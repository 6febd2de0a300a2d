"""Spatial (unit-quaternion) source: derivatives of every joint type, Christoffel C, energies,
errors."""

from __future__ import annotations

import numpy as np
import pytest

from nonmin.errors import InputError, ModelError, ShapeError, UnknownNameError
from nonmin.model import Model
from nonmin.model.spatial import (
    JOINT_KINDS,
    G_matrix,
    SpatialBuilder,
    SpatialModel,
    quaternion_from_axis_angle,
    quaternion_from_rotation_matrix,
    rotation_matrix,
)
from nonmin.model.spatial._quaternion import E_matrix, H_matrix, point_tensor, skew

#: Central-difference step and the tolerance that its O(h²) + round-off error meets.
FD_STEP = 1e-6
FD_TOL = 2e-8
EXACT_TOL = 1e-12


def _fd_jacobian(f, x, h=FD_STEP):
    return np.array([(f(x + h * e) - f(x - h * e)) / (2 * h) for e in np.eye(x.size)]).T


def _three_bodies(rng: np.random.Generator) -> SpatialBuilder:
    b = SpatialBuilder("three", gravity=(0.3, -9.81, 1.0))
    for i in range(3):
        b.add_body(
            f"b{i}",
            mass=1.0 + i,
            inertia=np.array([[0.10, 0.01, 0.0], [0.01, 0.20, 0.02], [0.0, 0.02, 0.25]]),
            position=rng.normal(size=3),
            quaternion=rng.normal(size=4),
        )
    return b


def _joint_model(kind: str, body_a: str, rng: np.random.Generator) -> SpatialModel:
    b = _three_bodies(rng)
    p = rng.normal(size=3)
    ax = rng.normal(size=3)
    if kind == "spherical":
        b.add_spherical("j", body_a, "b1", point=p)
    elif kind in ("revolute", "prismatic", "cylindrical"):
        getattr(b, f"add_{kind}")("j", body_a, "b1", point=p, axis=ax)
    elif kind == "universal":
        ax2 = np.cross(ax, rng.normal(size=3))
        b.add_universal("j", body_a, "b1", point=p, axis_a=ax, axis_b=ax2)
    elif kind == "weld":
        b.add_weld("j", body_a, "b1", point=p)
    elif kind == "point_on_plane":
        b.add_point_on_plane("j", body_a, "b1", point=p, normal=ax)
    return b.build()


@pytest.mark.parametrize("body_a", ["b0", "ground"])
@pytest.mark.parametrize("kind", JOINT_KINDS)
def test_joint_derivatives_against_finite_differences(kind: str, body_a: str) -> None:
    rng = np.random.default_rng(2 * JOINT_KINDS.index(kind) + (body_a == "ground"))
    model = _joint_model(kind, body_a, rng)
    q_ref = model.reference_configuration()
    zero = np.zeros(model.n)
    # satisfied at the reference configuration
    np.testing.assert_allclose(model.constraint_terms(0.0, q_ref, zero).phi, 0.0, atol=1e-13)
    # derivatives hold everywhere (off the manifold too)
    q = q_ref + 0.2 * rng.normal(size=model.n)
    qd = rng.normal(size=model.n)
    ct = model.constraint_terms(0.0, q, qd, active=["j"])
    assert ct.A.shape == (model.joint("j").dim, model.n)

    def phi(x):
        return model.constraint_terms(0.0, x, zero, active=["j"]).phi

    np.testing.assert_allclose(ct.A, _fd_jacobian(phi, q), atol=FD_TOL)

    def a_qd(s):
        return model.constraint_terms(0.0, q + s * qd, qd, active=["j"]).A @ qd

    gamma_fd = (a_qd(FD_STEP) - a_qd(-FD_STEP)) / (2 * FD_STEP)
    np.testing.assert_allclose(ct.gamma, gamma_fd, atol=FD_TOL * 10)
    Ad = model.constraint_jacobian_dot(0.0, q, qd, active=["j"])
    Ad_fd = (
        model.constraint_jacobian(0.0, q + FD_STEP * qd, ["j"])
        - model.constraint_jacobian(0.0, q - FD_STEP * qd, ["j"])
    ) / (2 * FD_STEP)
    np.testing.assert_allclose(Ad, Ad_fd, atol=FD_TOL * 10)
    np.testing.assert_allclose(Ad @ qd, ct.gamma, atol=EXACT_TOL)
    np.testing.assert_allclose(ct.velocity, ct.A @ qd, atol=EXACT_TOL)


def _rich_model(rng: np.random.Generator) -> SpatialModel:
    b = _three_bodies(rng)
    b.add_spherical("sph", "ground", "b0", point=[0, 0, 0])
    b.add_revolute("rev", "b0", "b1", point=[1, 0, 0], axis=[0, 1, 1])
    b.add_cylindrical("cyl", "b1", "b2", point=[0, 1, 0], axis=[0, 0, 1])
    b.add_spring("spr", "b0", [0, 0, 0], "b2", [1, 1, 1], stiffness=10.0, rest_length=0.5, damping=1.0)
    b.add_spring("spr0", "ground", [0, 1, 0], "b1", [1, 0, 1], stiffness=3.0, rest_length=0.0)
    b.add_actuator("tau", "rev")
    b.add_actuator("F", "cyl", dof="translation")
    b.add_actuator("T", "cyl", dof="rotation")
    b.add_output_point("tip", "b2", point=[1, 1, 1])
    return b.build()


def test_norm_constraint_and_sizes() -> None:
    rng = np.random.default_rng(3)
    m = _rich_model(rng)
    assert isinstance(m, Model)
    assert m.n == 21
    assert m.constraint_names[:3] == ("b0.norm", "b1.norm", "b2.norm")
    q = m.reference_configuration() + 0.1 * rng.normal(size=m.n)
    qd = rng.normal(size=m.n)
    ct = m.constraint_terms(0.0, q, qd, active=["b1.norm"])
    e, ed = q[10:14], qd[10:14]
    np.testing.assert_allclose(ct.phi, [0.5 * (e @ e - 1.0)], atol=EXACT_TOL)
    np.testing.assert_allclose(ct.A[0, 10:14], e, atol=EXACT_TOL)
    np.testing.assert_allclose(ct.gamma, [ed @ ed], atol=EXACT_TOL)


def test_mass_matrix_singular_along_quaternion_but_pd_on_nullspace() -> None:
    rng = np.random.default_rng(4)
    m = _rich_model(rng)
    q = m.reference_configuration()
    M = m.mass_matrix(q)
    np.testing.assert_allclose(M, M.T, atol=EXACT_TOL)
    for i in range(3):
        e = q[7 * i + 3 : 7 * i + 7]
        np.testing.assert_allclose(M[7 * i + 3 : 7 * i + 7, 7 * i + 3 : 7 * i + 7] @ e, 0.0, atol=1e-14)
    A = m.constraint_jacobian(0.0, q, [f"b{i}.norm" for i in range(3)])
    N = np.linalg.svd(A)[2][A.shape[0] :].T
    assert np.linalg.eigvalsh(N.T @ M @ N).min() > 1e-3


def test_coriolis_is_christoffel() -> None:
    rng = np.random.default_rng(5)
    m = _rich_model(rng)
    q = m.reference_configuration() + 0.3 * rng.normal(size=m.n)  # off the manifold too
    qd = rng.normal(size=m.n)
    C = m.coriolis_matrix(q, qd)
    Md = (m.mass_matrix(q + FD_STEP * qd) - m.mass_matrix(q - FD_STEP * qd)) / (2 * FD_STEP)
    S = Md - 2 * C
    np.testing.assert_allclose(S + S.T, 0.0, atol=FD_TOL * 10)
    # C qd = Ṁ qd − ½ ∂(qdᵀ M qd)/∂q (Lagrange)
    grad = _fd_jacobian(lambda x: np.atleast_1d(qd @ m.mass_matrix(x) @ qd), q)[0]
    np.testing.assert_allclose(C @ qd, Md @ qd - 0.5 * grad, atol=FD_TOL * 10)
    np.testing.assert_allclose(m.coriolis_force(q, qd), C @ qd, atol=1e-12)
    # Christoffel symbols are symmetric in the last two indices: C(q, a) b = C(q, b) a
    a, bvec = rng.normal(size=(2, m.n))
    np.testing.assert_allclose(m.coriolis_matrix(q, a) @ bvec, m.coriolis_matrix(q, bvec) @ a, atol=1e-12)


def test_conservative_force_is_minus_gradient_of_potential() -> None:
    rng = np.random.default_rng(6)
    m = _rich_model(rng)
    q = m.reference_configuration() + 0.2 * rng.normal(size=m.n)
    grad = _fd_jacobian(lambda x: np.atleast_1d(m.potential_energy(x)), q)[0]
    np.testing.assert_allclose(m.conservative_force(q), -grad, atol=FD_TOL * 100)


def test_energy_against_independent_com_kinematics() -> None:
    rng = np.random.default_rng(7)
    m = _rich_model(rng)
    q = m.reference_configuration()
    qd = rng.normal(size=m.n)
    T = 0.0
    V = 0.0
    g = np.array(m.gravity)
    h = 1e-6
    for i, b in enumerate(m.bodies):
        o = 7 * i
        r, e = q[o : o + 3], q[o + 3 : o + 7]
        # unit-norm velocity of the quaternion (tangent), rotation by finite differences
        ed = qd[o + 3 : o + 7] - (qd[o + 3 : o + 7] @ e) * e
        qd[o + 3 : o + 7] = ed
        R = rotation_matrix(e)
        Rd = (rotation_matrix(e + h * ed) - rotation_matrix(e - h * ed)) / (2 * h)
        W = Rd @ R.T  # world angular velocity, skew
        w = np.array([W[2, 1], W[0, 2], W[1, 0]])
        Jw = R @ b.inertia @ R.T
        T += 0.5 * b.mass * qd[o : o + 3] @ qd[o : o + 3] + 0.5 * w @ Jw @ w
        V -= b.mass * g @ r
    for s in m.springs:
        pa = m.point_position(q, s.body_a, s.point_a)
        pb = m.point_position(q, s.body_b, s.point_b)
        V += 0.5 * s.stiffness * (np.linalg.norm(pb - pa) - s.rest_length) ** 2
    assert m.kinetic_energy(q, qd) == pytest.approx(T, rel=1e-8)
    assert m.potential_energy(q) == pytest.approx(V, rel=1e-12)
    assert m.energy(q, qd) == pytest.approx(T + V, rel=1e-8)


def test_actuator_columns_do_virtual_work_of_joint_rates() -> None:
    """uᵀ Bᵀ qd equals torque × relative rate about the axis / force × slide rate."""
    rng = np.random.default_rng(8)
    m = _rich_model(rng)
    q = m.reference_configuration()
    # an admissible velocity: project a random one onto N(A)
    A = m.constraint_jacobian(0.0, q)
    N = np.linalg.svd(A)[2][np.linalg.matrix_rank(A) :].T
    qd = N @ rng.normal(size=N.shape[1])
    B = m.input_matrix(q)
    assert B.shape == (m.n, 3)
    rev = m.joint("rev")
    axis = rotation_matrix(q[3:7]) @ rev.vectors_a[0]
    w0 = m.angular_velocity(q, qd, "b0", frame="world")
    w1 = m.angular_velocity(q, qd, "b1", frame="world")
    assert B[:, 0] @ qd == pytest.approx(axis @ (w1 - w0), abs=1e-12)
    cyl = m.joint("cyl")
    axis = rotation_matrix(q[10:14]) @ cyl.vectors_a[0]
    w2 = m.angular_velocity(q, qd, "b2", frame="world")
    assert B[:, 2] @ qd == pytest.approx(axis @ (w2 - w1), abs=1e-12)

    def slide(x):
        pa = m.point_position(x, "b1", cyl.point_a)
        pb = m.point_position(x, "b2", cyl.point_b)
        return np.atleast_1d(rotation_matrix(x[10:14]) @ cyl.vectors_a[0] @ (pb - pa))

    np.testing.assert_allclose(B[:, 1], _fd_jacobian(slide, q)[0], atol=FD_TOL)


def test_damper_dissipates_and_outputs_geometry() -> None:
    rng = np.random.default_rng(9)
    m = _rich_model(rng)
    q = m.reference_configuration()
    qd = rng.normal(size=m.n)
    assert m.passive_force(0.0, q, qd) @ qd <= 0.0
    out = m.outputs(0.0, q, qd)
    assert set(out) == {"tip.position", "tip.velocity"}
    np.testing.assert_allclose(out["tip.position"], [1, 1, 1], atol=1e-12)
    J = m.point_jacobian(q, "b2", m.output_points[0].point)
    np.testing.assert_allclose(out["tip.velocity"], J @ qd, atol=1e-12)
    geo = m.geometry(q)
    assert geo.dim == 3 and geo.segments.shape[1:] == (2, 3) and geo.frames.shape == (3, 4, 3)
    np.testing.assert_allclose(geo.frames[1, 1:], rotation_matrix(q[10:14]).T, atol=1e-12)


def test_quaternion_conventions() -> None:
    rng = np.random.default_rng(10)
    e = rng.normal(size=4)
    e /= np.linalg.norm(e)
    R = rotation_matrix(e)
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-14)
    assert np.linalg.det(R) == pytest.approx(1.0)
    np.testing.assert_allclose(R, E_matrix(e) @ G_matrix(e).T, atol=1e-14)
    np.testing.assert_allclose(quaternion_from_rotation_matrix(R), e * np.sign(e[0]), atol=1e-12)
    # rotation about z by 90° maps x to y (Hamilton, body → world)
    Rz = rotation_matrix(quaternion_from_axis_angle([0, 0, 2], np.pi / 2))
    np.testing.assert_allclose(Rz @ [1, 0, 0], [0, 1, 0], atol=1e-15)
    s = rng.normal(size=3)
    np.testing.assert_allclose(np.einsum("ajk,j,k->a", point_tensor(s), e, e), R @ s, atol=1e-14)
    a, v = rng.normal(size=3), rng.normal(size=4)
    np.testing.assert_allclose(G_matrix(v).T @ a, H_matrix(a) @ v, atol=1e-14)
    ed = rng.normal(size=4)
    ed -= (ed @ e) * e
    Rd = (rotation_matrix(e + FD_STEP * ed) - rotation_matrix(e - FD_STEP * ed)) / (2 * FD_STEP)
    np.testing.assert_allclose(R.T @ Rd, skew(2 * G_matrix(e) @ ed), atol=FD_TOL)
    np.testing.assert_allclose(Rd @ R.T, skew(2 * E_matrix(e) @ ed), atol=FD_TOL)


def test_replace_gravity() -> None:
    m = _rich_model(np.random.default_rng(11))
    m2 = m.replace(gravity=(0.0, 0.0, 0.0))
    assert m2.potential_energy(m.reference_configuration()) != m.potential_energy(
        m.reference_configuration()
    )
    with pytest.raises(InputError, match="unknown field"):
        m.replace(gravty=(0, 0, 0))


# ---------------------------------------------------------------------- bad input
def test_unknown_names_raise() -> None:
    b = SpatialBuilder("bad")
    b.add_body("a", mass=1.0, inertia=[1, 1, 1])
    with pytest.raises(UnknownNameError, match="unknown body 'nope'"):
        b.add_revolute("j", "ground", "nope", point=[0, 0, 0], axis=[0, 0, 1])
    b.add_revolute("j", "ground", "a", point=[0, 0, 0], axis=[0, 0, 1])
    with pytest.raises(UnknownNameError, match="unknown joint 'k'"):
        b.add_actuator("u", "k")
    m = b.build()
    with pytest.raises(UnknownNameError):
        m.joint("k")
    with pytest.raises(UnknownNameError):
        m.constraint_terms(0.0, m.reference_configuration(), np.zeros(7), active=["k"])
    with pytest.raises(UnknownNameError):
        m.point_position(m.reference_configuration(), "nope", [0, 0, 0])


@pytest.mark.parametrize(
    "inertia, match",
    [
        ([1.0, 1.0, 3.0], "triangle inequality"),
        ([1.0, -1.0, 1.0], "positive definite"),
        ([[1.0, 0.5, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], "symmetric"),
        ([1.0, 1.0], "shape"),
        ([1.0, np.nan, 1.0], "finite"),
    ],
)
def test_non_physical_inertia_raises(inertia, match) -> None:
    with pytest.raises(ModelError, match=match):
        SpatialBuilder("bad").add_body("a", mass=1.0, inertia=inertia)


def test_other_bad_input_raises() -> None:
    b = SpatialBuilder("bad")
    with pytest.raises(ModelError, match="mass"):
        b.add_body("a", mass=0.0, inertia=[1, 1, 1])
    with pytest.raises(ModelError, match="reserved"):
        b.add_body("ground", mass=1.0, inertia=[1, 1, 1])
    with pytest.raises(ModelError, match="quaternion"):
        b.add_body("a", mass=1.0, inertia=[1, 1, 1], quaternion=[0, 0, 0, 0])
    b.add_body("a", mass=1.0, inertia=[1, 1, 1])
    with pytest.raises(ModelError, match="duplicate body"):
        b.add_body("a", mass=1.0, inertia=[1, 1, 1])
    for kind in ("revolute", "prismatic", "cylindrical"):
        with pytest.raises(ModelError, match="zero-length"):
            getattr(b, f"add_{kind}")("j", "ground", "a", point=[0, 0, 0], axis=[0, 0, 0])
    with pytest.raises(ModelError, match="zero-length"):
        b.add_point_on_plane("j", "ground", "a", point=[0, 0, 0], normal=[0, 0, 0])
    with pytest.raises(ModelError, match="perpendicular"):
        b.add_universal("j", "ground", "a", point=[0, 0, 0], axis_a=[1, 0, 0], axis_b=[1, 1, 0])
    with pytest.raises(ModelError, match="itself"):
        b.add_spherical("j", "a", "a", point=[0, 0, 0])
    b.add_spherical("j", "ground", "a", point=[0, 0, 0])
    with pytest.raises(ModelError, match="duplicate"):
        b.add_spherical("j", "ground", "a", point=[0, 0, 0])
    with pytest.raises(ModelError, match="no actuated rotation"):
        b.add_actuator("u", "j")
    with pytest.raises(ModelError, match="stiffness"):
        b.add_spring("s", "ground", [0, 0, 0], "a", [1, 0, 0], stiffness=-1.0)
    m = b.build()
    with pytest.raises(ShapeError):
        m.mass_matrix(np.zeros(6))


def test_assembly_of_spatial_models() -> None:
    """Gauss–Newton assembly works despite the singular quaternion block of M; a guess that
    cannot be assembled (zero quaternion) raises AssemblyError."""
    from nonmin.errors import AssemblyError
    from nonmin.library.top import top_model
    from nonmin.model import assemble, consistent

    m = top_model()
    rng = np.random.default_rng(12)
    q = m.reference_configuration() + 0.05 * rng.normal(size=7)
    s = assemble(m, q, rng.normal(size=7))
    assert consistent(m, s)
    assert np.linalg.norm(s.q[3:7]) == pytest.approx(1.0, abs=1e-10)
    np.testing.assert_allclose(m.point_position(s.q, "top", [0, 0, -0.1]), 0.0, atol=1e-10)
    with pytest.raises(AssemblyError):
        assemble(m, np.zeros(7))


def test_inactive_joint_is_data_not_topology() -> None:
    b = SpatialBuilder("switch")
    b.add_body("a", mass=1.0, inertia=[1, 1, 1], position=[1, 0, 0])
    b.add_spherical("pin", "ground", "a", point=[0, 0, 0])
    b.add_point_on_plane("wall", "ground", "a", point=[1, 0, 0], normal=[1, 0, 0], active=False)
    m = b.build()
    assert m.default_active == {"a.norm", "pin"}
    q = m.reference_configuration()
    assert m.constraint_terms(0.0, q, np.zeros(7)).A.shape == (4, 7)
    assert m.constraint_terms(0.0, q, np.zeros(7), active=m.constraint_names).A.shape == (5, 7)


def test_free_body_follows_euler_equations() -> None:
    """No joints: r̈ = g and ω̇' = −J⁻¹(ω' × J ω') (torque-free Euler equations)."""
    from nonmin.core import forward_dynamics

    J = np.array([[0.3, 0.02, 0.01], [0.02, 0.5, -0.03], [0.01, -0.03, 0.6]])
    m = SpatialBuilder("free", gravity=(0.0, 0.0, -9.81)).add_body(
        "b", mass=2.0, inertia=J, quaternion=[0.9, 0.1, -0.3, 0.2]
    ).build()
    assert m.constraint_names == ("b.norm",)
    rng = np.random.default_rng(13)
    q = m.reference_configuration()
    e = q[3:]
    w = rng.normal(size=3) * 5.0
    qd = np.concatenate((rng.normal(size=3), 0.5 * G_matrix(e).T @ w))
    ev = m.evaluate(0.0, q, qd)
    qdd = forward_dynamics(ev.M, ev.h, ev.constraints.A, ev.constraints.gamma)
    np.testing.assert_allclose(qdd[:3], [0.0, 0.0, -9.81], atol=1e-12)
    np.testing.assert_allclose(
        2.0 * G_matrix(e) @ qdd[3:], -np.linalg.solve(J, np.cross(w, J @ w)), atol=1e-10
    )
    geo = m.geometry(q)
    assert geo.segments.shape == (0, 2, 3) and geo.frames.shape == (1, 4, 3)


def test_replace_bodies_is_validated() -> None:
    import dataclasses

    m = _rich_model(np.random.default_rng(14))
    heavier = tuple(dataclasses.replace(b, mass=2 * b.mass) for b in m.bodies)
    m2 = m.replace(bodies=heavier)
    q = m.reference_configuration()
    np.testing.assert_allclose(m2.mass_matrix(q)[:3, :3], 2 * m.mass_matrix(q)[:3, :3])
    bad = (dataclasses.replace(m.bodies[0], inertia=np.diag([1.0, 1.0, 3.0])), *m.bodies[1:])
    with pytest.raises(ModelError, match="triangle"):
        m.replace(bodies=bad)
    with pytest.raises(ModelError, match="mass"):
        m.replace(bodies=(dataclasses.replace(m.bodies[0], mass=-1.0), *m.bodies[1:]))
