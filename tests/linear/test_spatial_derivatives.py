"""Derivatives of spatial-builder models (SpatialProgram on dual numbers) against central differences.

References: central differences of the engine's own evaluation and forward dynamics of the
same model (the functions differentiated numerically, h = 1e-5: truncation ~1e-10 and
round-off ~1e-11 relative, both below the tolerance), on Bricard's mechanism (IFToMM A04: a
closed spatial chain of five rods and six revolute joints with one permanently redundant row,
so the kernel's rank is m − 1 and its least-squares residual term is exercised) and on a chain
with a spherical, a revolute and a cylindrical joint, two spring-dampers and three actuators.
"""

import numpy as np
import pytest

import nonmin
from nonmin import library
from nonmin.linear import dynamics_derivatives, term_tangents
from nonmin.model.spatial import SpatialBuilder

FD_STEP = 1e-5
FD_RTOL = 1e-7


def _fd(fun, x, h=FD_STEP):
    cols = []
    for i in range(x.size):
        e = np.zeros_like(x)
        e[i] = h
        cols.append((fun(x + e) - fun(x - e)) / (2 * h))
    return np.stack(cols, axis=-1)


def _moving_bricard():
    """Bricard's tabled configuration with an admissible velocity (A qd = 0)."""
    mech = library.get("A04_bricard")
    model = mech.model
    q = mech.state.q
    A = model.constraint_jacobian(0.0, q)
    Z = np.linalg.svd(A)[2][np.linalg.matrix_rank(A) :].T
    qd = Z @ np.array([1.3] + [0.0] * (Z.shape[1] - 1))
    return model, q, qd


def _rich():
    rng = np.random.default_rng(7)
    b = SpatialBuilder("rich", gravity=(0.3, -9.81, 1.0))
    for i in range(3):
        b.add_body(
            f"b{i}",
            mass=1.0 + i,
            inertia=np.array([[0.10, 0.01, 0.0], [0.01, 0.20, 0.02], [0.0, 0.02, 0.25]]),
            position=rng.normal(size=3),
            quaternion=rng.normal(size=4),
        )
    b.add_spherical("sph", "ground", "b0", point=[0, 0, 0])
    b.add_revolute("rev", "b0", "b1", point=[1, 0, 0], axis=[0, 1, 1])
    b.add_cylindrical("cyl", "b1", "b2", point=[0, 1, 0], axis=[0, 0, 1])
    b.add_spring(
        "spr", "b0", [0, 0, 0], "b2", [1, 1, 1], stiffness=10.0, rest_length=0.5, damping=1.0
    )
    b.add_spring("spr0", "ground", [0, 1, 0], "b1", [1, 0, 1], stiffness=3.0, rest_length=0.0)
    b.add_actuator("tau", "rev")
    b.add_actuator("F", "cyl", dof="translation")
    b.add_actuator("T", "cyl", dof="rotation")
    model = b.build()
    q = nonmin.model.assemble(model, model.reference_configuration()).q
    A = model.constraint_jacobian(0.0, q)
    Z = np.linalg.svd(A)[2][np.linalg.matrix_rank(A) :].T
    qd = Z @ rng.normal(size=Z.shape[1])
    return model, q, qd


CASES = {"bricard": _moving_bricard, "rich": _rich}


@pytest.mark.parametrize("name", sorted(CASES))
def test_spatial_term_tangents_match_central_differences(name):
    model, q, qd = CASES[name]()
    prog = model.engine_program()
    mask = model.active_mask(model.default_active)
    rng = np.random.default_rng(3)
    dq = rng.standard_normal(model.n)
    dv = rng.standard_normal(model.n)
    tt = term_tangents(model, q, qd, dq, dv)

    def ev(s):
        T = prog.evaluate(0.0, q + s * dq, qd + s * dv, mask)
        return {
            k: np.array(getattr(T, k))
            for k in ("M", "h", "f_passive", "B", "A", "gamma", "phi", "velocity")
        }

    p, m = ev(FD_STEP), ev(-FD_STEP)
    for key in ("M", "h", "f_passive", "B", "A", "gamma", "phi", "velocity"):
        fd = (p[key] - m[key]) / (2 * FD_STEP)
        exact = tt["d" + key][0]
        scale = max(1.0, float(np.abs(fd).max(initial=0.0)))
        assert np.abs(exact - fd).max(initial=0.0) <= FD_RTOL * scale, key


