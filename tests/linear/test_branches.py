"""Linearization on one branch at a singular configuration, against exact 1-DOF reductions.

At a singular configuration several branches of the configuration manifold cross; the
dynamics on each is a smooth 1-DOF system there. ``linearize(..., branch=d)`` picks the branch
whose tangent is nearest to the velocity direction d and must return the linearization of that
branch's reduced dynamics θ̈ = F(θ, θ̇) written in the chart z = Zᵀ(Q(θ) − Q(θ₀)),
v = Zᵀ Q1(θ) θ̇ (Q(θ) the branch, Q1, Q2, Q3 its θ-derivatives, Z the returned tangent):
v̇ = G(z, v) = s1 θ̇² + s F with s = Zᵀ Q1, s1 = Zᵀ Q2, s2 = Zᵀ Q3, θ̇ = v/s, so

    ∂G/∂v = 2 s1 θ̇ / s + F_ω,
    ∂G/∂z = (s2 θ̇² − 2 s1² θ̇²/s + s1 F + s F_θ − s1 θ̇ F_ω) / s,
    drift = (s θ̇, s1 θ̇² + s F).

* IFToMM A02 (N four-bar) at the horizontal configuration (tangent space of dimension N + 1
  when no branch is chosen): the parallelogram branch (every crank at the same angle θ,
  reduction I θ̈ = −g c cos θ of shared/benchmarks/README.md) and, for N = 1, the folded
  branch where crank 0 stays put and the coupler turns with crank 1 about the second ground
  pivot (a rigid pair of two bars: I = 2/3, torque −g cos θ).
* The crossed four-bar at its change point θ = 0: the anti-parallelogram branch (the
  library's closed-form reduction) and the parallelogram branch (ψ = θ, the coupler
  translates: I = 1/3 + 2 + 1/3, V = 3 g sin θ).
"""

import math

import numpy as np
import pytest

import nonmin
from nonmin import library

G = 9.81


def _chart_reference(Z, Q1, Q2, Q3, omega, F, F_th, F_om):
    s, s1, s2 = Z @ Q1, Z @ Q2, Z @ Q3
    dG_dv = 2 * s1 * omega / s + F_om
    dG_dz = (s2 * omega**2 - 2 * s1**2 * omega**2 / s + s1 * F + s * F_th - s1 * omega * F_om) / s
    return np.array([[0.0, 1.0], [dG_dz, dG_dv]]), np.array([s * omega, s1 * omega**2 + s * F])


# ------------------------------------------------------------------ A02 parallelogram branch
def _a02(N, theta):
    c, s = math.cos(theta), math.sin(theta)
    q, Q1, Q2, Q3 = [], [], [], []
    for i in range(N + 1):
        q += [i + 0.5 * c, 0.5 * s, theta]
        Q1 += [-0.5 * s, 0.5 * c, 1.0]
        Q2 += [-0.5 * c, -0.5 * s, 0.0]
        Q3 += [0.5 * s, -0.5 * c, 0.0]
    for i in range(1, N + 1):
        q += [i - 0.5 + c, s, 0.0]
        Q1 += [-s, c, 0.0]
        Q2 += [-c, -s, 0.0]
        Q3 += [s, -c, 0.0]
    return (np.array(x) for x in (q, Q1, Q2, Q3))


@pytest.mark.parametrize("N", [1, 2, 3])
@pytest.mark.parametrize("omega", [0.0, -1.3])
def test_a02_parallelogram_branch_at_the_horizontal_configuration(N, omega):
    model = library.a02_n_four_bar(N=N).model
    q, Q1, Q2, Q3 = _a02(N, 0.0)
    lin_all = nonmin.linearize(model, q, Q1 * omega)
    assert lin_all.singular and lin_all.tangent_dim == N + 1 and lin_all.branch is None
    lin = nonmin.linearize(model, q, Q1 * omega, branch=Q1)
    assert lin.singular and lin.tangent_dim == 1 and lin.velocity_dim == 1
    assert lin.generic_rank == 6 * N + 2 and lin.rank == 5 * N + 2
    assert abs(abs(lin.branch @ Q1) / np.linalg.norm(Q1) - 1.0) <= 1e-9
    kappa = G * ((N + 1) / 2 + N) / ((N + 1) / 3 + N)
    A_ref, drift_ref = _chart_reference(lin.Zq[:, 0], Q1, Q2, Q3, omega, -kappa, 0.0, 0.0)
    assert np.allclose(lin.A, A_ref, rtol=1e-8, atol=1e-8)
    assert np.allclose(lin.drift, drift_ref, rtol=1e-8, atol=1e-8)
    # an approximate direction (a velocity slightly off the branch) finds the same branch
    rng = np.random.default_rng(N)
    near = Q1 + 0.05 * lin_all.Zq @ rng.standard_normal(N + 1)
    d = nonmin.linear.branch_tangent(model, q, near)
    assert abs(abs(d @ lin.branch) - 1.0) <= 1e-9
    # the modes on the branch: the 2 × 2 system, not the 2(N + 1) of the span of all branches
    m = nonmin.modes(model, q, branch=Q1)
    assert m.eigenvalues.size == 2 and nonmin.modes(model, q).eigenvalues.size == 2 * (N + 1)


