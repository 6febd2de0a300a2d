"""Linearization, equilibria and modes against closed forms nobody here wrote.

* IFToMM A01 (Cartesian point pendulum, L = 1 m, g = 9.81): one mode, ω = √(g/L).
* IFToMM A02 N four-bar hanging at rest: its exact 1-DOF reduction
  ``I θ̈ = −g c cos θ`` (``I = (N+1)/3 + N``, ``c = (N+1)/2 + N``; shared/benchmarks/README.md)
  linearized about θ = −π/2 gives ω² = g c / I; at the horizontal singular configuration the
  tangent space has dimension N + 1.
"""

import math

import numpy as np
import pytest

import nonmin
from nonmin import library

#: √(9.81) rad/s, the A01 pendulum's small-oscillation frequency (issue 21).
OMEGA_A01 = 3.1320919526731650
#: Tolerance asked by the issue on that frequency.
FREQ_ATOL = 1e-10


def _a02_config(N, theta):
    """A02 configuration with every crank at angle θ from +x (the parallelogram mode)."""
    c, s = math.cos(theta), math.sin(theta)
    q = []
    for i in range(N + 1):
        q += [i + 0.5 * c, 0.5 * s, theta]
    for i in range(1, N + 1):
        q += [i - 0.5 + c, s, 0.0]
    return np.array(q)


def _a02_velocity(N, theta, omega):
    c, s = math.cos(theta), math.sin(theta)
    v = []
    for _ in range(N + 1):
        v += [-0.5 * s * omega, 0.5 * c * omega, omega]
    for _ in range(1, N + 1):
        v += [-s * omega, c * omega, 0.0]
    return np.array(v)


@pytest.mark.parametrize("x0", [1.0, -1.0])
def test_a01_pendulum_has_exactly_one_mode_at_sqrt_g_over_L(x0):
    model = library.a01_pendulum().model
    eq = nonmin.equilibrium(model, [0.3 * x0, -0.8])
    assert eq.converged
    assert np.allclose(eq.q, [0.0, -1.0], atol=1e-12)
    m = nonmin.modes(model, eq.q)
    assert m.frequencies.shape == (1,)  # no spurious modes from μ or the rod direction
    assert abs(m.frequencies[0] - OMEGA_A01) <= FREQ_ATOL
    assert abs(m.damping_ratios[0]) <= 1e-12
    assert m.stable
    assert m.system.A.shape == (2, 2)
    assert np.allclose(np.abs(m.shapes[:, 0]), [1.0, 0.0], atol=1e-12)  # horizontal swing


def test_a01_inverted_pendulum_is_one_unstable_pair():
    model = library.a01_pendulum().model
    m = nonmin.modes(model, [0.0, 1.0])
    lam = np.sort(m.eigenvalues.real)
    assert np.allclose(lam, [-OMEGA_A01, OMEGA_A01], atol=1e-10)
    assert not m.stable


@pytest.mark.parametrize("N", [1, 2, 4])
def test_a02_hanging_mode_equals_the_exact_reduction(N):
    model = library.a02_n_four_bar(N=N).model
    q_eq = _a02_config(N, -math.pi / 2)
    lin = nonmin.linearize(model, q_eq)
    assert not lin.singular and lin.tangent_dim == 1 and lin.rank == 6 * N + 2
    I = (N + 1) / 3 + N
    c = (N + 1) / 2 + N
    m = nonmin.modes(model, q_eq)
    assert m.frequencies.shape == (1,)
    assert abs(m.frequencies[0] - math.sqrt(9.81 * c / I)) <= 1e-10
    # the equilibrium search lands on it from a nearby guess
    guess = q_eq + 0.02 * np.random.default_rng(N).standard_normal(q_eq.size)
    eq = nonmin.equilibrium(model, guess)
    assert eq.converged and eq.residual <= 1e-10


@pytest.mark.parametrize("theta", [0.4, 2.0])
def test_a02_linearization_at_a_moving_state_matches_the_reduction(theta):
    """At a moving regular state (q̇ ≠ 0: the curvature term acts) the tangent-space
    linearization equals the reduced dynamics θ̈ = f(θ) = −(g c/I) cos θ written in the
    tangent chart z = Zᵀ(Q(θ) − Q(θ₀)), v = Zᵀ Q1(θ) θ̇ = s(θ) θ̇ (Q1, Q2, Q3 the first three
    θ-derivatives of the configuration Q(θ)): v̇ = G(z, v) = s1 v²/s² + s f, so
    ∂G/∂v = 2 s1 θ̇ / s and ∂G/∂z = (s2 θ̇² − 2 s1² θ̇²/s + s1 f + s f1) / s with
    s = Zᵀ Q1, s1 = Zᵀ Q2, s2 = Zᵀ Q3, f1 = df/dθ."""
    N = 2
    model = library.a02_n_four_bar(N=N).model
    omega = -1.3
    q = _a02_config(N, theta)
    Q1 = _a02_velocity(N, theta, 1.0)
    lin = nonmin.linearize(model, q, Q1 * omega)
    assert lin.tangent_dim == 1 and lin.velocity_dim == 1 and not lin.singular
    cth, sth = math.cos(theta), math.sin(theta)
    Q2 = np.zeros_like(q)
    for i in range(N + 1):
        Q2[3 * i : 3 * i + 2] = [-0.5 * cth, -0.5 * sth]
    for i in range(N):
        j = 3 * (N + 1) + 3 * i
        Q2[j : j + 2] = [-cth, -sth]
    Q3 = -Q1.copy()
    Q3[2::3] = 0.0
    Z = lin.Zq[:, 0]
    assert np.allclose(lin.Zv[:, 0], Z)
    s, s1, s2 = Z @ Q1, Z @ Q2, Z @ Q3
    kappa = 9.81 * ((N + 1) / 2 + N) / ((N + 1) / 3 + N)
    f, f1 = -kappa * cth, kappa * sth
    dG_dv = 2 * s1 * omega / s
    dG_dz = (s2 * omega**2 - 2 * s1**2 * omega**2 / s + s1 * f + s * f1) / s
    assert np.allclose(lin.A, [[0.0, 1.0], [dG_dz, dG_dv]], rtol=1e-10, atol=1e-10)
    assert np.allclose(lin.drift, [s * omega, s1 * omega**2 + s * f], rtol=1e-10, atol=1e-10)