@pytest.mark.parametrize("name", sorted(CASES))
def test_spatial_dynamics_derivatives_match_central_differences(name):
    model, q, qd = CASES[name]()
    rng = np.random.default_rng(4)
    u = rng.standard_normal(model.k)
    f = rng.standard_normal(model.n)
    d = dynamics_derivatives(model, q, qd, u=u, f=f)

    def acc(qq, vv, ff=f, uu=u):
        g = ff + model.input_matrix(qq) @ uu if model.k else ff
        return model.forward_dynamics(qq, vv, f=g)

    ref = acc(q, qd)
    assert np.allclose(d.qdd, ref.qdd, rtol=1e-10, atol=1e-10 * (1 + np.abs(ref.qdd).max()))
    if name == "bricard":
        # Bricard's redundant row is redundant on the manifold only: 1e-5 off it the rank is
        # m, another branch of the kernel. Differentiate along curves of the manifold
        # (q(s) = assemble(q + s z), z in N(A): q(s) = q + s z + O(s²), even in s, so central
        # differences give ∂q̈/∂q z).
        A = model.constraint_jacobian(0.0, q)
        Z = np.linalg.svd(A)[2][np.linalg.matrix_rank(A) :].T

        def on(s, z):
            return nonmin.model.assemble(model, q + s * z, tol=1e-14).q

        dq_pairs = [
            (d.dqdd_dq @ Z, _fd(lambda x: acc(on(x[0], Z[:, 0]), qd).qdd, np.zeros(1))),
            (d.dfc_dq @ Z, _fd(lambda x: acc(on(x[0], Z[:, 0]), qd).f_c, np.zeros(1))),
        ]
    else:
        dq_pairs = [
            (d.dqdd_dq, _fd(lambda x: acc(x, qd).qdd, q)),
            (d.dfc_dq, _fd(lambda x: acc(x, qd).f_c, q)),
        ]
    pairs = [
        *dq_pairs,
        (d.dqdd_dqd, _fd(lambda x: acc(q, x).qdd, qd)),
        (d.dqdd_df, _fd(lambda x: acc(q, qd, ff=x).qdd, f)),
        (d.dfc_dqd, _fd(lambda x: acc(q, x).f_c, qd)),
    ]
    if model.k:
        pairs.append((d.dqdd_du, _fd(lambda x: acc(q, qd, uu=x).qdd, u)))
    for exact, fd in pairs:
        scale = max(1.0, float(np.abs(fd).max()))
        assert np.abs(exact - fd).max() <= FD_RTOL * scale
    # the NumPy specification (terms' tangents from the engine, the kernel in NumPy)
    p = dynamics_derivatives(model, q, qd, u=u, f=f, backend="numpy")
    assert p.rank == d.rank
    for key in ("qdd", "dqdd_dq", "dqdd_dqd", "dqdd_df", "dfc_dq", "dfc_dqd"):
        a, b = getattr(d, key), getattr(p, key)
        assert np.abs(a - b).max() <= 1e-9 * max(1.0, float(np.abs(b).max())), key


def test_bricard_rank_is_one_below_its_rows():
    model, q, qd = _moving_bricard()
    d = dynamics_derivatives(model, q, qd)
    m = model.constraint_jacobian(0.0, q).shape[0]
    assert d.rank == m - 1


def test_spatial_linearize_has_one_mode_pair():
    """Bricard's mechanism has mobility 1: its tangent linearization is 2 × 2."""
    model, q, _ = _moving_bricard()
    lin = nonmin.linearize(model, q)
    assert lin.A.shape == (2, 2)
