"""Assembly of consistent initial states (Gauss–Newton in the mass metric, velocity projection)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from nonmin.core import impact_map
from nonmin.errors import AssemblyError, UnknownNameError
from nonmin.library import a02_n_four_bar, crossed_four_bar, n_four_bar_reference
from nonmin.model import assemble, assembly_residual, consistent
from nonmin.model.planar import PlanarBuilder

TOL = 1e-10


def test_assemble_n_four_bar_from_perturbed_guess():
    mech = a02_n_four_bar(N=2)
    m = mech.model
    rng = np.random.default_rng(0)
    q_guess = mech.state.q + 0.05 * rng.standard_normal(m.n)
    qd_guess = mech.state.qd + 0.3 * rng.standard_normal(m.n)
    s = assemble(m, q_guess, qd_guess, tol=1e-12)
    r = assembly_residual(m, s)
    assert r.position <= 1e-12 and r.velocity <= 1e-12
    assert consistent(m, s)
    assert not consistent(m, m.state(q_guess, qd_guess))
    # the velocity step is the mass-orthogonal projection (= plastic impact map) at the new q
    A = m.constraint_jacobian(0.0, s.q)
    np.testing.assert_allclose(s.qd, impact_map(m.mass_matrix(s.q), A, qd_guess), atol=1e-12)


def test_assemble_stays_on_the_nearby_branch_and_keeps_fixed_coordinates():
    mech = crossed_four_bar()
    m = mech.model
    q_guess = mech.state.q.copy()
    q_guess[2] += 0.1  # crank angle moved: keep it fixed, the rest follows on the same branch
    s = assemble(m, q_guess, fixed=["crank.theta"])
    assert s.q[2] == q_guess[2]
    assert abs(float(m.outputs(0, s.q, s.qd)["anti_branch_residual"])) < 1e-9
    assert consistent(m, s)


def test_assemble_keeps_fixed_velocity():
    mech = a02_n_four_bar(N=1)
    m = mech.model
    qd_guess = np.zeros(m.n)
    qd_guess[2] = -2.0  # crank0 rate
    s = assemble(m, mech.state.q, qd_guess, fixed=[2])
    assert s.qd[2] == -2.0
    ref = n_four_bar_reference([0.0], N=1)
    np.testing.assert_allclose(s.qd, 2.0 * ref["qd"][0], atol=1e-12)


def test_rheonomic_particular_solution():
    b = PlanarBuilder("driven")
    b.body("bar", mass=1.0, inertia=1 / 12)
    b.revolute("pivot", ("ground", (0.0, 0.0)), ("bar", (-0.5, 0.0)))
    b.drive_angle("drive", "bar", start=0.2, speed=3.0)
    m = b.build()
    t = 0.4
    s = assemble(m, [0.3, 0.3, 1.0], t=t)
    th = 0.2 + 3.0 * t
    np.testing.assert_allclose(s.q, [0.5 * math.cos(th), 0.5 * math.sin(th), th], atol=1e-12)
    np.testing.assert_allclose(s.qd, 3.0 * np.array([-0.5 * math.sin(th), 0.5 * math.cos(th), 1.0]), atol=1e-12)
    assert assembly_residual(m, s).velocity <= 1e-12


def test_point_mass_and_singular_configuration():
    """Assembly of the A02 mechanism at its singular (horizontal) configuration."""
    mech = a02_n_four_bar(N=2)
    ref = n_four_bar_reference([0.71435553], N=2)
    s = assemble(mech.model, ref["q"][0] + 1e-3, ref["qd"][0])
    assert consistent(mech.model, s)


def test_impossible_assembly_raises_with_residual():
    b = PlanarBuilder("impossible")
    b.body("bar", mass=1.0, inertia=1.0)
    b.revolute("left", ("ground", (0.0, 0.0)), ("bar", (-0.5, 0.0)))
    b.revolute("right", ("ground", (3.0, 0.0)), ("bar", (0.5, 0.0)))  # 3 m apart, bar 1 m long
    m = b.build()
    with pytest.raises(AssemblyError, match=r"‖φ‖∞ = 1\.0"):
        assemble(m, [1.5, 0.0, 0.0])


def test_inconsistent_fixed_velocity_raises():
    mech = a02_n_four_bar(N=1)
    qd = np.zeros(mech.model.n)
    qd[0] = 1.0  # crank0 x-velocity and crank0 y-velocity both fixed: y must be 0 and x≠0 at θ=π/2 is fine,
    qd[2] = 0.0  # but ω = 0 with ẋ = 1 is impossible
    with pytest.raises(AssemblyError, match="velocity"):
        assemble(mech.model, mech.state.q, qd, fixed=[0, 2])


def test_unknown_fixed_name():
    mech = a02_n_four_bar(N=1)
    with pytest.raises(UnknownNameError):
        assemble(mech.model, mech.state.q, fixed=["nope"])


def test_inactive_unilateral_penetration_is_reported():
    b = PlanarBuilder("wall")
    b.point_mass("p", mass=1.0, points=["P"])
    b.point_on_line("wall", ("ground", (1.0, 0.0)), "P", axis=(0.0, 1.0), unilateral=True)
    m = b.build()
    s = m.state([1.2, 0.0])  # 0.2 m behind the wall (gap = 1 − x < 0)
    r = assembly_residual(m, s)
    assert r.penetration == pytest.approx(0.2)
    assert not consistent(m, s)
    s_on = assemble(m, [1.2, 0.3], active=["wall"])
    np.testing.assert_allclose(s_on.q, [1.0, 0.3], atol=1e-12)


def test_mass_matrix_singular_off_the_nullspace():
    """M = diag(1, 1, 0) is singular, but positive definite on N(A) for A = [0, 0, 1] (+ a circle)."""
    from nonmin.model import FunctionConstraint, FunctionModel

    circle = FunctionConstraint.holonomic(
        "circle", phi=lambda q: [0.5 * (q[0] ** 2 + q[1] ** 2 - 1.0)], jacobian=lambda q: [[q[0], q[1], 0.0]],
        adot_qd=lambda q, v: [v[0] ** 2 + v[1] ** 2])
    plane = FunctionConstraint.holonomic(
        "plane", phi=lambda q: [q[2]], jacobian=lambda q: [[0.0, 0.0, 1.0]], adot_qd=lambda q, v: [0.0])
    m = FunctionModel("massless_z", ["x", "y", "z"], mass=lambda q: np.diag([1.0, 1.0, 0.0]),
                      coriolis=lambda q, v: np.zeros((3, 3)), conservative=lambda q: np.zeros(3),
                      potential=lambda q: 0.0, constraints=[circle, plane])
    s = assemble(m, [0.9, 0.3, 0.2], [1.0, 1.0, 1.0])
    assert consistent(m, s, tol=1e-12)
    assert s.q[2] == pytest.approx(0.0, abs=1e-14) and abs(np.hypot(s.q[0], s.q[1]) - 1) < 1e-12


def test_function_model_names_and_callables_are_checked() -> None:
    """coordinate_names ("x", "x") was accepted (q0.x, CSV columns and plots then clash), and a
    mass given as an array failed only inside simulate ('user function mass raised TypeError')."""
    import numpy as np
    import pytest

    from nonmin.errors import InputError
    from nonmin.model import FunctionModel

    fns = {"mass": lambda q: np.eye(2), "coriolis": lambda q, qd: np.zeros((2, 2)),
           "conservative": lambda q: np.zeros(2), "potential": lambda q: 0.0}  # fmt: skip
    with pytest.raises(InputError, match=r"coordinate_names must be unique.*\['x'\]"):
        FunctionModel("p", ("x", "x"), **fns)
    with pytest.raises(InputError, match="coordinate_names must be a sequence of strings"):
        FunctionModel("p", "xy", **fns)
    with pytest.raises(InputError, match="mass must be a callable, got ndarray"):
        FunctionModel("p", ("x", "y"), **{**fns, "mass": np.eye(2)})
    assert FunctionModel("p", ("x", "y"), **fns).n == 2