def test_a02_folded_branch_of_one_window():
    """N = 1: crank 0 fixed horizontal, coupler and crank 1 turning together about (1, 0)."""
    model = library.a02_n_four_bar(N=1).model
    q, _, _, _ = _a02(1, 0.0)
    # Q(θ): crank 0 (0.5, 0, 0); crank 1 and coupler both centred at (1 + cos θ/2, sin θ/2), angle θ
    Q1 = np.array([0, 0, 0, 0.0, 0.5, 1.0, 0.0, 0.5, 1.0])
    Q2 = np.array([0, 0, 0, -0.5, 0.0, 0.0, -0.5, 0.0, 0.0])
    Q3 = np.array([0, 0, 0, 0.0, -0.5, 0.0, 0.0, -0.5, 0.0])
    omega = 0.7
    lin = nonmin.linearize(model, q, Q1 * omega, branch=Q1)
    assert lin.tangent_dim == 1
    F = -G * 1.0 / (2.0 / 3.0)  # −g cos θ / I at θ = 0
    A_ref, drift_ref = _chart_reference(lin.Zq[:, 0], Q1, Q2, Q3, omega, F, 0.0, 0.0)
    assert np.allclose(lin.A, A_ref, rtol=1e-8, atol=1e-8)
    assert np.allclose(lin.drift, drift_ref, rtol=1e-8, atol=1e-8)
    # the two branches give different systems at the same state (q, 0)
    par = nonmin.linearize(model, q, branch=list(_a02(1, 0.0))[1])
    fold = nonmin.linearize(model, q, branch=Q1)
    assert not np.allclose(par.drift, fold.drift)


# ------------------------------------------------------------------ crossed four-bar
def _cfb_parallelogram(theta):
    """Crank, coupler, rocker on the parallelogram branch ψ = θ (ground pivots (0,0), (2,0))."""
    c, s = math.cos(theta), math.sin(theta)
    Q1 = np.array([-0.5 * s, 0.5 * c, 1.0, -s, c, 0.0, -0.5 * s, 0.5 * c, 1.0])
    Q2 = np.array([-0.5 * c, -0.5 * s, 0.0, -c, -s, 0.0, -0.5 * c, -0.5 * s, 0.0])
    Q3 = np.array([0.5 * s, -0.5 * c, 0.0, s, -c, 0.0, 0.5 * s, -0.5 * c, 0.0])
    return Q1, Q2, Q3


def test_crossed_four_bar_branches_at_the_change_point():
    from nonmin.library._planar import _cfb_branch, _cfb_coordinates, _cfb_reduced

    model = library.crossed_four_bar().model
    q0, _ = _cfb_coordinates(np.array(0.0), np.array(0.0))
    q0 = np.asarray(q0, dtype=float)
    lin_all = nonmin.linearize(model, q0)
    assert lin_all.singular and lin_all.tangent_dim == 2

    # anti-parallelogram branch at rest: F = −V'/m, F_θ from the closed form (central difference
    # of the reference's own V' and m, which know nothing of nonmin)
    mass_and_slope, _ = _cfb_reduced(G)
    br = _cfb_branch(np.array(0.0))
    Q1 = np.concatenate([np.append(br["dg"][k], br["dang"][k]) for k in range(3)])
    Q2 = np.concatenate([np.append(br["ddg"][k], br["ddang"][k]) for k in range(3)])
    m0, _, dV0 = mass_and_slope(0.0)
    h = 1e-5
    Fp = -mass_and_slope(h)[2] / mass_and_slope(h)[0]
    Fm = -mass_and_slope(-h)[2] / mass_and_slope(-h)[0]
    F, F_th = -dV0 / m0, (Fp - Fm) / (2 * h)
    anti = nonmin.linearize(model, q0, branch=Q1)
    A_ref, drift_ref = _chart_reference(anti.Zq[:, 0], Q1, Q2, 0 * Q1, 0.0, F, F_th, 0.0)
    assert np.allclose(anti.A, A_ref, rtol=1e-7, atol=1e-7)
    assert np.allclose(anti.drift, drift_ref, rtol=1e-8, atol=1e-8)

    # parallelogram branch (moving): m = 8/3, V = 3 g sin θ
    P1, P2, P3 = _cfb_parallelogram(0.0)
    omega = 1.1
    par = nonmin.linearize(model, q0, P1 * omega, branch=P1)
    A_ref, drift_ref = _chart_reference(par.Zq[:, 0], P1, P2, P3, omega, -3 * G / (8 / 3), 0.0, 0.0)
    assert np.allclose(par.A, A_ref, rtol=1e-8, atol=1e-8)
    assert np.allclose(par.drift, drift_ref, rtol=1e-8, atol=1e-8)
    assert abs(abs(par.branch @ anti.branch)) < 0.9  # two distinct tangents