@pytest.mark.parametrize("N", [1, 2, 3])
def test_a02_horizontal_singular_configuration_has_tangent_dimension_N_plus_1(N):
    model = library.a02_n_four_bar(N=N).model
    q = _a02_config(N, 0.0)
    lin = nonmin.linearize(model, q)
    assert lin.singular
    assert lin.tangent_dim == N + 1 and lin.rank == 5 * N + 2 and lin.generic_rank == 6 * N + 2
    assert "singular configuration" in lin.note
    # the parallelogram branch's tangent lies in the tangent space used
    branch = _a02_velocity(N, 0.0, 1.0)
    assert np.linalg.norm(branch - lin.Zq @ (lin.Zq.T @ branch)) <= 1e-12 * np.linalg.norm(branch)
    m = nonmin.modes(model, q)
    assert m.eigenvalues.size == 2 * (N + 1)
    assert np.all(np.isfinite(m.eigenvalues))


def test_linear_system_maps_and_python_control_export():
    mech = library.crossed_four_bar()
    model = mech.model
    lin = nonmin.linearize(model, mech.state.q, mech.state.qd, inputs="forces")
    n = model.n
    assert lin.B.shape == (lin.A.shape[0], n) and lin.C.shape == (2 * n, lin.A.shape[0])
    x = np.arange(1.0, lin.A.shape[0] + 1)
    dq, dqd = lin.to_dependent(x)
    assert np.allclose(lin.C @ x, np.concatenate([dq, dqd]))
    # the output velocity is admissible to first order: A(q) δq̇ + (∂A/∂q δq) q̇ = 0
    A = model.constraint_jacobian(0.0, mech.state.q)
    t = nonmin.linear.term_tangents(model, mech.state.q, mech.state.qd, dq)
    assert np.abs(A @ dqd + t["dA"][0] @ mech.state.qd).max() <= 1e-10 * (1 + np.abs(dqd).max())
    assert np.abs(A @ dq).max() <= 1e-12 * (1 + np.abs(dq).max())
    control = pytest.importorskip("control")
    ss = lin.to_control()
    assert isinstance(ss, control.StateSpace)
    assert np.allclose(ss.A, lin.A)


def test_linearize_rejects_bad_inputs():
    model = library.a01_pendulum().model
    with pytest.raises(nonmin.errors.InputError, match="inputs"):
        nonmin.linearize(model, [0.0, -1.0], inputs="torques")
    with pytest.raises(nonmin.errors.ShapeError, match="inputs"):
        nonmin.linearize(model, [0.0, -1.0], inputs=np.ones((3, 1)))
    with pytest.raises(nonmin.errors.ModelError, match="no static equilibrium"):
        nonmin.equilibrium(model, [0.5, 0.5], max_iter=1)
    assert not nonmin.equilibrium(model, [0.5, 0.5], max_iter=1, throw=False).converged


def test_mode_motion_stays_on_the_manifold_and_animates(tmp_path):
    """A01: mode 0's motion is the small swing x ≈ 0.1 cos ωt on the unit circle, with
    admissible velocities, and goes through viz.animate."""
    model = library.a01_pendulum().model
    m = nonmin.modes(model, [0.0, -1.0])
    mo = m.motion(0, amplitude=0.1, periods=2.0, samples=41)
    assert mo.q.shape == (41, 2) and mo.qd.shape == (41, 2)
    assert abs(mo.t[-1] - 2 * 2 * math.pi / OMEGA_A01) <= 1e-12
    assert np.abs(np.linalg.norm(mo.q, axis=1) - 1.0).max() <= 1e-12  # on the rod's circle
    x = mo.q[:, 0] * np.sign(m.shapes[0, 0].real)
    # the linear motion assembled onto the circle (minimal-norm): x = 0.1 cos ωt / √(1 + x²)
    assert np.abs(x - 0.1 * np.cos(OMEGA_A01 * mo.t)).max() <= 6e-4
    assert np.abs((mo.q * mo.qd).sum(axis=1)).max() <= 1e-12  # admissible velocities
    pytest.importorskip("matplotlib")
    from nonmin.viz import animate

    out = animate(mo, model, tmp_path / "mode.gif", max_frames=10, progress=False)
    assert out.exists() and out.stat().st_size > 0
    with pytest.raises(nonmin.errors.InputError, match="mode index"):
        m.motion(3)
