"""The A03 Andrews peers of benchmarks/andrews_peers.py and nonmin's symbolic A03.

Every engine of A03's work–precision diagram must simulate the Test Set's mechanism: the body
model reproduces the Test Set's M(q), constraints and potential (against the library's
``AndrewsModel``), and each peer reaches the Test Set's PSIDE angles at 0.03 s at a setting
where its method converges (the benchmark's finest settings are tighter still).
"""

from __future__ import annotations

import numpy as np
import pytest

from nonmin.library import AndrewsModel


@pytest.fixture(scope="module")
def ap(load_benchmark):  # type: ignore[no-untyped-def]
    return load_benchmark("andrews_peers")


def test_the_body_model_is_the_test_sets_mechanism(ap) -> None:  # type: ignore[no-untyped-def]
    lib = AndrewsModel()
    bs = ap.bodies()
    rng = np.random.default_rng(3)
    assert ap.closure(ap.q0()) < 1e-15
    for _ in range(4):
        q = rng.uniform(-3.0, 3.0, 7)
        # the closures at E are the Test Set's g1 … g6 (the library's φ, sign aside)
        fr = ap.frames(q)
        e2 = ap.point(fr, "b2", bs["b2"]["points"]["E"])
        g = np.concatenate([ap.point(fr, b, bs[b]["points"]["E"]) - e2 for _, b in ap.CLOSURES])
        np.testing.assert_allclose(g, -lib.constraint_terms(0.0, q, np.zeros(7)).phi, atol=1e-15)
        # M(q) from the bodies' centres of mass and inertias: J_cᵀ m J_c + J_θᵀ I J_θ (central differences)
        h, M = 1e-6, np.zeros((7, 7))
        jac = {k: np.zeros((3, 7)) for k in bs}
        for i in range(7):
            dq = np.zeros(7)
            dq[i] = h
            fp, fm = ap.frames(q + dq), ap.frames(q - dq)
            for k, b in bs.items():
                jac[k][:2, i] = (ap.point(fp, k, b["com"]) - ap.point(fm, k, b["com"])) / (2 * h)
                jac[k][2, i] = (fp[k][1] - fm[k][1]) / (2 * h)
        for k, b in bs.items():
            M += b["m"] * jac[k][:2].T @ jac[k][:2] + b["I"] * np.outer(jac[k][2], jac[k][2])
        np.testing.assert_allclose(M, lib.mass_matrix(q), rtol=1e-8, atol=1e-14)
        assert ap.potential(q) == pytest.approx(lib.potential_energy(q), rel=1e-14, abs=1e-15)


def test_pinocchio_reaches_the_reference(ap) -> None:  # type: ignore[no-untyped-def]
    pytest.importorskip("pinocchio")
    r = ap.run_pinocchio(2e-5, "rk4", 0.0, 0)
    assert r["status"] == "ok"
    assert r["error_vs_reference_max"] < 1e-6  # 1.1e-7 rad; β turns by 15.9 rad
    assert r["energy_drift"] < 1e-6
    assert r["closure_max"] < 1e-8


def test_exudyn_reaches_the_reference(ap) -> None:  # type: ignore[no-untyped-def]
    pytest.importorskip("exudyn")
    r = ap.run_exudyn(2e-5, 0.9, 0)
    assert r["status"] == "ok"
    assert r["error_vs_reference_max"] < 2e-3  # 4.3e-4 rad (second order: 1e-6 at dt 2e-6)
    assert r["closure_max"] < 1e-10


def test_mujoco_reaches_the_reference_with_stiff_equalities(ap) -> None:  # type: ignore[no-untyped-def]
    pytest.importorskip("mujoco")
    r = ap.run_mujoco(2e-5, "stiff", "RK4", 0)
    assert r["status"] == "ok"
    assert r["error_vs_reference_max"] < 2e-3  # 3.8e-4 rad (6.6e-7 at dt 1e-6)
    assert r["closure_max"] < 1e-6
    # MuJoCo's default equality (solref 0.02 s) is far softer than the 0.03 s motion
    d = ap.run_mujoco(2e-5, "default", "RK4", 0)
    assert d["error_vs_reference_max"] > 1.0


def test_the_symbolic_model_is_the_library_model(load_benchmark) -> None:  # type: ignore[no-untyped-def]
    pytest.importorskip("sympy")
    from nonmin import simulate
    from nonmin.library._andrews import ANDREWS_Q0

    sym = load_benchmark("library_wp").a03_symbolic()
    lib = AndrewsModel()
    rng = np.random.default_rng(5)
    q, v = rng.normal(size=7), rng.normal(size=7) * 10
    np.testing.assert_allclose(sym.mass_matrix(q), lib.mass_matrix(q), rtol=1e-14, atol=1e-18)
    np.testing.assert_allclose(sym.constraint_terms(0.0, q, v).A, lib.constraint_terms(0.0, q, v).A, rtol=1e-13,
                               atol=1e-17)  # fmt: skip
    assert sym.potential_energy(q) == pytest.approx(lib.potential_energy(q), rel=1e-13)
    te = np.array([0.0, 0.03])
    a = simulate(sym, (0.0, 0.03), ANDREWS_Q0, np.zeros(7), method="dop853", rtol=1e-8, atol=1e-8, t_eval=te,
                 progress=False)  # fmt: skip
    b = simulate(lib, (0.0, 0.03), ANDREWS_Q0, np.zeros(7), method="dop853", rtol=1e-8, atol=1e-8, t_eval=te,
                 progress=False)  # fmt: skip
    assert np.max(np.abs(np.asarray(a.q[-1]) - np.asarray(b.q[-1]))) < 1e-9
