"""Batched and single calls agree exactly (bitwise, ``np.array_equal``) for every kernel.

The batch mixes ranks (full, deficient, duplicated rows, zero rows, all-zero A) and masses
(SPD and singular off N(A)); it has two leading dimensions, and M (n, n) is also broadcast
against a batch of A.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from core_testlib import available_backends, random_A, random_spd, singular_mass_pd_on_nullspace

from nonmin.core import (
    actuation_projectors,
    baumgarte_bias,
    constraint_force,
    constraint_force_projector,
    constraint_inertia,
    coriolis_bar,
    forward_dynamics,
    impact_map,
    lambda_matrix,
    nullspace_projector,
    optimal_virtual_mass,
    position_correction,
    projector_derivative,
    pseudo_inverse,
    range_basis,
    solve_dynamics,
    use_backend,
)

N_, M_ = 5, 3
BATCH = (2, 3)
KINDS = ("full", "deficient", "duplicated", "zero_rows", "all_zero", "full")


def _fit_rows(A, m):
    """Pad with zero rows / cut to exactly m rows (keeps the kind's character)."""
    if A.shape[0] >= m:
        return A[:m]
    return np.vstack([A, np.zeros((m - A.shape[0], A.shape[1]))])


def _batch(seed: int, m: int = M_):
    rng = np.random.default_rng(seed)
    As, Ms = [], []
    for i, kind in enumerate(KINDS):
        A, _ = random_A(rng, kind, N_, m + 1 if kind == "duplicated" else m)
        A = _fit_rows(A, m)
        r = np.linalg.matrix_rank(A) if m else 0
        M = singular_mass_pd_on_nullspace(rng, A, r) if (i % 2 and r) else random_spd(rng, N_)
        As.append(A)
        Ms.append(M)
    A = np.array(As).reshape((*BATCH, m, N_))
    M = np.array(Ms).reshape((*BATCH, N_, N_))
    data = {
        "M": M,
        "A": A,
        "Adot": rng.standard_normal(A.shape),
        "C": rng.standard_normal(M.shape),
        "h": rng.standard_normal((*BATCH, N_)),
        "f": rng.standard_normal((*BATCH, N_)),
        "v": rng.standard_normal((*BATCH, N_)),
        "g": rng.standard_normal((*BATCH, m)),
        "phi": rng.standard_normal((*BATCH, m)),
        "B": rng.standard_normal((*BATCH, N_, N_ + 1)),
    }
    data["g"] = np.einsum("...mn,...n->...m", A, data["v"])  # consistent biases
    data["phi"] = np.einsum("...mn,...n->...m", A, data["h"])
    P, _ = nullspace_projector(A)
    data["P"] = P
    data["mu"] = optimal_virtual_mass(M, P)
    return data


def _kernels():
    """(name, function of a dict of inputs -> tuple of arrays)."""
    return [
        ("nullspace_projector", lambda d: nullspace_projector(d["A"])),
        ("nullspace_projector_rtol", lambda d: nullspace_projector(d["A"], rtol=1e-6)),
        ("range_basis", lambda d: tuple(range_basis(d["A"])[:-1])),
        ("pseudo_inverse", lambda d: (pseudo_inverse(d["A"]),)),
        ("lambda_matrix", lambda d: (lambda_matrix(d["A"], d["Adot"]),)),
        ("projector_derivative", lambda d: (projector_derivative(d["A"], d["Adot"]),)),
        ("constraint_inertia", lambda d: (constraint_inertia(d["M"], d["P"], d["mu"]),)),
        ("optimal_virtual_mass", lambda d: (optimal_virtual_mass(d["M"], d["P"]),)),
        ("coriolis_bar", lambda d: (coriolis_bar(d["M"], d["C"], d["A"], d["Adot"], d["mu"]),)),
        ("forward_dynamics", lambda d: (forward_dynamics(d["M"], d["h"], d["A"], d["g"], d["f"]),)),
        ("forward_dynamics_mu", lambda d: (forward_dynamics(d["M"], d["h"], d["A"], d["g"],
                                                            mu=d["mu"]),)),
        ("constraint_force", lambda d: (constraint_force(d["M"], d["h"], d["A"], d["g"], d["f"]),)),
        ("solve_dynamics", lambda d: tuple(solve_dynamics(d["M"], d["h"], d["A"], d["g"], d["f"]))),
        ("constraint_force_projector", lambda d: (constraint_force_projector(d["M"], d["P"],
                                                                             d["mu"]),)),
        ("actuation_projectors", lambda d: actuation_projectors(d["B"], d["P"])),
        ("impact_map", lambda d: (impact_map(d["M"], d["A"], d["v"]),)),
        ("impact_map_e", lambda d: (impact_map(d["M"], d["A"], d["v"], restitution=0.6),)),
        ("position_correction", lambda d: (position_correction(d["M"], d["A"], d["phi"]),)),
        ("baumgarte_bias", lambda d: (baumgarte_bias(d["g"], d["phi"], d["g"], alpha=2.0,
                                                     beta=3.0),)),
    ]


# number of trailing (core) dimensions of each input
CORE_NDIM = {"M": 2, "A": 2, "Adot": 2, "C": 2, "P": 2, "B": 2, "h": 1, "f": 1, "v": 1, "g": 1,
             "phi": 1, "mu": 0}


def _element(d, idx, broadcast=()):
    out = {}
    for k, x in d.items():
        if k in broadcast:
            out[k] = x
        else:
            out[k] = x[idx]
    return out


def _assert_batch_equals_singles(d, fn, broadcast=()):
    batched = fn(d)
    for idx in itertools.product(*(range(b) for b in BATCH)):
        single = fn(_element(d, idx, broadcast))
        assert len(single) == len(batched)
        for b, s in zip(batched, single):
            b = np.asarray(b)
            assert np.array_equal(b[idx], np.asarray(s)), idx


BACKENDS = available_backends()


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("name,fn", _kernels(), ids=[k for k, _ in _kernels()])
def test_batched_equals_single_bitwise(name, fn, backend):
    with use_backend(backend):
        _assert_batch_equals_singles(_batch(3), fn)


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("name,fn", _kernels(), ids=[k for k, _ in _kernels()])
def test_batched_equals_single_bitwise_no_constraints(name, fn, backend):
    with use_backend(backend):
        _assert_batch_equals_singles(_batch(4, m=0), fn)


BROADCAST_M = ["forward_dynamics", "constraint_force", "solve_dynamics", "impact_map",
               "position_correction", "constraint_inertia", "constraint_force_projector",
               "optimal_virtual_mass", "coriolis_bar"]


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("name", BROADCAST_M)
def test_broadcast_M_against_batched_A_bitwise(name, backend):
    d = _batch(5)
    rng = np.random.default_rng(9)
    d["M"] = random_spd(rng, N_)  # one (n, n) M for the whole batch of A
    d["C"] = rng.standard_normal((N_, N_))
    d["mu"] = optimal_virtual_mass(d["M"], d["P"])
    fn = dict(_kernels())[name]
    with use_backend(backend):
        _assert_batch_equals_singles(d, fn, broadcast=("M", "C"))


@pytest.mark.parametrize("backend", BACKENDS)
def test_batch_of_one_and_scalar_mu_broadcast(backend):
    with use_backend(backend):
        _batch_of_one(_batch(6))


def _batch_of_one(d):
    one = {k: v[:1, :1] for k, v in d.items()}
    q1 = forward_dynamics(one["M"], one["h"], one["A"], one["g"], one["f"])
    q = forward_dynamics(d["M"][0, 0], d["h"][0, 0], d["A"][0, 0], d["g"][0, 0], d["f"][0, 0])
    assert q1.shape == (1, 1, N_)
    assert np.array_equal(q1[0, 0], q)
    # a scalar μ broadcast over the batch equals the per-element calls with that μ
    qb = forward_dynamics(d["M"], d["h"], d["A"], d["g"], mu=2.5)
    for idx in itertools.product(range(2), range(3)):
        assert np.array_equal(qb[idx], forward_dynamics(d["M"][idx], d["h"][idx], d["A"][idx],
                                                        d["g"][idx], mu=2.5))
