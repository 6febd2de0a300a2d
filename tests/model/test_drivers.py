"""Drivers (rheonomic constraints) of every builder, with time functions evaluated by the engine.

References: closed forms (slider-crank kinematics, law of cosines), the NumPy/Python
evaluation of the same model (``Model._solve_one``: Python ``evaluate``), SciPy's spline
derivatives, SymPy's derivatives, and the inverse dynamics of the undriven mechanism.
"""

from __future__ import annotations

import numpy as np
import pytest

import nonmin
from nonmin.errors import InputError, ModelError
from nonmin.model import Expression, Polynomial, Sampled, Spline, assemble
from nonmin.model.planar import PlanarBuilder

R_CRANK, L_ROD = 0.3, 1.0


# --------------------------------------------------------------------------- time functions
def test_time_functions_and_their_engine_twins() -> None:
    from scipy.interpolate import CubicSpline

    ts = np.linspace(-0.5, 3.5, 23)
    knots = np.array([0.0, 0.7, 1.5, 2.2, 3.0])
    vals = np.array([0.0, 0.4, -0.2, 0.9, 1.0])
    cs = CubicSpline(knots, vals)
    cases = [
        (
            Polynomial([0.2, 1.5, -0.3, 0.05]),
            lambda t: (
                0.2 + 1.5 * t - 0.3 * t**2 + 0.05 * t**3,
                1.5 - 0.6 * t + 0.15 * t**2,
                -0.6 + 0.3 * t,
            ),
        ),
        (Spline(knots, vals), lambda t: (cs(t), cs(t, 1), cs(t, 2))),
    ]
    _check(cases, ts)
    # a sampled array is held outside its samples (rates 0)
    s = Sampled([0.0, 1.0, 4.0, 9.0], dt=0.5)
    assert s(2.0) == (9.0, 0.0, 0.0) and s.engine()(2.0) == (9.0, 0.0, 0.0)
    np.testing.assert_allclose(s.engine()(0.75), s(0.75), rtol=1e-14)
    with pytest.raises(InputError):
        Spline([0.0, 1.0, 1.0], [0, 1, 2])
    with pytest.raises(InputError):
        Sampled([1.0, 2.0])


def _check(cases, ts) -> None:
    for fn, ref in cases:
        eng = fn.engine()
        for t in ts:
            want = np.array(ref(t), dtype=float)
            np.testing.assert_allclose(fn(t), want, rtol=1e-12, atol=1e-12)
            np.testing.assert_allclose(eng(t), want, rtol=1e-12, atol=1e-12)


def test_expression_derivatives_are_exact() -> None:
    """SymPy's derivatives, compiled to a tape, against the hand-derived closed form."""
    expr = Expression("0.3*sin(2*pi*t) + t**2/2")
    ref = lambda t: (  # noqa: E731
        0.3 * np.sin(2 * np.pi * t) + t * t / 2,
        0.6 * np.pi * np.cos(2 * np.pi * t) + t,
        -1.2 * np.pi**2 * np.sin(2 * np.pi * t) + 1.0,
    )
    _check([(expr, ref)], np.linspace(-0.5, 3.5, 23))
    with pytest.raises(InputError):
        Expression("sin(u*t)")


# --------------------------------------------------------------------------- planar slider-crank
def _slider_crank(drive=None, *, driven=True, motor=False):
    b = PlanarBuilder("slider_crank")
    b.body(
        "crank",
        mass=1.0,
        inertia=R_CRANK**2 / 12,
        points={"c0": (-R_CRANK / 2, 0.0), "c1": (R_CRANK / 2, 0.0)},
    )
    b.body(
        "rod",
        mass=2.0,
        inertia=2.0 * L_ROD**2 / 12,
        points={"r0": (-L_ROD / 2, 0.0), "r1": (L_ROD / 2, 0.0)},
    )
    b.point_mass("slider", mass=0.5, points=["s"])
    b.revolute("O", ("ground", (0.0, 0.0)), "c0")
    b.revolute("A", "c1", "r0")
    b.revolute("B", "r1", "s")
    b.point_on_line("guide", ("ground", (0.0, 0.0)), "s", axis=(1.0, 0.0))
    if driven:
        b.drive_angle("drive", "crank", profile=drive)
    if motor:
        b.actuator("motor", "O")
    m = b.build()
    return m


def _slider_x(theta):
    return R_CRANK * np.cos(theta) + np.sqrt(L_ROD**2 - (R_CRANK * np.sin(theta)) ** 2)


