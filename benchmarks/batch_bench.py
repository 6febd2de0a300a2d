"""Model + kernel over many distinct states in one call (issue 17, target 5, batched part).

nonmin: ``model.forward_dynamics(Q, V)`` — the model's compiled program evaluated and the
projection dynamics solved for every state in the engine (``nonmin._engine.forward_batch``),
threaded over the batch. MuJoCo's C batch: ``mujoco.rollout.rollout`` with one Euler step per
initial state (``mj_step`` = ``mj_forward`` + an Euler update, in C, over a thread pool of
MjData). Pinocchio has no batch: a Python loop of ``constraintDynamics`` is reported for the
robots as the like-for-like single-state pipeline.

Same physical models: the planar four-bars are sim_bench.py's MJCF (hinge tree + connect
closures) and nonmin's library mechanisms; the robots are robot_bench.py's (UR5 with its tool
point pinned, the dual-arm grasp). States: N distinct random perturbations of the initial
configuration and random velocities (not on the constraint manifold: neither engine needs it).

Usage::

    OPENBLAS_NUM_THREADS=1 python benchmarks/batch_bench.py            # N = 10⁴, 1 and 2 threads
    python benchmarks/batch_bench.py --n 1000 --repeat 3               # quicker

Prints a Markdown table (µs per state, medians of ``--repeat`` calls) and writes
``results/batch_bench.json``.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))


def _median_us(fn: Callable[[], Any], N: int, repeat: int) -> float:
    fn()
    walls = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        walls.append(time.perf_counter() - t0)
    return statistics.median(walls) / N * 1e6


def _mujoco_batch(m: Any, N: int, rng: np.random.Generator, threads: int) -> Callable[[], Any]:
    import mujoco
    from mujoco import rollout

    m.opt.integrator = mujoco.mjtIntegrator.mjINT_EULER
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    d = mujoco.MjData(m)
    nstate = mujoco.mj_stateSize(m, spec)
    states = np.empty((N, nstate))
    for i in range(N):
        mujoco.mj_resetData(m, d)
        d.qpos[:] = d.qpos + 0.05 * rng.standard_normal(m.nq)
        d.qvel[:] = rng.standard_normal(m.nv)
        mujoco.mj_getState(m, d, states[i], spec)
    datas = [mujoco.MjData(m) for _ in range(threads)]
    out = np.empty((N, 1, nstate))
    return lambda: rollout.rollout(m, datas if threads > 1 else datas[0], states, nstep=1, state=out,
                                   skip_checks=False)


def cases() -> list[tuple[str, Any, Any, Any]]:
    """(label, nonmin model, nonmin state, MjModel factory, pinocchio pieces or None)."""
    import mujoco
    import robot_bench as rb
    import sim_bench as sb

    out: list[tuple[str, Any, Any, Any]] = []
    for label, bar in (("crossed_four_bar", sb.crossed_four_bar_mechanism()), ("A02 N=2", sb.a02_mechanism(2)),
                       ("A02 N=40", sb.a02_mechanism(40))):
        mech = sb.nonmin_mechanism(bar)
        out.append((label, mech, lambda bar=bar: mujoco.MjModel.from_xml_string(sb.mjcf(bar, 1e-3, "default")),
                    None))
    for name in ("ur5_point", "dual_arm_grasp"):
        case = rb.CASES[name](1.0)
        mech = type("Mech", (), {"model": case.model, "state": type("S", (), {"q": case.q0, "active": None})})
        out.append((name, mech, lambda case=case: rb._mj_model(case, "RK4", 1e-3, False)[0], case))
    return out


def _pinocchio_loop(case: Any, Q: np.ndarray, V: np.ndarray) -> Callable[[], Any]:
    import pinocchio as pin

    pm = case.model.pinocchio_model
    pd = pm.createData()
    cms = pin.StdVec_RigidConstraintModel()
    for cm in case.pin_constraints(pm):
        cms.append(cm)
    cds = pin.StdVec_RigidConstraintData()
    for cm in cms:
        cds.append(cm.createData())
    pin.initConstraintDynamics(pm, pd, cms, cds)
    prox = pin.ProximalSettings(1e-12, 1e-12, 1)
    tau = np.zeros(pm.nv)
    Qp = [case.model.pinocchio_configuration(q) for q in Q]
    Vp = [case.model.to_pinocchio_velocity(q, v) for q, v in zip(Q, V)]

    def run() -> None:
        for q, v in zip(Qp, Vp):
            pin.constraintDynamics(pm, pd, q, v, tau, cms, cds, prox)

    return run


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, default=10_000)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--json", default=str(HERE / "results" / "batch_bench.json"))
    a = ap.parse_args(argv)
    N = a.n
    rows = []
    print("| case | n | nonmin 1 thread | nonmin 2 threads | MuJoCo rollout 1 | MuJoCo rollout 2 | "
          "ratio (2 threads) | Pinocchio loop |")
    print("|---|---|---|---|---|---|---|---|")
    for label, mech, mj_factory, rcase in cases():
        rng = np.random.default_rng(0)
        model = mech.model
        q0 = np.asarray(mech.state.q)
        Q = q0 + 0.05 * rng.standard_normal((N, model.n))
        V = rng.standard_normal((N, model.n))
        act = mech.state.active
        row: dict[str, Any] = {"case": label, "n": model.n, "N": N}
        for th in (1, 2):
            def run(th: int = th, model: Any = model, Q: np.ndarray = Q, V: np.ndarray = V, act: Any = act) -> Any:
                return model.forward_dynamics(Q, V, active=act, threads=th)

            row[f"nonmin_{th}"] = _median_us(run, N, a.repeat)
            row[f"mujoco_{th}"] = _median_us(_mujoco_batch(mj_factory(), N, np.random.default_rng(1), th), N,
                                             a.repeat)
        row["pinocchio_loop"] = (_median_us(_pinocchio_loop(rcase, Q[:2000], V[:2000]), 2000, a.repeat)
                                 if rcase is not None else None)
        row["ratio_2"] = row["nonmin_2"] / row["mujoco_2"]
        rows.append(row)
        pl = f"{row['pinocchio_loop']:.2f}" if row["pinocchio_loop"] is not None else "—"
        print(f"| {label} | {model.n} | {row['nonmin_1']:.2f} | {row['nonmin_2']:.2f} | {row['mujoco_1']:.2f} | "
              f"{row['mujoco_2']:.2f} | {row['ratio_2']:.2f} | {pl} |", flush=True)
    import robot_bench as rb

    res = {"machine": rb.machine(), "N": N, "repeat": a.repeat, "unit": "us per state", "rows": rows,
           "command": " ".join(["python", "benchmarks/batch_bench.py", *(argv or sys.argv[1:])])}
    Path(a.json).parent.mkdir(parents=True, exist_ok=True)
    Path(a.json).write_text(json.dumps(res, indent=1))


if __name__ == "__main__":
    main()
