"""Simultaneous impacts and the mass-metric projection onto a polyhedron (nonmin.core.impact)
against independent references: a KKT solve with multipliers over every complementary set,
closed forms, and the single-contact impact map."""

from __future__ import annotations

from itertools import combinations

import numpy as np
import pytest

from nonmin.core import impact_map, polyhedral_projection, simultaneous_impact
from nonmin.errors import InputError

TOL = 1e-12


def _kkt_reference(M, x0, Ae, re, Ai, ri):  # type: ignore[no-untyped-def]
    """The QP by its KKT conditions with multipliers (A of full row rank): every set of
    inequality rows held at equality, keep the one with λ ≥ 0 and every row feasible."""
    n = len(x0)
    for size in range(Ai.shape[0] + 1):
        for W in combinations(range(Ai.shape[0]), size):
            A = np.vstack((Ae, Ai[list(W)]))
            r = np.concatenate((re, ri[list(W)]))
            m = A.shape[0]
            K = np.block([[M, -A.T], [A, np.zeros((m, m))]])
            sol = np.linalg.solve(K, np.concatenate((M @ x0, -r)))
            x, lam = sol[:n], sol[n:]
            if np.all(lam[len(re):] >= -1e-12) and np.all(Ai @ x + ri >= -1e-12):
                return x
    raise AssertionError("no KKT point")


def _spd(rng: np.random.Generator, n: int) -> np.ndarray:
    B = rng.standard_normal((n, n))
    return B @ B.T + n * np.eye(n)