def test_branch_direction_must_lie_in_the_tangent_space():
    model = library.a02_n_four_bar(N=1).model
    q, _, _, _ = _a02(1, 0.0)
    lin = nonmin.linearize(model, q)
    A = model.constraint_jacobian(0.0, q)
    normal = A.T @ np.ones(A.shape[0])
    normal -= lin.Zq @ (lin.Zq.T @ normal)
    with pytest.raises(nonmin.errors.InputError, match="branch"):
        nonmin.linearize(model, q, branch=normal)
    with pytest.raises(nonmin.errors.ShapeError, match="branch"):
        nonmin.linearize(model, q, branch=np.ones(3))


@pytest.mark.parametrize("N", [1, 2, 3])
def test_a02_has_N_plus_1_branches_at_the_horizontal_configuration(N):
    """Each window is a rhombus: at the flat configuration it either stays a parallelogram
    (both its cranks turn together) or folds (its left crank stays flat, its coupler turns with
    the right crank about the right ground pivot). The exact reduction: window i allows
    c_i = c_{i+1} or c_i = 0 (crank angles), so the branches through the flat configuration are
    the crank-angle lines (0, …, 0, 1, …, 1): N + 1 of them, found from the second-order cone
    (no sampling) and certified complete."""
    model = library.a02_n_four_bar(N=N).model
    q, Q1, _, _ = _a02(N, 0.0)
    found = nonmin.linear.branches(model, q)
    assert isinstance(found, nonmin.linear.Branches)
    assert found.certified and found.method == "second-order cone", found.note
    assert len(found) == N + 1
    A = model.constraint_jacobian(0.0, q)
    cranks = []
    for B in found:
        assert B.shape == (model.n, 1)
        assert np.abs(A @ B).max() <= 1e-12
        c = B[2 : 3 * (N + 1) : 3, 0]
        cranks.append(tuple(np.round(c / np.abs(c).max(), 10)))
    expected = {tuple([0.0] * k + [1.0] * (N + 1 - k)) for k in range(N + 1)}
    assert set(cranks) == expected
    # the tangent of each branch = the exact reduction's: the parallelogram motion of windows
    # k…N−1 (cranks k…N at the same rate), the windows before k not moving (their cranks flat)
    for B in found:
        c = B[2 : 3 * (N + 1) : 3, 0]
        k0 = int(np.argmax(np.abs(c) > 0.5 * np.abs(c).max()))
        ref = np.zeros(model.n)
        for i in range(k0, N + 1):
            ref[3 * i : 3 * i + 3] = Q1[3 * i : 3 * i + 3]  # crank i: centre (0, 1/2), rate 1
        for i in range(1, N + 1):  # coupler i (between cranks i − 1 and i): moves with crank i
            j = 3 * (N + 1) + 3 * (i - 1)
            if i - 1 >= k0:
                ref[j : j + 3] = Q1[j : j + 3]  # translates with both cranks
            elif i >= k0:
                ref[j : j + 3] = [0.0, 0.5, 1.0]  # folds: turns about its left end with crank i
        ref /= np.linalg.norm(ref)
        assert abs(abs(float(ref @ B[:, 0])) - 1.0) <= 1e-12
    # a label selects the same branch as its velocity direction
    label = cranks.index(tuple([1.0] * (N + 1)))
    by_label = nonmin.linearize(model, q, Q1 * 0.5, branch=label)
    by_direction = nonmin.linearize(model, q, Q1 * 0.5, branch=Q1)
    assert np.allclose(by_label.A, by_direction.A, atol=1e-12)
    with pytest.raises(nonmin.errors.InputError, match="label"):
        nonmin.linearize(model, q, branch=N + 1)


