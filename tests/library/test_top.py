"""Spinning top (unit quaternion, spherical joint at the tip) against Euler's rigid-body
equations about the fixed point, integrated independently."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from nonmin.core import solve_dynamics
from nonmin.library.top import NAME, top_model, top_state

#: Agreement of angular velocity (rad/s, relative to the spin) and orientation after 0.5 s.
AGREE_TOL = 1e-8
T_END = 0.5


def _quat_mul(a, b):
    a0, av = a[0], a[1:]
    b0, bv = b[0], b[1:]
    return np.concatenate(([a0 * b0 - av @ bv], a0 * bv + b0 * av + np.cross(av, bv)))


def _rot(e):
    """Rotation matrix of a unit quaternion (w, x, y, z), written out independently."""
    w, x, y, z = e / np.linalg.norm(e)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def _euler_rhs(m, l, I1, I3, g):
    """Euler's equations about the tip: I_O ω̇ + ω × I_O ω = c × Rᵀ(m g), ε̇ = ½ ε ⊗ (0, ω)."""
    IO = np.diag([I1 + m * l * l, I1 + m * l * l, I3])
    c = np.array([0.0, 0.0, l])

    def f(t, y):
        e, w = y[:4], y[4:]
        F_body = _rot(e).T @ np.array([0.0, 0.0, -m * g])
        wd = np.linalg.solve(IO, np.cross(c, F_body) - np.cross(w, IO @ w))
        ed = 0.5 * _quat_mul(e, np.concatenate(([0.0], w)))
        return np.concatenate((ed, wd))

    return f


@pytest.mark.parametrize("spin, precession", [(60.0, 0.0), (20.0, 3.0)])
def test_top_matches_euler_equations(spin: float, precession: float) -> None:
    params = dict(mass=0.5, l=0.1, transverse_inertia=2.5e-3, axial_inertia=3.0e-3, g=9.81)
    model = top_model(**params, tilt=0.3)
    assert model.name == NAME and model.n == 7 and model.num_rows() == 4
    s = top_state(model, spin=spin, precession=precession)
    ct = model.constraint_terms(0.0, s.q, s.qd)
    np.testing.assert_allclose(ct.phi, 0.0, atol=1e-15)
    np.testing.assert_allclose(ct.velocity, 0.0, atol=1e-14)
    n = model.n

    def rhs(t, y):
        ev = model.evaluate(t, y[:n], y[n:])
        qdd = solve_dynamics(ev.M, ev.h, ev.constraints.A, ev.constraints.gamma).qdd
        return np.concatenate((y[n:], qdd))

    kw = dict(method="DOP853", rtol=1e-12, atol=1e-13, dense_output=True)
    sol = solve_ivp(rhs, (0.0, T_END), np.concatenate((s.q, s.qd)), **kw)
    assert sol.success
    w0 = model.angular_velocity(s.q, s.qd, "top")
    ref = solve_ivp(
        _euler_rhs(params["mass"], params["l"], params["transverse_inertia"],
                   params["axial_inertia"], params["g"]),
        (0.0, T_END), np.concatenate((s.q[3:7], w0)), **kw,
    )
    assert ref.success
    e_end = model.energy(sol.y[:n, -1], sol.y[n:, -1])
    for t in np.linspace(0.1, T_END, 5):
        y = sol.sol(t)
        r = ref.sol(t)
        w = model.angular_velocity(y[:n], y[n:], "top")
        np.testing.assert_allclose(w, r[4:], atol=AGREE_TOL * spin)
        np.testing.assert_allclose(model.rotation(y[:n], "top"), _rot(r[:4]), atol=AGREE_TOL)
        # centre of mass from the orientation alone (tip fixed at the origin)
        np.testing.assert_allclose(y[:3], _rot(r[:4]) @ [0.0, 0.0, params["l"]], atol=AGREE_TOL)
    # the top really precesses/nutates: the axis moved
    assert np.linalg.norm(sol.y[:3, -1] - sol.y[:3, 0]) > 1e-3
    assert e_end == pytest.approx(model.energy(s.q, s.qd), abs=1e-9)


def test_top_outputs_and_parameters() -> None:
    model = top_model(l=0.2, tilt=0.0)
    s = top_state(model, spin=10.0)
    out = model.outputs(0.0, s.q, s.qd)
    np.testing.assert_allclose(out["com.position"], [0, 0, 0.2], atol=1e-15)
    np.testing.assert_allclose(out["apex.position"], [0, 0, 0.4], atol=1e-15)
    np.testing.assert_allclose(out["apex.velocity"], 0.0, atol=1e-14)  # spinning upright
    np.testing.assert_allclose(model.angular_velocity(s.q, s.qd, "top"), [0, 0, 10.0], atol=1e-14)


def test_registered_in_library() -> None:
    import nonmin.library as lib
    from nonmin.model import consistent

    mech = lib.get("spinning_top", spin=25.0, precession=1.0)
    assert mech.name == "spinning_top"
    assert consistent(mech.model, mech.state)
    w = mech.model.angular_velocity(mech.state.q, mech.state.qd, "top", frame="world")
    axis = mech.model.rotation(mech.state.q, "top")[:, 2]
    assert w @ axis == pytest.approx(25.0 + np.cos(0.3) * 1.0)