@pytest.mark.parametrize("seed", range(12))
def test_polyhedral_projection_equals_the_kkt_solution(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = 6
    M = _spd(rng, n)
    Ae = rng.standard_normal((1, n))
    Ai = rng.standard_normal((4, n))
    x0 = rng.standard_normal(n)
    ri = rng.standard_normal(4)
    re = rng.standard_normal(1)
    got = polyhedral_projection(M, x0, Ae, re, Ai, ri)
    ref = _kkt_reference(M, x0, Ae, re, Ai, ri)
    assert np.max(np.abs(got.x - ref)) < 1e-11 * (1 + np.max(np.abs(ref)))
    assert np.all(Ai @ got.x + ri >= -1e-12)
    assert np.allclose(Ae @ got.x + re, 0.0, atol=1e-12)


def test_redundant_rows_give_the_unique_velocity() -> None:
    """A row repeated and a row that is the sum of two others (rank 2 of 4) — the KKT
    matrix is singular, the minimizer is not: it equals the projection onto the independent
    rows."""
    rng = np.random.default_rng(3)
    M = _spd(rng, 4)
    a = rng.standard_normal((2, 4))
    x0 = -(a.T @ np.array([1.0, 2.0]))  # approaches both
    Ai = np.vstack((a, a[0], a[0] + a[1]))
    ri = np.zeros(4)
    got = polyhedral_projection(M, x0, np.zeros((0, 4)), [], Ai, ri)
    ref = _kkt_reference(M, x0, np.zeros((0, 4)), np.zeros(0), a, np.zeros(2))
    assert np.max(np.abs(got.x - ref)) < TOL * 10
    assert got.at_bound.tolist() == [True, True, True, True]


def test_flat_bar_on_three_points_bounces_without_spin() -> None:
    """The issue's case at the kernel: any order of the contacts, e = 0.5 → ω = 0."""
    M = np.diag([1.0, 1.0, 1.0 / 3.0])
    A = np.array([[0.0, 1.0, -1.0], [0.0, 1.0, 0.0], [0.0, 1.0, 1.0]])
    for perm in ([0, 1, 2], [2, 0, 1], [1, 2, 0]):
        r = simultaneous_impact(M, np.zeros((0, 3)), A[perm], [0.0, -3.0, 0.0], restitution=0.5)
        assert np.max(np.abs(r.qd_plus - [0.0, 1.5, 0.0])) < TOL
        assert not r.closed.any()
    # one restitution for a set that all approaches: the impact map of the set
    v = np.array([0.3, -2.0, 0.4])
    r = simultaneous_impact(M, np.zeros((0, 3)), A, v, restitution=0.7)
    assert np.max(np.abs(r.qd_plus - impact_map(M, A, v, restitution=0.7))) < TOL


def test_bar_on_two_points_with_two_restitutions_closed_form() -> None:
    """Bar (m = 1, I = 1/3, contacts at ±1) falling flat at 1 m/s, e = 0.2 left, 0.8 right:
    Newton per contact gives u⁺ = (0.2, 0.8), so v_y⁺ = 0.5, ω⁺ = 0.3 (impulses 0.7 and 0.8,
    both compressive), and the energy loss is what the impulses do."""
    M = np.diag([1.0, 1.0, 1.0 / 3.0])
    A = np.array([[0.0, 1.0, -1.0], [0.0, 1.0, 1.0]])
    v = np.array([0.0, -1.0, 0.0])
    r = simultaneous_impact(M, np.zeros((0, 3)), A, v, restitution=[0.2, 0.8])
    assert np.max(np.abs(r.qd_plus - [0.0, 0.5, 0.3])) < TOL
    lam = np.linalg.lstsq(A.T, M @ (r.qd_plus - v), rcond=None)[0]
    assert np.allclose(lam, [0.7, 0.8], atol=TOL)
    T = lambda x: 0.5 * x @ M @ x  # noqa: E731
    # Kelvin's theorem: ΔT = Λ · (u⁻ + u⁺)/2 per contact
    assert abs((T(r.qd_plus) - T(v)) - lam @ (A @ (v + r.qd_plus)) / 2) < TOL


@pytest.mark.parametrize(("e", "expected"), [(1.0, [0.0, 1.0]), (0.0, [-0.5, 0.5])])
def test_impact_reopens_a_resting_contact(e: float, expected: list[float]) -> None:
    """A unit point mass sliding left at 1 m/s on the floor (gap y, resting: u = 0) into a 45°
    ramp (gap (x + y)/√2). With e = 1 it leaves straight up, (0, 1); plastic, it slides up
    the ramp, (−½, ½): the floor opens in both (an equality floor row would pull: impulse
    −2 with e = 1)."""
    A = np.array([[0.0, 1.0], [1.0, 1.0]]) / np.array([[1.0], [np.sqrt(2.0)]])
    r = simultaneous_impact(np.eye(2), np.zeros((0, 2)), A, [-1.0, 0.0], restitution=[0.0, e])
    assert np.max(np.abs(r.qd_plus - expected)) < TOL
    assert r.closed.tolist() == [False, e == 0.0]


def test_newtons_cradle_of_three_is_newtons_law_not_the_cradle() -> None:
    """Ball 1 at v onto balls 2–3 in contact, e = 1 at both contacts: Newton's law for the set
    gives (−v/3, 2v/3, 2v/3) (the known limit of a simultaneous Newton law: the real cradle
    needs a wave model), not the sequential answer (0, 0, v) — documented, tested."""
    A = np.array([[-1.0, 1.0, 0.0], [0.0, -1.0, 1.0]])
    r = simultaneous_impact(np.eye(3), np.zeros((0, 3)), A, [3.0, 0.0, 0.0], restitution=[1.0, 1.0])
    assert np.max(np.abs(r.qd_plus - [-1.0, 2.0, 2.0])) < TOL
    assert r.closed.tolist() == [False, True]


def test_bilateral_rows_are_kept() -> None:
    """A pendulum bob (rod: x² + y² = 1 at (1, 0): row (1, 0)) hitting a floor below it
    (gap y, falling at 1 m/s): the rod stays, the floor takes the rest (plastic: at rest)."""
    r = simultaneous_impact(np.eye(2), [[1.0, 0.0]], [[0.0, 1.0]], [0.0, -1.0], restitution=0.0)
    assert np.max(np.abs(r.qd_plus)) < TOL and r.closed.tolist() == [True]


def test_inputs_are_validated() -> None:
    with pytest.raises(InputError, match="restitution"):
        simultaneous_impact(np.eye(2), np.zeros((0, 2)), [[0.0, 1.0]], [0.0, -1.0], restitution=1.5)
    with pytest.raises(InputError, match="A_in"):
        polyhedral_projection(np.eye(2), [0.0, 0.0], np.zeros((0, 2)), [], np.ones((17, 2)), np.zeros(17))
