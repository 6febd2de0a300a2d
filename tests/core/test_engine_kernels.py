"""The rest of the core on the C++ engine (engine/src/core_dynamics.cpp) against NumPy.

M̄ (constraint_inertia), μ (optimal_virtual_mass), C̄ (coriolis_bar, eq. (Cbar2)), R and Γ
(actuation_projectors), S (constraint_force_projector), the impact map and the mass-metric
position correction, single and batched (with broadcasting), on every generated kind of A
(tests/core/core_testlib.py), to round-off; their typed errors raised identically.
"""

from __future__ import annotations

import numpy as np
import pytest
from core_testlib import KINDS, random_A, random_spd, singular_mass_pd_on_nullspace

from nonmin.core import (
    actuation_projectors,
    constraint_force_projector,
    constraint_inertia,
    coriolis_bar,
    impact_map,
    nullspace_projector,
    optimal_virtual_mass,
    position_correction,
    use_backend,
)
from nonmin.errors import InfeasibleActuationError, NotPositiveDefiniteError

#: Engine vs NumPy: round-off of the same formulas (different summation orders, SVD routines).
RTOL = 1e-11


def _both(fn, *args, **kw):
    with use_backend("numpy"):
        ref = fn(*args, **kw)
    with use_backend("engine"):
        got = fn(*args, **kw)
    return got, ref


def _close(a, b, scale=None, rtol=RTOL):
    a, b = np.asarray(a), np.asarray(b)
    assert a.shape == b.shape
    s = float(np.max(np.abs(b), initial=0.0)) if scale is None else scale
    return float(np.max(np.abs(a - b), initial=0.0)) <= rtol * max(s, 1e-300)


def _system(seed, kind, n=5, m=3, singular=False):
    rng = np.random.default_rng(seed)
    A, r = random_A(rng, kind, n, m)
    A = np.ascontiguousarray(A)
    M = singular_mass_pd_on_nullspace(rng, A, r) if (singular and r) else random_spd(rng, n)
    return rng, M, A, r


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("seed", range(4))
def test_engine_kernels_match_numpy(kind, seed):
    rng, M, A, _ = _system(seed, kind, n=3 + seed, m=2 + seed, singular=seed % 2 == 1)
    n, m = M.shape[0], A.shape[0]
    P, _ = nullspace_projector(A)
    mu = float(optimal_virtual_mass(M, P))
    got, ref = _both(optimal_virtual_mass, M, P)
    assert _close(got, ref)
    got, ref = _both(constraint_inertia, M, P, mu)
    assert _close(got, ref)
    got, ref = _both(constraint_force_projector, M, P, mu)
    assert _close(got, ref, scale=1.0 + float(np.max(np.abs(ref))), rtol=1e-10)
    C, Adot = rng.standard_normal((n, n)), rng.standard_normal((m, n))
    got, ref = _both(coriolis_bar, M, C, A, Adot, mu)
    assert _close(got, ref, scale=float(np.max(np.abs(ref))) + 1.0, rtol=1e-10)
    v = rng.standard_normal(n)
    for e in (0.0, 0.5):
        got, ref = _both(impact_map, M, A, v, restitution=e)
        assert _close(got, ref, scale=float(np.max(np.abs(v))))
    phi = A @ rng.standard_normal(n)
    got, ref = _both(position_correction, M, A, phi)
    ps = float(np.max(np.abs(ref))) + float(np.max(np.abs(phi), initial=0.0))
    assert _close(got, ref, scale=ps)
    got, ref = _both(position_correction, M, A, phi, mu=2.5 * mu)
    assert _close(got, ref, scale=ps, rtol=1e-10)
    B = np.hstack([np.eye(n), rng.standard_normal((n, 1))])
    got, ref = _both(actuation_projectors, B, P)
    for g_, r_ in zip(got, ref):
        assert _close(g_, r_, scale=float(np.max(np.abs(r_))) + 1.0, rtol=1e-10)


def test_engine_kernels_batched_and_broadcast():
    """A batch mixing kinds, with M shared (broadcast, stride 0) and μ per state: the batch
    equals the single calls bitwise and NumPy to round-off."""
    rng = np.random.default_rng(7)
    n, m = 5, 3
    As, Ps = [], []
    for kind in ("full", "deficient", "duplicated", "zero_rows", "all_zero", "full"):
        A, _ = random_A(rng, kind, n, m + 1 if kind == "duplicated" else m)
        A = np.vstack([A, np.zeros((max(m - A.shape[0], 0), n))])[:m]
        As.append(A)
        Ps.append(nullspace_projector(A)[0])
    A, P = np.array(As).reshape(2, 3, m, n), np.array(Ps).reshape(2, 3, n, n)
    M = random_spd(rng, n)
    mu = rng.uniform(0.5, 2.0, (2, 3))
    v = rng.standard_normal((2, 3, n))
    phi = np.einsum("...ij,...j->...i", A, rng.standard_normal((2, 3, n)))
    C, Adot = rng.standard_normal((n, n)), rng.standard_normal((2, 3, m, n))
    cases = [
        (constraint_inertia, (M, P, mu), {}),
        (optimal_virtual_mass, (M, P), {}),
        (constraint_force_projector, (M, P, mu), {}),
        (coriolis_bar, (M, C, A, Adot, mu), {}),
        (impact_map, (M, A, v), {"restitution": 0.3}),
        (position_correction, (M, A, phi), {"mu": mu}),
    ]
    for fn, args, kw in cases:
        got, ref = _both(fn, *args, **kw)
        assert _close(got, ref, scale=float(np.max(np.abs(ref))) + 1.0, rtol=1e-10), fn.__name__
        with use_backend("engine"):
            for i, j in ((0, 0), (1, 2)):
                one_args = [x[i, j] if (isinstance(x, np.ndarray) and x.ndim > 0 and x.shape[:2] == (2, 3)) else x
                            for x in args]  # fmt: skip
                one_kw = {k: (x[i, j] if isinstance(x, np.ndarray) else x) for k, x in kw.items()}
                one = fn(*one_args, **one_kw)
                assert np.array_equal(one, got[i, j]), fn.__name__


def test_engine_typed_errors_identical():
    M = np.diag([1.0, 2.0, 0.0])
    A = np.array([[1.0, 1.0, 0.0]])
    P, _ = nullspace_projector(A)
    msgs = []
    for name in ("numpy", "engine"):
        with use_backend(name):
            with pytest.raises(NotPositiveDefiniteError) as e1:
                constraint_force_projector(M, P, 1.0)
            with pytest.raises(NotPositiveDefiniteError) as e2:
                impact_map(M, A, np.ones(3))
            with pytest.raises(NotPositiveDefiniteError) as e3:
                position_correction(M, A, np.ones(1))
            with pytest.raises(InfeasibleActuationError) as e4:
                actuation_projectors(np.array([[1.0], [1.0], [0.0]]), P)
            msgs.append([str(e.value) for e in (e1, e2, e3, e4)])
    assert msgs[0] == msgs[1]