def _crank_state(m, theta):
    c, s = np.cos(theta), np.sin(theta)
    p1 = R_CRANK * np.array([c, s])
    xs = _slider_x(theta)
    rod_ang = np.arctan2(-p1[1], xs - p1[0])
    q = [p1[0] / 2, p1[1] / 2, theta, (p1[0] + xs) / 2, p1[1] / 2, rod_ang, xs, 0.0]
    return assemble(m, q)


@pytest.mark.parametrize("kind", ["polynomial", "spline", "expression"])
def test_driven_crank_slider_position_matches_closed_form(kind) -> None:
    theta = {
        "polynomial": Polynomial([0.3, 4.0]),
        "spline": Spline([0.0, 0.5, 1.0, 1.5], [0.3, 1.5, 2.2, 4.0], bc_type="natural"),
        "expression": Expression("0.3 + 4*t + 0.5*sin(3*t)"),
    }[kind]
    m = _slider_crank(theta)
    st = _crank_state(m, theta(0.0)[0])
    traj = nonmin.simulate(m, 1.5, st, dt=1e-3, t_eval=np.linspace(0.0, 1.5, 31))
    th = np.array([theta(t)[0] for t in traj.t])
    np.testing.assert_allclose(traj.q[:, 2], th, atol=1e-9)  # the crank follows f(t)
    np.testing.assert_allclose(traj.q[:, 6], _slider_x(th), atol=1e-9)
    # slider velocity: d/dt x(θ(t)) = x'(θ) θ̇
    thd = np.array([theta(t)[1] for t in traj.t])
    dx = -R_CRANK * np.sin(th) - R_CRANK**2 * np.sin(th) * np.cos(th) / np.sqrt(
        L_ROD**2 - (R_CRANK * np.sin(th)) ** 2
    )
    np.testing.assert_allclose(traj.qd[:, 6], dx * thd, atol=1e-8)


def test_engine_program_evaluates_drivers_like_python() -> None:
    """The compiled program (time functions as data) against the Python evaluation."""
    b = PlanarBuilder("drivers")
    b.body("bar", mass=1.0, inertia=0.1, points={"tip": (0.5, 0.0), "mid": (0.0, 0.0)})
    b.body("box", mass=2.0, inertia=0.2, points={"corner": (0.1, 0.2)})
    b.drive_coordinate("bx", "bar.x", Sampled([0.0, 0.2, 0.1, 0.4, 0.3], dt=0.25))
    b.drive_coordinate("bth", "bar.theta", Expression("sin(t)"))
    b.drive_path("path", "corner", Spline([0, 1, 2], [1.0, 1.5, 1.2]), Polynomial([0.5, 0.1, -0.2]))
    b.drive_distance("dist", "tip", ("ground", (2.0, 1.0)), Expression("1.5 + 0.2*cos(t)"))
    b.revolute("pin", "mid", ("box", (-0.3, 0.0)), active=False)
    m = b.build()
    assert m.engine_program() is not None
    assert {c.kind for c in m.constraints[:4]} == {"rheonomic"}
    rng = np.random.default_rng(0)
    for t in (0.0, 0.37, 0.9, 1.6):
        q, qd = rng.normal(size=m.n), rng.normal(size=m.n)
        py = m._solve_one(t, q, qd, m.default_active, None, 1e-10, 0)
        en = m.forward_dynamics(q, qd, t=t)
        np.testing.assert_allclose(en.qdd, py.qdd, rtol=1e-9, atol=1e-9)
    # velocity residual A q̇ + φ_t of a trajectory that follows the motions is zero
    st = assemble(m, np.zeros(m.n) + 0.1, t=0.0)
    traj = nonmin.simulate(m, 1.0, st, dt=1e-3, t_eval=[0.0, 0.5, 1.0])
    assert traj.velocity_residual_norm.max() < 1e-9
    x = Sampled([0.0, 0.2, 0.1, 0.4, 0.3], dt=0.25)
    np.testing.assert_allclose(traj.q[:, 0], [x(t)[0] for t in traj.t], atol=1e-9)
    np.testing.assert_allclose(traj.q[:, 2], np.sin(traj.t), atol=1e-9)
    ct = m.constraint_terms(1.0, traj.q[-1], traj.qd[-1])
    assert np.abs(ct.phi).max() < 1e-9 and np.abs(ct.velocity).max() < 1e-8


