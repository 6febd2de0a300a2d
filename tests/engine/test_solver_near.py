"""``Solver::near`` (engine/src/core_solver.cpp) against a fresh solve.

The simulation loop solves the velocity correction and the dynamics at a projected q on the
position correction's factorization, refined to the corrected A (``Solver::near``, with ≥ 33
active rows). Here the held factorization is taken at A(q), the near solve at A(q + ε dq), and
its q̈ and f_c are compared with the NumPy specification's fresh solve at A(q + ε dq)
(``nonmin.core.dynamics._solve_dynamics_numpy``, LAPACK's SVD). Binding:
``nonmin._engine.core_solve_near`` (a test helper).
"""

from __future__ import annotations

import numpy as np
import pytest

from nonmin import _engine as E
from nonmin import library
from nonmin.core.dynamics import _solve_dynamics_numpy
from nonmin.core.linalg import DEFAULT_RTOL

OK, DECLINED = 0, 4


def _terms(mech, q, qd):
    T = mech.model.evaluate(mech.state.t, q, qd, mech.state.active)
    g = np.asarray(T.h + T.f_passive, dtype=float)
    A = np.ascontiguousarray(T.constraints.A, dtype=float)
    gam = np.ascontiguousarray(T.constraints.gamma, dtype=float)
    return np.ascontiguousarray(T.M, dtype=float), g, A, gam


def _near_case(name, kw, eps, seed=0):
    mech = library.get(name, **kw)
    q, qd = mech.state.q.copy(), mech.state.qd.copy()
    rng = np.random.default_rng(seed)
    dq = rng.standard_normal(q.shape)
    dq /= np.linalg.norm(dq)
    M, _, Ah, gh = _terms(mech, q, qd)
    M2, g2, A, gam = _terms(mech, q + eps * dq, qd)
    assert np.array_equal(M, M2)  # (constant M: the near solve takes the held call's M)
    res = E.core_solve_near(M, g2, Ah, gh, A, gam, DEFAULT_RTOL)
    ref = _solve_dynamics_numpy(M, g2, A, gam, None, None, None)
    return res, ref, A, gam


@pytest.mark.parametrize(
    ("name", "kw"),
    [("A02_n_four_bar", {"N": 40}), ("A02_n_four_bar", {"N": 2}), ("crossed_four_bar", {})],
)
@pytest.mark.parametrize("eps", [1e-9, 1e-6])
def test_near_equals_a_fresh_solve(name, kw, eps):
    res, ref, A, gam = _near_case(name, kw, eps)
    assert res["held_status"] == OK and res["held_method"] != 0 and res["held_null_space_form"]
    assert res["status"] == OK and res["rank"] == A.shape[0]
    qdd, fc = res["near"]
    scale_q = max(1.0, np.abs(ref.qdd).max())
    scale_f = max(1.0, np.abs(ref.f_c).max())
    assert np.abs(qdd - ref.qdd).max() <= 1e-12 * scale_q
    assert np.abs(fc - ref.f_c).max() <= 1e-12 * scale_f
    # the solution at the moved A, not at the held one: A q̈ + γ = 0 there to round-off
    assert np.abs(A @ qdd + gam).max() <= 1e-10 * (np.abs(A).max() * scale_q + np.abs(gam).max())
    # the second call at the same A reuses the refined basis: bitwise the first
    assert res["status_same"] == OK
    assert np.array_equal(res["near_same"], res["near"])


def test_near_declines_a_far_matrix():
    """A 1e-2 change of q moves A by far more than a projection's correction: the refinement
    passes do not reach round-off and the caller is told to factorize."""
    res, _, _, _ = _near_case("A02_n_four_bar", {"N": 40}, 1e-2)
    assert res["held_status"] == OK
    assert res["status"] == DECLINED
