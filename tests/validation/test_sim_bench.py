"""The peer benchmark's neutral mechanism description and peer models (benchmarks/sim_bench.py).

Checks that every engine simulates the *same* mechanism as nonmin's library: equal initial
state and energy, and short peer runs that follow the exact reference.
"""

from __future__ import annotations

import numpy as np
import pytest

from nonmin import library


@pytest.fixture(scope="module")
def sb(load_benchmark):  # type: ignore[no-untyped-def]
    mod = load_benchmark("sim_bench")
    return mod


@pytest.mark.parametrize("which", ["crossed_four_bar", "A02_N2", "A02_N3"])
def test_same_initial_state_and_energy_as_the_library(sb, which: str) -> None:  # type: ignore[no-untyped-def]
    if which == "crossed_four_bar":
        bar = sb.crossed_four_bar_mechanism()
        mech = library.get("crossed_four_bar")
    else:
        n = int(which[5:])
        bar = sb.a02_mechanism(n)
        mech = library.get("A02_n_four_bar", N=n)
    com = bar.com_state(bar.angles0, bar.rates0)
    mine = sb._nonmin_to_com(bar, mech.model, mech.state.q[None], mech.state.qd[None])[0]
    np.testing.assert_allclose(mine, com, atol=1e-12)
    e_bar = float(sb.energy(bar, com[None])[0])
    e_lib = float(mech.model.energy(mech.state.q, mech.state.qd))
    assert e_bar == pytest.approx(e_lib, abs=1e-12)
    assert float(sb.joint_errors(bar, com[None])[0]) < 1e-12


def test_two_independent_crossed_four_bar_references_agree(sb) -> None:  # type: ignore[no-untyped-def]
    bar = sb.crossed_four_bar_mechanism()
    t = np.linspace(0.0, 0.6, 61)  # past the first change point (t ≈ 0.2 s)
    mine = sb.reduced_reference(bar)(t)
    th = library.crossed_four_bar_reference(t)["theta"]
    np.testing.assert_allclose(mine, np.stack([np.cos(th), np.sin(th)], axis=1), atol=1e-9)


@pytest.mark.parametrize("engine", ["exudyn", "mujoco", "pinocchio"])
def test_peer_models_follow_the_reference_briefly(sb, engine: str) -> None:  # type: ignore[no-untyped-def]
    pytest.importorskip({"exudyn": "exudyn", "mujoco": "mujoco", "pinocchio": "pinocchio"}[engine])
    bar = sb.a02_mechanism(2, t_final=0.3)
    if engine == "exudyn":
        res = sb.run_exudyn(bar, 1e-3, repeat=0)
    elif engine == "mujoco":
        res = sb.run_mujoco(bar, 1e-3, "stiff", repeat=0)
    else:
        res = sb.run_pinocchio(bar, 1e-3, repeat=0)
    row = sb.summarize(bar, res, sb.a02_reference(2))
    assert row["on_branch"], row
    assert row["error_vs_reference_max"] < 5e-3, row
    assert row["closure_max"] < {"exudyn": 1e-10, "mujoco": 1e-4, "pinocchio": 1e-2}[engine], row