def test_distance_driver_lifts_a_boom_by_the_law_of_cosines() -> None:
    a, s = 1.0, 0.6  # cylinder base on the ground at (a, 0), attached at s along the boom
    b = PlanarBuilder("boom")
    b.body("boom", mass=3.0, inertia=3.0 / 12, points={"root": (-0.5, 0.0), "lug": (s - 0.5, 0.0)})
    b.revolute("hinge", ("ground", (0.0, 0.0)), "root")
    length = Expression("0.7 + 0.3*t")
    b.drive_distance("cylinder", ("ground", (a, 0.0)), "lug", length)
    m = b.build()
    th0 = np.arccos((a * a + s * s - 0.7**2) / (2 * a * s))
    st = assemble(m, [0.5 * np.cos(th0), 0.5 * np.sin(th0), th0])
    traj = nonmin.simulate(m, 1.0, st, dt=1e-3, t_eval=np.linspace(0, 1, 11))
    L = 0.7 + 0.3 * traj.t
    np.testing.assert_allclose(
        traj.q[:, 2], np.arccos((a * a + s * s - L**2) / (2 * a * s)), atol=1e-9
    )


def test_driver_torque_equals_inverse_dynamics_of_the_undriven_crank() -> None:
    theta = Expression("0.3 + 4*t + 0.5*sin(3*t)")
    m = _slider_crank(theta)
    st = _crank_state(m, theta(0.0)[0])
    traj = nonmin.simulate(m, 1.0, st, dt=1e-3, t_eval=np.linspace(0, 1, 501)).with_reactions(
        m, ["drive"]
    )
    lam = traj.reactions["drive"].multipliers[:, 0]  # A = e_θ(crank): the torque on the crank
    free = _slider_crank(driven=False, motor=True)
    for i in range(0, len(traj), 25):
        res = nonmin.inverse_dynamics(free, traj.q[i], traj.qd[i], traj.qdd[i])
        assert res.ok, res.message
        assert abs(res.u[0] - lam[i]) < 1e-7 * max(1.0, abs(lam[i]))
    # and the computed torque, applied to the undriven crank, reproduces the motion
    from scipy.interpolate import CubicSpline

    u_of_t = CubicSpline(traj.t, lam)

    class Motor:
        def __call__(self, t, q, qd, state=None, active=None):
            return np.array([float(u_of_t(t))])

    fwd = nonmin.simulate(
        free, 1.0, traj.q[0], traj.qd[0], dt=1e-3, controller=Motor(), t_eval=traj.t
    )
    assert np.abs(fwd.q[:, 2] - traj.q[:, 2]).max() < 1e-6


def test_builder_driver_errors_are_typed() -> None:
    b = PlanarBuilder("e")
    b.body("bar", mass=1.0, inertia=0.1)
    with pytest.raises(InputError, match="coordinate"):
        b.drive_coordinate("d", "bar.z", 0.0)
    with pytest.raises(InputError, match="prescribed motion"):
        b.drive_coordinate("d", "bar.x", object())
    with pytest.raises(ModelError, match="> 0"):
        b.drive_distance("d", ("bar", (0, 0)), ("ground", (0, 0)), 0.0)


# --------------------------------------------------------------------------- spatial
def _spatial_driven():
    from nonmin.model.spatial import SpatialBuilder

    l = 0.6
    b = SpatialBuilder("spatial_drivers")
    b.add_body("bob", mass=1.0, inertia=[0.01, 0.01, 0.01], position=[l, 0.0, 0.0])
    b.add_revolute("hinge", "ground", "bob", point=[0.0, 0.0, 0.0], axis=[0.0, 1.0, 0.0])
    b.add_coordinate_driver("drive_x", "bob", "x", Expression("0.6*cos(0.4*t)"))
    b.add_body("box", mass=2.0, inertia=[0.02, 0.03, 0.04], position=[0.0, 2.0, 0.0])
    b.add_path_driver(
        "path",
        "box",
        point=[0.1, 2.0, 0.0],
        x=Polynomial([0.1, 0.2]),
        y=Spline([0, 1, 2], [2.0, 2.1, 1.9]),
        z=Expression("0.1*sin(t)"),
    )
    b.add_body("ball", mass=0.5, inertia=[0.001, 0.001, 0.001], position=[0.0, -1.0, -1.0])
    b.add_spherical("socket", "ground", "ball", point=[0.0, -1.0, 0.0])
    b.add_distance_driver(
        "rope",
        "ground",
        "ball",
        point_a=[0.5, -1.0, 0.0],
        point_b=[0.0, -1.0, -1.0],
        motion=Expression("sqrt(1.25) - 0.1*t"),
    )
    # an arm turned about the world z axis through (0, 3, 0) by its joint angle θ(t)
    b.add_body("arm", mass=1.5, inertia=[0.01, 0.05, 0.05], position=[0.5, 3.0, 0.0])
    b.add_revolute("shoulder", "ground", "arm", point=[0.0, 3.0, 0.0], axis=[0.0, 0.0, 1.0])
    b.add_angle_driver("turn", "shoulder", Expression("0.8*t + 0.3*sin(2*t)"))
    # a slider on a rail along (1, 1, 0)/√2 through (0, −3, 0), pushed by its slide s(t)
    b.add_body("slider", mass=0.7, inertia=[0.01, 0.01, 0.01], position=[0.0, -3.0, 0.0])
    b.add_prismatic("rail", "ground", "slider", point=[0.0, -3.0, 0.0], axis=[1.0, 1.0, 0.0])
    b.add_slide_driver("push", "rail", Polynomial([0.0, 0.5, 0.25]))
    return b.build()