def test_crossed_four_bar_has_two_branches_at_the_change_point():
    from nonmin.library._planar import _cfb_coordinates

    model = library.crossed_four_bar().model
    q0 = np.asarray(_cfb_coordinates(np.array(0.0), np.array(0.0))[0], dtype=float)
    found = nonmin.linear.branches(model, q0)
    assert found.certified and len(found) == 2, found.note
    ratios = sorted(float(B[8, 0] / B[2, 0]) for B in found)  # rocker rate / crank rate
    assert np.allclose(ratios, [-3.0, 1.0], atol=1e-12)  # anti-parallelogram ψ' = −3, parallelogram
    # at a regular configuration there is one branch: N(A)
    q1 = np.asarray(_cfb_coordinates(np.array(1.0), np.array(0.0))[0], dtype=float)
    regular = nonmin.linear.branches(model, q1)
    assert regular.certified and regular.method == "regular"
    (B,) = regular
    assert B.shape == (9, 1)


# ------------------------------------------------------------------ the quadratic cone itself
def _product(a, b):
    """The symmetric matrix of the form (a·c)(b·c)."""
    return 0.5 * (np.outer(a, b) + np.outer(b, a))


def _lines(dec):
    out = set()
    for B in dec.subspaces:
        assert B.shape[1] == 1
        b = B[:, 0] / B[int(np.argmax(np.abs(B[:, 0]))), 0]
        out.add(tuple(np.round(b, 6) + 0.0))
    return out


def test_quadratic_cone_of_products_in_any_basis_of_the_pencil():
    """c_i (c_i − c_{i+1}) = 0 (the A02 windows): N + 1 lines, also when the forms given are
    mixed (the splitting members are then found in the pencils of pairs)."""
    from nonmin.linear._cone import quadratic_cone

    for N in (2, 3):
        e = np.eye(N + 1)
        F = [_product(e[i], e[i] - e[i + 1]) for i in range(N)]
        expected = {tuple([0.0] * k + [1.0] * (N + 1 - k)) for k in range(N + 1)}
        mixes = [np.random.default_rng(seed).standard_normal((N, N)) for seed in range(5)]
        for forms in [F] + [[sum(x[i, j] * F[j] for j in range(N)) for i in range(N)] for x in mixes]:
            dec = quadratic_cone(forms)
            assert dec.exact and dec.reason == ""
            assert _lines(dec) == expected
    # N = 4 mixed: the splitting members are not all in pencils of pairs (two levels): the
    # decomposition says it is not certified instead of returning a partial list as complete
    e = np.eye(5)
    F = [_product(e[i], e[i] - e[i + 1]) for i in range(4)]
    x = np.random.default_rng(0).standard_normal((4, 4))
    dec = quadratic_cone([sum(x[i, j] * F[j] for j in range(4)) for i in range(4)])
    assert not dec.exact and "dimension" in dec.reason
    assert quadratic_cone(F).exact and len(quadratic_cone(F).subspaces) == 5


def test_quadratic_cone_flags_what_it_cannot_certify():
    from nonmin.linear._cone import quadratic_cone

    # a curved cone x² + y² = z²: no linear subspace, not a union of lines: not certified
    dec = quadratic_cone([np.diag([1.0, 1.0, -1.0])])
    assert not dec.exact and dec.subspaces == () and "dimension 3" in dec.reason
    # definite: only 0, certified; semidefinite: its kernel; zero: the whole space
    assert quadratic_cone([np.diag([1.0, 2.0, 3.0])]) == quadratic_cone([np.eye(3)])
    assert quadratic_cone([np.eye(3)]).exact and quadratic_cone([np.eye(3)]).subspaces == ()
    (K,) = quadratic_cone([np.diag([1.0, 0.0, 2.0])]).subspaces
    assert K.shape == (3, 1) and abs(abs(K[1, 0]) - 1.0) <= 1e-15
    (W,) = quadratic_cone([np.zeros((3, 3))]).subspaces
    assert W.shape == (3, 3)
    # two planes x·y = 0 in R³ (a plane pair, not lines)
    dec = quadratic_cone([_product(np.eye(3)[0], np.eye(3)[1])])
    assert dec.exact and sorted(B.shape[1] for B in dec.subspaces) == [2, 2]
