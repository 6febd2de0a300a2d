"""A planar four-bar built twice — with the planar builder (x, y, θ) and with the spatial
builder (unit quaternions, revolute joints about z, three redundant rows) — gives the same
energies and the same accelerations through nonmin's core."""

from __future__ import annotations

import numpy as np
import pytest

from nonmin.core import solve_dynamics
from nonmin.model import assemble
from nonmin.model.planar import PlanarBuilder
from nonmin.model.spatial import G_matrix, SpatialBuilder

AGREE = 1e-9
BARS = (("crank", 1.0, 1.0), ("coupler", 2.0, 2.2), ("rocker", 1.5, 1.6))
D = 2.0
G = 9.81
#: Spatial rank tolerance: the three extra rows of a planar loop in 3D are exactly dependent.
RANK_RTOL = 1e-8


def _planar():
    b = PlanarBuilder("fourbar_planar", gravity=(0.0, -G))
    for name, m, L in BARS:
        b.body(name, mass=m, inertia=m * L**2 / 12)
    L1, L2, L3 = (L for _, _, L in BARS)
    b.revolute("O", ("ground", (0.0, 0.0)), ("crank", (-L1 / 2, 0.0)))
    b.revolute("A", ("crank", (L1 / 2, 0.0)), ("coupler", (-L2 / 2, 0.0)))
    b.revolute("B", ("coupler", (L2 / 2, 0.0)), ("rocker", (L3 / 2, 0.0)))
    b.revolute("D", ("ground", (D, 0.0)), ("rocker", (-L3 / 2, 0.0)))
    return b.build()


def _spatial_from(q_planar):
    """The same bars, posed as in the planar configuration (rotation θ about z)."""
    b = SpatialBuilder("fourbar_spatial", gravity=(0.0, -G, 0.0))
    ends = {}
    for i, (name, m, L) in enumerate(BARS):
        x, y, th = q_planar[3 * i : 3 * i + 3]
        b.add_body(
            name,
            mass=m,
            inertia=[0.01 * m, m * L**2 / 12, m * L**2 / 12],
            position=[x, y, 0.0],
            quaternion=[np.cos(th / 2), 0.0, 0.0, np.sin(th / 2)],
        )
        u = np.array([np.cos(th), np.sin(th), 0.0])
        ends[name] = (np.array([x, y, 0.0]) - L / 2 * u, np.array([x, y, 0.0]) + L / 2 * u)
    z = [0.0, 0.0, 1.0]
    b.add_revolute("O", "ground", "crank", point=ends["crank"][0], axis=z)
    b.add_revolute("A", "crank", "coupler", point=ends["crank"][1], axis=z)
    b.add_revolute("B", "coupler", "rocker", point=ends["coupler"][1], axis=z)
    b.add_revolute("D", "ground", "rocker", point=ends["rocker"][0], axis=z)
    return b.build()


def _to_spatial_velocity(q_planar, qd_planar):
    qd = []
    for i in range(3):
        th = q_planar[3 * i + 2]
        xd, yd, thd = qd_planar[3 * i : 3 * i + 3]
        e = np.array([np.cos(th / 2), 0.0, 0.0, np.sin(th / 2)])
        qd += [xd, yd, 0.0, *(0.5 * G_matrix(e).T @ [0.0, 0.0, thd])]
    return np.array(qd)


@pytest.mark.parametrize("crank_angle, crank_rate", [(1.2, 0.0), (2.0, 3.0), (-0.7, -1.5)])
def test_fourbar_planar_vs_spatial(crank_angle: float, crank_rate: float) -> None:
    planar = _planar()
    L1 = BARS[0][2]
    # guess: crank at the given angle, then assemble (crank coordinates kept)
    c, s = np.cos(crank_angle), np.sin(crank_angle)
    guess = np.array([L1 / 2 * c, L1 / 2 * s, crank_angle, 1.5, 1.0, 0.0, 2.0, 0.8, 1.5])
    qd_guess = np.zeros(9)
    qd_guess[:3] = [-L1 / 2 * s * crank_rate, L1 / 2 * c * crank_rate, crank_rate]
    st = assemble(planar, guess, qd_guess, fixed=[0, 1, 2])
    q_p, qd_p = st.q, st.qd

    spatial = _spatial_from(q_p)
    q_s = spatial.reference_configuration()
    qd_s = _to_spatial_velocity(q_p, qd_p)
    ct = spatial.constraint_terms(0.0, q_s, qd_s)
    np.testing.assert_allclose(ct.phi, 0.0, atol=1e-10)
    np.testing.assert_allclose(ct.velocity, 0.0, atol=1e-10)
    assert spatial.energy(q_s, qd_s) == pytest.approx(planar.energy(q_p, qd_p), abs=AGREE)
    assert spatial.potential_energy(q_s) == pytest.approx(planar.potential_energy(q_p), abs=AGREE)

    ev_p = planar.evaluate(0.0, q_p, qd_p)
    qdd_p = solve_dynamics(ev_p.M, ev_p.h, ev_p.constraints.A, ev_p.constraints.gamma).qdd
    ev_s = spatial.evaluate(0.0, q_s, qd_s)
    sol = solve_dynamics(
        ev_s.M, ev_s.h, ev_s.constraints.A, ev_s.constraints.gamma, rtol=RANK_RTOL
    )
    assert spatial.n - int(sol.rank) == 1  # 23 rows, rank 20: mobility 1
    for i in range(3):
        o = 7 * i
        e = q_s[o + 3 : o + 7]
        w_dot = 2.0 * G_matrix(e) @ sol.qdd[o + 3 : o + 7]  # ω̇' = 2 G ε̈ (since Ġ ε̇ = 0)
        np.testing.assert_allclose(sol.qdd[o : o + 3], [*qdd_p[3 * i : 3 * i + 2], 0.0], atol=AGREE)
        np.testing.assert_allclose(w_dot, [0.0, 0.0, qdd_p[3 * i + 2]], atol=AGREE)