def test_spatial_drivers_engine_matches_python_and_follow_their_motions() -> None:
    m = _spatial_driven()
    kinds = {c.name: c.kind for c in m.constraints}
    assert {kinds[k] for k in ("drive_x", "path", "rope", "turn", "push")} == {"rheonomic"}
    rng = np.random.default_rng(1)
    q0 = m.reference_configuration()
    for t in (0.0, 0.4, 1.3):
        q = q0 + 0.05 * rng.normal(size=m.n)
        qd = rng.normal(size=m.n)
        py = m._solve_one(t, q, qd, m.default_active, None, 1e-10, 0)
        en = m.forward_dynamics(q, qd, t=t)
        np.testing.assert_allclose(en.qdd, py.qdd, rtol=1e-9, atol=1e-9)
    st = assemble(m, q0, t=0.0)
    traj = nonmin.simulate(m, 1.5, st, dt=1e-3, t_eval=np.linspace(0, 1.5, 16))
    t = traj.t
    np.testing.assert_allclose(traj.q[:, 0], 0.6 * np.cos(0.4 * t), atol=1e-9)  # bob x
    # the hinge keeps the bob at 0.6 from the axis: z = −0.6 sin(0.4 t)
    np.testing.assert_allclose(traj.q[:, 2], -0.6 * np.sin(0.4 * t), atol=1e-8)
    box = m.body_index("box")
    p = np.array([m.point_position(q, "box", [0.1, 0.0, 0.0]) for q in traj.q])
    y = Spline([0, 1, 2], [2.0, 2.1, 1.9])
    np.testing.assert_allclose(p[:, 0], 0.1 + 0.2 * t, atol=1e-9)
    np.testing.assert_allclose(p[:, 1], [y(tt)[0] for tt in t], atol=1e-9)
    np.testing.assert_allclose(p[:, 2], 0.1 * np.sin(t), atol=1e-9)
    ball = m.body_index("ball")
    d = traj.q[:, 7 * ball : 7 * ball + 3] - np.array([0.5, -1.0, 0.0])
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), np.sqrt(1.25) - 0.1 * t, atol=1e-9)
    assert box >= 0 and traj.velocity_residual_norm.max() < 1e-8
    arm = m.body_index("arm")
    th = 0.8 * t + 0.3 * np.sin(2 * t)
    want = np.stack([0.5 * np.cos(th), 3.0 + 0.5 * np.sin(th)], -1)
    np.testing.assert_allclose(traj.q[:, 7 * arm : 7 * arm + 2], want, atol=1e-9)
    sl = m.body_index("slider")
    s = 0.5 * t + 0.25 * t * t
    want = np.stack([s / np.sqrt(2), -3.0 + s / np.sqrt(2), 0 * s], -1)
    np.testing.assert_allclose(traj.q[:, 7 * sl : 7 * sl + 3], want, atol=1e-9)


