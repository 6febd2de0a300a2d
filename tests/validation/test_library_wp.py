"""The A04 Bricard peers and the tree formulation of benchmarks/library_wp.py.

Every engine of the work–precision diagram must simulate the *same* mechanism as the library's
A04: the tree of five hinges closed at J6 (nonmin's robot source, Pinocchio, MuJoCo) and the
five free bodies (Exudyn) follow P3 of the library's spatial model over the first second.
"""

from __future__ import annotations

import numpy as np
import pytest

from nonmin import library, simulate

pytest.importorskip("pinocchio")

T = 1.0


@pytest.fixture(scope="module")
def wp(load_benchmark):  # type: ignore[no-untyped-def]
    mod = load_benchmark("library_wp")
    # a 1 s horizon and its reference: P3 of the library's spatial A04 every 0.01 s
    mod.HORIZON["A04_bricard"] = T
    mech = library.get("A04_bricard")
    te = np.round(np.arange(0.0, T + 1e-9, 0.01), 10)
    tr = simulate(mech, (0.0, T), method="dop853", rtol=1e-12, atol=1e-14, t_eval=te, progress=False)
    mod._A04_FINE["t"] = np.asarray(tr.t)
    mod._A04_FINE["P3"] = np.asarray(tr.outputs(mech.model)["P3.position"])
    return mod


def test_the_tree_formulation_is_the_same_mechanism(wp) -> None:  # type: ignore[no-untyped-def]
    robot = wp.a04_robot()
    assert robot.n == 5
    te = np.round(np.arange(0.0, T + 1e-9, 0.01), 10)
    tr = simulate(robot, (0.0, T), np.zeros(5), np.zeros(5), method="dop853", rtol=1e-11, atol=1e-13,
                  t_eval=te, progress=False)  # fmt: skip
    p3 = wp.a04_robot_p3(robot, np.asarray(tr.q))
    ref = wp.a04_fine_reference()["P3"]
    assert np.max(np.abs(p3[0] - [1.0, -1.0, 0.0])) < 1e-15
    assert np.max(np.abs(p3 - ref)) < 1e-8  # it moves by ~0.5 m in this second
    assert np.max(np.abs(ref[-1] - ref[0])) > 0.1
    # one redundant row along the motion: rank 4 of 5
    assert set(np.asarray(tr.rank).tolist()) == {4}
    assert tr.energy_drift < 1e-8


def test_the_pinocchio_peer_follows_the_reference(wp) -> None:  # type: ignore[no-untyped-def]
    r = wp.run_pinocchio_a04(5e-3, "rk4", 0.0, 0)
    assert r["status"] == "ok"
    assert r["error_vs_reference_max"] < 1e-6
    assert r["energy_drift"] < 1e-5
    # the coarse symplectic Euler without correction drifts off the closure
    e = wp.run_pinocchio_a04(1e-2, "euler", 0.0, 0)
    assert e["closure_max"] > 1e-4


def test_the_exudyn_peer_follows_the_reference(wp) -> None:  # type: ignore[no-untyped-def]
    pytest.importorskip("exudyn")
    r = wp.run_exudyn_a04(2e-3, 0.9, 0)
    assert r["status"] == "ok"
    assert r["error_vs_reference_max"] < 1e-4
    assert r["closure_max"] < 1e-8
    assert r["energy_drift"] < 1e-4


def test_the_mujoco_peer_follows_the_reference(wp) -> None:  # type: ignore[no-untyped-def]
    pytest.importorskip("mujoco")
    r = wp.run_mujoco_a04(1e-3, "stiff", 0)
    assert r["status"] == "ok"
    assert r["error_vs_reference_max"] < 2e-2