# --------------------------------------------------------------------------- robots
def test_driven_robot_joint_and_its_torque() -> None:
    pytest.importorskip("pinocchio")
    from nonmin.model.robots import JointDriver
    from nonmin.model.robots._examples import fourbar

    free, st0 = fourbar("planar_point")
    motion = Expression("-1.2 + 1.5*t + 0.2*sin(4*t)")
    driven = free.replace(
        robot_constraints=(*free.robot_constraints, JointDriver("drive", "crank", motion))
    )
    assert driven.constraint("drive").kind == "rheonomic"
    rng = np.random.default_rng(2)
    for t in (0.0, 0.7):  # engine program vs Pinocchio (Python) evaluation
        q = st0.q + 0.1 * rng.normal(size=driven.n)
        qd = rng.normal(size=driven.n)
        a = driven.evaluate(t, q, qd)
        b = driven._evaluate_pinocchio(t, q, qd, driven.default_active)
        for x, y in zip(a.constraints[:4], b.constraints[:4], strict=True):
            np.testing.assert_allclose(x, y, rtol=1e-10, atol=1e-10)
    st = assemble(driven, st0.q, t=0.0)
    traj = nonmin.simulate(driven, 1.0, st, dt=1e-3, t_eval=np.linspace(0, 1, 11)).with_reactions(
        driven, ["drive"]
    )
    i = driven.coordinate_names.index("crank")
    np.testing.assert_allclose(traj.q[:, i], [motion(t)[0] for t in traj.t], atol=1e-9)
    lam = traj.reactions["drive"].multipliers[:, 0]
    for k in range(len(traj)):
        res = nonmin.inverse_dynamics(free, traj.q[k], traj.qd[k], traj.qdd[k])
        assert res.ok, res.message
        assert abs(res.u[0] - lam[k]) < 1e-7 * max(1.0, abs(lam[k]))


def test_time_functions_pickle() -> None:
    import pickle

    for fn in (
        Polynomial([1.0, 2.0]),
        Spline([0, 1, 2], [0.0, 1.0, 0.5]),
        Expression("exp(-t)*cos(t)"),
    ):
        fn.engine()
        back = pickle.loads(pickle.dumps(fn))
        np.testing.assert_allclose(back(0.3), fn(0.3), rtol=1e-14)
        np.testing.assert_allclose(back.engine()(0.3), fn(0.3), rtol=1e-14)


def test_engine_loop_and_python_driver_agree_on_driven_models() -> None:
    theta = Expression("0.3 + 4*t + 0.5*sin(3*t)")
    planar = _slider_crank(theta)
    spatial = _spatial_driven()
    te = np.linspace(0, 0.2, 5)
    for m, st in (
        (planar, _crank_state(planar, 0.3)),
        (spatial, assemble(spatial, spatial.reference_configuration())),
    ):
        a = nonmin.simulate(m, 0.2, st, dt=2e-3, t_eval=te, engine="engine")
        b = nonmin.simulate(m, 0.2, st, dt=2e-3, t_eval=te, engine="python")
        np.testing.assert_allclose(a.q, b.q, atol=1e-10)
        np.testing.assert_allclose(a.f_c, b.f_c, atol=1e-8 * max(1.0, np.abs(b.f_c).max()))


def test_planar_slide_driver_pushes_a_cart_along_a_tilted_rail() -> None:
    b = PlanarBuilder("cart")
    b.body("cart", mass=2.0, inertia=0.1, points={"c": (0.0, 0.0)})
    b.body("pole", mass=0.5, inertia=0.05, points={"top": (0.0, 0.4), "mid": (0.0, 0.0)})
    axis = (np.cos(0.5), np.sin(0.5))
    b.prismatic("rail", ("ground", (0.0, 0.0)), "c", axis=axis)
    b.revolute("hinge", "c", "top")
    push = Spline([0.0, 0.5, 1.0], [0.0, 0.3, 0.2], bc_type="clamped")
    b.drive_slide("push", "rail", push)
    m = b.build()
    st = assemble(m, [0.0, 0.0, 0.0, 0.0, -0.4, 0.0])
    rng = np.random.default_rng(3)
    for t in (0.1, 0.7):  # engine program = Python evaluation
        q, qd = st.q + 0.1 * rng.normal(size=m.n), rng.normal(size=m.n)
        py = m._solve_one(t, q, qd, m.default_active, None, 1e-10, 0)
        np.testing.assert_allclose(m.forward_dynamics(q, qd, t=t).qdd, py.qdd, rtol=1e-9, atol=1e-9)
    traj = nonmin.simulate(m, 1.0, st, dt=1e-3, t_eval=np.linspace(0, 1, 11))
    s = np.array([push(t)[0] for t in traj.t])
    np.testing.assert_allclose(traj.q[:, :2], np.outer(s, axis), atol=1e-9)
    r = traj.with_reactions(m, ["push"]).reactions["push"]
    assert r.kind == "planar" and r.body_b == "cart" and r.determined.all()
