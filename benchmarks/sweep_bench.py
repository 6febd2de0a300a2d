"""Many runs at once (issue 20): the batched engine loop against the same runs one by one and
against ``mujoco.rollout``; parallel efficiency of sweeps from 1 to 2 workers.

Runs: the crossed four-bar (crank 1 m, coupler 2 m, rocker 1 m, ground 2 m; sim_bench.py's
mechanism) over 2 s from random crank angles θ0 ∈ [0, 2π) and crank rates ω0 ∈ ±[5, 9] rad/s,
each started on the anti-parallelogram branch; RK4 (nonmin, with the mass-metric projection)
at dt = 1e-3, samples every 10 ms.

* nonmin batched: ``simulate_batch(..., threads=T)`` (the engine loop, k runs in one call).
* nonmin one by one: ``simulate`` per run (the same engine loop, one call per run).
* MuJoCo: ``mujoco.rollout.rollout`` of sim_bench.py's MJCF four-bar (hinge tree + equality
  connect, semi-implicit Euler at the same dt; ``default`` and ``stiff`` solver settings),
  2000 steps per run from the same initial states, T MjData (threads), in blocks of 500 runs
  (its output holds every step).
* work–precision: the batch also at dt = 5e-3 and 1e-2 (RK4's error grows as dt⁴, MuJoCo's
  semi-implicit Euler's as dt: equal accuracy is a different dt for each).
* accuracy: crank angle error against the exact 1-DOF reduction
  (``nonmin.library.crossed_four_bar_reference``) on the first ``--ref`` runs, max over the
  samples; branch: the largest distance of the rocker angle from its anti-parallelogram value
  over every sample of every run.
* parallel efficiency: ``nonmin.sweep`` of ``--sweep-runs`` runs with 1 and 2 local workers,
  and on a ``dask.distributed.LocalCluster`` of 2 worker processes started here (1 worker: the
  sweep restricted to one of them): ``E = T1 / (2 T2)`` per round of 1, 2, 2, 1 workers; the
  median and the minimum over ``--repeat`` rounds (see ``efficiency``).

Usage::

    OPENBLAS_NUM_THREADS=1 python benchmarks/sweep_bench.py              # 1e4 runs
    python benchmarks/sweep_bench.py --runs 1000 --single 50 --sweep-runs 400   # quicker

Prints a Markdown table and writes ``results/sweep_bench.json``; the load average is printed
before and after (the machine is shared: ratios measured in one process, interleaved where it
matters; re-run when quieter).
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import json
import math
import statistics
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

T_FINAL = 2.0
DT = 1e-3



_CPU = [math.nan]  # CPU time of the last nonmin timing window (process_time, all threads)


def _interleaved(
    paths: dict[str, Any], args: Any
) -> tuple[dict[str, float], dict[str, Any], dict[str, list[float]], dict[str, float]]:
    """Every path once per round, ``args.repeat`` rounds: the median wall time per run of each
    (one by one: over ``args.single`` runs, else ``args.runs``), each path's last output, the
    wall times per run of every round, and the median CPU time per run (``time.process_time``
    of the whole process, every thread, over the same window as the wall time: the nonmin paths
    set ``_CPU``; the model's setup is outside both)."""
    walls: dict[str, list[float]] = {k: [] for k in paths}
    cpus: dict[str, list[float]] = {k: [] for k in paths}
    outs: dict[str, Any] = {}
    for _ in range(args.repeat):
        for k, fn in paths.items():
            _CPU[0] = math.nan
            w, out = fn()
            per = args.single if "one by one" in k else args.runs
            walls[k].append(w / per)
            cpus[k].append(_CPU[0] / per)  # (NaN for paths that do not set it)
            outs[k] = out
    med = {k: statistics.median(v) for k, v in walls.items()}
    return med, outs, walls, {k: statistics.median(v) for k, v in cpus.items()}


def states(k: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    th = rng.uniform(0.0, 2 * math.pi, k)
    om = rng.uniform(5.0, 9.0, k) * rng.choice([-1.0, 1.0], k)
    return th, om


def anti_residual(theta: np.ndarray, psi: np.ndarray) -> np.ndarray:
    z = np.exp(1j * theta)
    with np.errstate(invalid="ignore"):  # a diverged run's NaN
        anti = np.angle((z - 2.0) / (1.0 - 2.0 * z))
    return np.abs((psi - anti + math.pi) % (2 * math.pi) - math.pi)


def crank_errors(theta: np.ndarray, th0: np.ndarray, om0: np.ndarray, t: np.ndarray, R: int) -> list[float]:
    from nonmin.library import crossed_four_bar_reference

    out = []
    for i in range(R):
        ref = crossed_four_bar_reference(t, theta0=float(th0[i]), omega0=float(om0[i]))
        out.append(float(np.max(np.abs(theta[i] - ref["theta"]))))
    return out


# --------------------------------------------------------------------------- nonmin


def nonmin_batch(th0: np.ndarray, om0: np.ndarray, threads: int | None, dt: float = DT) -> tuple[float, Any]:
    from nonmin import library
    from nonmin.library._planar import _cfb_coordinates
    from nonmin.sim import simulate_batch

    model = library.get("crossed_four_bar").model
    Q, V = _cfb_coordinates(th0, om0)
    t = np.linspace(0.0, T_FINAL, round(T_FINAL / 0.01) + 1)
    c0, w0 = time.process_time(), time.perf_counter()
    bt = simulate_batch(model, T_FINAL, Q, V, dt=dt, t_eval=t, threads=threads)
    w = time.perf_counter() - w0
    _CPU[0] = time.process_time() - c0
    return w, bt


def nonmin_single(th0: np.ndarray, om0: np.ndarray) -> tuple[float, np.ndarray]:
    from nonmin import library
    from nonmin.library._planar import _cfb_coordinates
    from nonmin.sim import simulate

    model = library.get("crossed_four_bar").model
    Q, V = _cfb_coordinates(th0, om0)
    t = np.linspace(0.0, T_FINAL, round(T_FINAL / 0.01) + 1)
    qs = []
    c0, w0 = time.process_time(), time.perf_counter()
    for i in range(len(th0)):
        qs.append(simulate(model, T_FINAL, Q[i], V[i], dt=DT, t_eval=t, progress=False).q)
    w = time.perf_counter() - w0
    _CPU[0] = time.process_time() - c0
    return w, np.array(qs)


# --------------------------------------------------------------------------- MuJoCo


def mujoco_rollout(th0: np.ndarray, om0: np.ndarray, setting: str, threads: int, block: int = 500,
                   dt: float = DT, integrator: str = "Euler") -> tuple[float, np.ndarray]:  # fmt: skip
    """Wall time of the rollouts and the crank/rocker angles every 10 ms (k, 201, 2)."""
    import mujoco
    import sim_bench as sb
    from mujoco import rollout

    ref = sb.crossed_four_bar_mechanism()
    xml = sb.mjcf(ref, dt, setting).replace('integrator="Euler"', f'integrator="{integrator}"')
    m = mujoco.MjModel.from_xml_string(xml)
    jid = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, f"j{i}") for i in range(ref.nb)]
    qadr = [int(m.jnt_qposadr[j]) for j in jid]
    vadr = [int(m.jnt_dofadr[j]) for j in jid]
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    nstate = mujoco.mj_stateSize(m, spec)
    d = mujoco.MjData(m)
    k = len(th0)
    init = np.empty((k, nstate))
    for i in range(k):
        mech = sb.crossed_four_bar_mechanism(sb.FourBarParams(theta0=float(th0[i]), omega0=float(om0[i])))
        mujoco.mj_resetData(m, d)
        for b, (kind, p) in enumerate(ref.parents):
            if kind == "bar":
                d.qpos[qadr[b]] = (mech.angles0[b] - mech.angles0[p]) - (ref.angles0[b] - ref.angles0[p])
                d.qvel[vadr[b]] = mech.rates0[b] - mech.rates0[p]
            else:
                d.qpos[qadr[b]] = mech.angles0[b] - ref.angles0[b]
                d.qvel[vadr[b]] = mech.rates0[b]
        mujoco.mj_forward(m, d)
        mujoco.mj_getState(m, d, init[i], spec)
    nstep = round(T_FINAL / dt)
    datas = [mujoco.MjData(m) for _ in range(threads)]
    every = round(0.01 / dt)
    angles = np.empty((k, nstep // every + 1, 2))
    wall = 0.0
    for lo in range(0, k, block):
        hi = min(lo + block, k)
        out = np.empty((hi - lo, nstep, nstate))
        w0 = time.perf_counter()
        rollout.rollout(m, datas if threads > 1 else datas[0], init[lo:hi], nstep=nstep, state=out,
                        skip_checks=False)  # fmt: skip
        wall += time.perf_counter() - w0
        qpos = np.concatenate([init[lo:hi, None, 1:1 + m.nq], out[:, every - 1 :: every, 1:1 + m.nq]], axis=1)
        angles[lo:hi, :, 0] = ref.angles0[0] + qpos[:, :, qadr[0]]
        angles[lo:hi, :, 1] = ref.angles0[2] + qpos[:, :, qadr[2]]
    return wall, angles


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", type=int, default=10_000)
    ap.add_argument("--single", type=int, default=200, help="runs timed one by one through simulate")
    ap.add_argument("--ref", type=int, default=20, help="runs checked against the exact reference")
    ap.add_argument("--sweep-runs", type=int, default=2000)
    ap.add_argument("--repeat", type=int, default=3, help="interleaved rounds (medians)")
    ap.add_argument("--skip-dask", action="store_true")
    ap.add_argument("--dask-defaults", action="store_true",
                    help="the efficiency's LocalCluster with Dask's default settings (profiler and monitors on)")
    ap.add_argument("--json", default=str(HERE / "results" / "sweep_bench.json"))
    ap.add_argument("--work-precision", action="store_true",
                    help="only the work-precision comparison with mujoco.rollout over a range of dt for both")
    ap.add_argument("--batch-vs-single", action="store_true",
                    help="only the batch (1 thread and the default thread count) against simulate one by one")
    ap.add_argument("--efficiency", action="store_true",
                    help="only the sweep's parallel efficiency from 1 to 2 workers (local and Dask)")
    args = ap.parse_args()
    if args.efficiency:
        return efficiency_only(args)
    if args.work_precision:
        return work_precision(args)
    if args.batch_vs_single:
        return batch_vs_single(args)
    load0 = os.getloadavg()
    th0, om0 = states(args.runs, 2026)
    t = np.linspace(0.0, T_FINAL, 201)
    rows: dict[str, Any] = {"runs": args.runs, "load_before": load0}
    # ---- every path, interleaved ``--repeat`` times (medians): the load drifts on a shared machine
    coarse_dt = (2.5e-3, 5e-3, 1e-2)  # work-precision
    paths: dict[str, Any] = {
        "nonmin simulate one by one": lambda: nonmin_single(th0[: args.single], om0[: args.single]),
        "nonmin batch, 1 thread": lambda: nonmin_batch(th0, om0, 1),
        "nonmin batch, 2 threads": lambda: nonmin_batch(th0, om0, 2),
        "mujoco.rollout default, 1 thread": lambda: mujoco_rollout(th0, om0, "default", 1),
        "mujoco.rollout default, 2 threads": lambda: mujoco_rollout(th0, om0, "default", 2),
        "mujoco.rollout stiff, 1 thread": lambda: mujoco_rollout(th0, om0, "stiff", 1),
    }
    for h in coarse_dt:
        paths[f"nonmin batch, 1 thread, dt = {h:g}"] = lambda h=h: nonmin_batch(th0, om0, 1, h)
    per, outs, _, _ = _interleaved(paths, args)
    q_single, bt = outs["nonmin simulate one by one"], outs["nonmin batch, 1 thread"]
    ang_def, ang_stiff = outs["mujoco.rollout default, 1 thread"], outs["mujoco.rollout stiff, 1 thread"]
    coarse = {h: (None, outs[f"nonmin batch, 1 thread, dt = {h:g}"]) for h in coarse_dt}
    same = bool(np.array_equal(bt.q[: args.single], q_single))
    assert bt.q is not None
    theta, psi = bt.q[:, :, 2], bt.q[:, :, 8]
    acc = {
        "nonmin": crank_errors(theta, th0, om0, t, args.ref),
        "mujoco default": crank_errors(ang_def[:, :, 0], th0, om0, t, args.ref),
        "mujoco stiff": crank_errors(ang_stiff[:, :, 0], th0, om0, t, args.ref),
    }
    for h, (_, b) in coarse.items():
        acc[f"nonmin dt = {h:g}"] = crank_errors(b.q[:, :, 2], th0, om0, t, args.ref)
    branch = {
        "nonmin": float(np.nanmax(anti_residual(theta, psi))),
        "mujoco default": float(np.nanmax(anti_residual(ang_def[:, :, 0], ang_def[:, :, 1]))),
        "mujoco stiff": float(np.nanmax(anti_residual(ang_stiff[:, :, 0], ang_stiff[:, :, 1]))),
    }
    for h, (_, b) in coarse.items():
        branch[f"nonmin dt = {h:g}"] = float(np.nanmax(anti_residual(b.q[:, :, 2], b.q[:, :, 8])))
    rows.update(per_run_s=per, crank_error_max=dict((k, max(v)) for k, v in acc.items()),
                crank_error_median=dict((k, float(np.median(v))) for k, v in acc.items()),
                branch_distance_max=branch, batch_equals_single=same,
                failed=int(np.count_nonzero(~bt.success)))  # fmt: skip
    # ---- parallel efficiency
    eff = efficiency(args.sweep_runs, not args.skip_dask, args.repeat, lean=not args.dask_defaults)
    rows["efficiency"] = eff
    rows["load_after"] = os.getloadavg()
    print(f"load average before {load0[0]:.2f} {load0[1]:.2f} {load0[2]:.2f}, after "
          f"{rows['load_after'][0]:.2f} {rows['load_after'][1]:.2f} {rows['load_after'][2]:.2f}")  # fmt: skip
    print(f"\n{args.runs} runs of the crossed four-bar over {T_FINAL} s, dt = {DT} (per run, ms)\n")
    print("| path | per run (ms) | ratio to one-by-one | ratio to rollout default 1 thr |")
    print("|---|---|---|---|")
    for k, v in per.items():
        print(f"| {k} | {v * 1e3:.3f} | {v / per['nonmin simulate one by one']:.3f} | "
              f"{v / per['mujoco.rollout default, 1 thread']:.3f} |")  # fmt: skip
    print("\n| engine | crank angle error, max / median over the checked runs (rad) | max branch distance (rad) |")
    print("|---|---|---|")
    for k in acc:
        print(f"| {k} | {max(acc[k]):.2e} / {np.median(acc[k]):.2e} | {branch[k]:.2e} |")
    print(f"\nbatched runs equal simulate() bitwise on the {args.single} runs timed one by one: {same}; "
          f"failed runs: {rows['failed']}")  # fmt: skip
    print()
    _print_efficiency(eff, args.sweep_runs)
    Path(args.json).parent.mkdir(parents=True, exist_ok=True)
    Path(args.json).write_text(json.dumps(rows, indent=1), encoding="utf-8")
    return 0


NONMIN_DT = (1e-3, 2e-3, 2.5e-3, 5e-3, 1e-2, 2e-2)
MUJOCO_DT = (2e-3, 1e-3, 5e-4, 2.5e-4)


def work_precision(args: Any) -> int:
    """Per-run cost against accuracy: nonmin's batch (RK4 + projection, 1 thread) and
    mujoco.rollout (semi-implicit Euler and RK4, default and stiff constraint settings, 1 thread)
    over a range of steps, on the first ``--runs`` states; crank angle error against the exact
    reduction on the first ``--ref`` runs; every run's largest distance from its branch."""
    load0 = os.getloadavg()
    th0, om0 = states(args.runs, 2026)
    t = np.linspace(0.0, T_FINAL, 201)
    paths: dict[str, Any] = {}
    for h in NONMIN_DT:
        paths[f"nonmin RK4+projection, dt = {h:g}"] = lambda h=h: nonmin_batch(th0, om0, 1, h)
    for integ in ("Euler", "RK4"):
        for setting in ("default", "stiff"):
            for h in MUJOCO_DT:
                paths[f"mujoco {integ} {setting}, dt = {h:g}"] = (
                    lambda h=h, s=setting, i=integ: mujoco_rollout(th0, om0, s, 1, dt=h, integrator=i))
    walls: dict[str, list[float]] = {k: [] for k in paths}
    outs: dict[str, Any] = {}
    for _ in range(args.repeat):
        for k, fn in paths.items():
            w, out = fn()
            walls[k].append(w / args.runs)
            outs[k] = out
    rows = []
    for k in paths:
        o = outs[k]
        theta, psi = (o.q[:, :, 2], o.q[:, :, 8]) if k.startswith("nonmin") else (o[:, :, 0], o[:, :, 1])
        err = crank_errors(theta, th0, om0, t, args.ref)
        rows.append((k, statistics.median(walls[k]), max(err), float(np.median(err)),
                     float(np.nanmax(anti_residual(theta, psi)))))  # fmt: skip
    load1 = os.getloadavg()
    print(f"load average before {load0[0]:.2f} {load0[1]:.2f} {load0[2]:.2f}, after {load1[0]:.2f} {load1[1]:.2f} "
          f"{load1[2]:.2f}\n\n{args.runs} runs of the crossed four-bar over {T_FINAL} s, 1 thread each, medians of "
          f"{args.repeat} interleaved rounds; crank error over the first {args.ref} runs\n")  # fmt: skip
    print("| path | per run (ms) | crank error max (rad) | median (rad) | max branch distance (rad) |")
    print("|---|---|---|---|---|")
    for k, w, e_max, e_med, br in rows:
        print(f"| {k} | {w * 1e3:.3f} | {e_max:.2e} | {e_med:.2e} | {br:.2e} |")
    print("\nFor each MuJoCo setting: the cheapest nonmin step at equal or better accuracy (max error over the "
          "checked runs, and every run within 1e-3 rad of its branch)\n")  # fmt: skip
    print("| MuJoCo | its ms | its error | cheapest nonmin at ≤ error | nonmin ms | ratio nonmin / MuJoCo |")
    print("|---|---|---|---|---|---|")
    nm = [r for r in rows if r[0].startswith("nonmin") and r[4] < 1e-3]
    for k, w, e_max, _, _ in rows:
        if k.startswith("nonmin"):
            continue
        ok = [r for r in nm if r[2] <= e_max]
        if not ok:
            print(f"| {k} | {w * 1e3:.3f} | {e_max:.2e} | none | | |")
            continue
        best = min(ok, key=lambda r: r[1])
        print(f"| {k} | {w * 1e3:.3f} | {e_max:.2e} | {best[0].split(', ')[1]} ({best[2]:.1e}) | "
              f"{best[1] * 1e3:.3f} | {best[1] / w:.2f} |")  # fmt: skip
    Path(args.json).parent.mkdir(parents=True, exist_ok=True)
    Path(args.json).with_name("sweep_bench_work_precision.json").write_text(
        json.dumps({"load": [load0, load1], "rows": rows}, indent=1), encoding="utf-8")
    return 0


def _no_lanes(fn: Any) -> Any:
    """fn() with the batch's lock-step lanes off (the scalar batch: engine/src/lanes.hpp)."""
    before = os.environ.get("NONMIN_LANES")
    os.environ["NONMIN_LANES"] = "0"
    try:
        return fn()
    finally:
        if before is None:
            del os.environ["NONMIN_LANES"]
        else:
            os.environ["NONMIN_LANES"] = before


def batch_vs_single(args: Any) -> int:
    """Wall time per run of the batch on 1 thread and on the default thread count (threads=None:
    every core) against the same runs through ``simulate`` one by one; interleaved rounds, medians.
    The batch runs the first ``--runs`` states, ``simulate`` the first ``--single`` of them."""
    load0 = os.getloadavg()
    th0, om0 = states(args.runs, 2026)
    paths: dict[str, Any] = {
        "nonmin simulate one by one": lambda: nonmin_single(th0[: args.single], om0[: args.single]),
        "nonmin batch, 1 thread": lambda: nonmin_batch(th0, om0, 1),
        f"nonmin batch, default threads ({os.cpu_count()} cores)": lambda: nonmin_batch(th0, om0, None),
        "nonmin batch, 1 thread, no lanes (NONMIN_LANES=0)": lambda: _no_lanes(lambda: nonmin_batch(th0, om0, 1)),
    }
    per, outs, walls, cpu = _interleaved(paths, args)
    b1, bd = outs["nonmin batch, 1 thread"], outs[list(paths)[2]]
    same = bool(np.array_equal(b1.q[: args.single], outs["nonmin simulate one by one"]))
    same_t = bool(np.array_equal(b1.q, bd.q)) and bool(np.array_equal(b1.q, outs[list(paths)[3]].q))
    load1 = os.getloadavg()
    print(f"load average before {load0[0]:.2f} {load0[1]:.2f} {load0[2]:.2f}, after {load1[0]:.2f} {load1[1]:.2f} "
          f"{load1[2]:.2f}\n\n{args.runs} runs (batch) / {args.single} runs (one by one) of the crossed four-bar "
          f"over {T_FINAL} s, RK4 dt = {DT}, medians of {args.repeat} interleaved rounds\n")  # fmt: skip
    print("| path | wall per run (ms) | ratio to one by one | CPU per run (ms) | CPU ratio |")
    print("|---|---|---|---|---|")
    base, cbase = per["nonmin simulate one by one"], cpu["nonmin simulate one by one"]
    for k, v in per.items():
        print(f"| {k} | {v * 1e3:.3f} | {v / base:.3f} | {cpu[k] * 1e3:.3f} | {cpu[k] / cbase:.3f} |")
    print(f"\nbatch (1 thread) equals simulate bitwise on the {args.single} runs: {same}; "
          f"batch 1 thread equals batch default threads and the batch without lanes bitwise: {same_t}; failed runs: "
          f"{int(np.count_nonzero(~b1.success))}")  # fmt: skip
    Path(args.json).parent.mkdir(parents=True, exist_ok=True)
    Path(args.json).with_name("sweep_bench_batch_vs_single.json").write_text(
        json.dumps({"load": [load0, load1], "per_run_s": per, "walls": walls, "cpu_per_run_s": cpu,
                    "equal": [same, same_t]}, indent=1),
        encoding="utf-8")  # fmt: skip
    return 0


#: The Dask settings of the benchmark's LocalCluster (unless ``--dask-defaults``): Dask's own
#: background work off or slowed — the worker's statistical profiler (a thread sampling the
#: task's stack every 10 ms), the event-loop tick (20 ms), the system monitor (0.5 s) and the
#: nanny's memory monitor (0.1 s). With the defaults, these take ~5 % of a core in the client
#: process (scheduler, nannies) and ~4–5 % in each worker process, measured in SWEEP.md: on a
#: 2-core host the 2-worker sweep pays that out of its workers' cores, the 1-worker sweep not.
LEAN_DASK: dict[str, Any] = {
    "distributed.worker.profile.enabled": False,
    "distributed.admin.tick.interval": "1s",
    "distributed.admin.system-monitor.interval": "5s",
    "distributed.worker.memory.monitor-interval": "1s",
}


def _print_efficiency(eff: dict, runs: int) -> None:
    """The Markdown tables of target 2: seconds on 1 and 2 workers (medians), the efficiency
    t1 / (2 t2) of each round and its median and minimum; CPU seconds per sweep."""
    print(f"| sweep, {runs} runs | 1 worker (s) | 2 workers (s) | efficiency per round | median | min |")
    print("|---|---|---|---|---|---|")
    for k, e in eff.items():
        rounds = " ".join(f"{x:.2f}" for x in e["rounds"])
        print(f"| {k} | {e['t1']:.2f} | {e['t2']:.2f} | {rounds} | **{e['median']:.2f}** | {e['min']:.2f} |")
    print("\nCPU seconds per sweep (medians; local: this process; Dask: the client process — client,"
          " scheduler, nannies — and the worker processes):\n")
    print("| sweep | 1 worker: client / workers | 2 workers: client / workers |")
    print("|---|---|---|")
    for k, e in eff.items():
        c1, c2 = e["cpu1"], e["cpu2"]
        print(f"| {k} | {c1[0]:.2f} / {c1[1]:.2f} | {c2[0]:.2f} / {c2[1]:.2f} |")


def efficiency(runs: int, dask: bool, repeat: int = 1, lean: bool = True) -> dict[str, dict[str, Any]]:
    """Parallel efficiency of one sweep from 1 to 2 workers, locally (threads) and on a Dask
    LocalCluster of 2 worker processes (1 thread each) started here.

    Method (the host's speed drifts by 10–20 % within a minute): every path is warmed up, then
    ``repeat`` rounds, each timed as 1 worker, 2 workers, 2 workers, 1 worker (ABBA: a linear
    drift cancels), the round's efficiency E = (t1 + t1') / (2 (t2 + t2')); the median and the
    minimum over the rounds are reported. Dask: one cluster for both worker counts — the
    1-worker sweeps are restricted to its first worker (``dask.annotate(workers=[...])``; the
    other worker idles), so both are warmed up, set up and chunked alike and interleave (two
    clusters alive in one process hung the sweep, 02:20 and 02:50 UTC). Cluster start-up is
    outside the timings. ``lean``: the cluster runs with ``LEAN_DASK`` (Dask's profiler and
    monitors), else with Dask's defaults."""
    import psutil

    from nonmin import library, sweep
    from nonmin.library._planar import _cfb_coordinates

    bar = library.get("crossed_four_bar")
    th0, om0 = states(runs, 99)
    Q, V = _cfb_coordinates(th0, om0)
    states0 = list(zip(Q, V))  # one zipped axis: (q0, qd0) of each draw
    t = np.linspace(0.0, T_FINAL, 201)
    kw: dict[str, Any] = {"t_span": T_FINAL, "dt": DT, "t_eval": t, "progress": False, "chunk": 50}
    failed: list[int] = []
    me = psutil.Process()

    def cpu_of(procs: list[Any]) -> float:
        out = 0.0
        for p in procs:
            try:
                c = p.cpu_times()
                out += c.user + c.system
            except psutil.NoSuchProcess:
                pass
        return out

    def timed(procs: list[Any], **extra: Any) -> tuple[float, float, float]:
        """Wall seconds, this process's CPU seconds, the processes ``procs``' CPU seconds."""
        k0, c0, w0 = cpu_of(procs), time.process_time(), time.perf_counter()
        res = sweep(bar.model, {("q0", "qd0"): states0}, **kw, **extra)
        w, c = time.perf_counter() - w0, time.process_time() - c0
        failed.append(res.failed)
        return w, c, cpu_of(procs) - k0

    def rounds(one: Any, two: Any) -> dict[str, Any]:
        one(), two()  # warm-up
        r1: list[tuple[float, float, float]] = []
        r2: list[tuple[float, float, float]] = []
        es = []
        for _ in range(max(repeat, 1)):
            a, b, c, d = one(), two(), two(), one()
            r1 += [a, d]
            r2 += [b, c]
            es.append((a[0] + d[0]) / (2 * (b[0] + c[0])))
        med = statistics.median
        return {"t1": med(x[0] for x in r1), "t2": med(x[0] for x in r2), "rounds": es, "median": med(es),
                "min": min(es), "walls1": [x[0] for x in r1], "walls2": [x[0] for x in r2],
                "cpu1": [med(x[1] for x in r1), med(x[2] for x in r1)],
                "cpu2": [med(x[1] for x in r2), med(x[2] for x in r2)]}  # fmt: skip

    out = {"local threads": rounds(lambda: timed([], workers=1), lambda: timed([], workers=2))}
    if dask:
        import dask as dk
        from dask.distributed import Client, LocalCluster

        with dk.config.set(LEAN_DASK if lean else {}), \
                LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as lc, \
                Client(lc) as client:  # fmt: skip
            first = sorted(client.scheduler_info()["workers"])[0]
            kids = me.children(recursive=True)

            def one() -> tuple[float, float, float]:
                with dk.annotate(workers=[first]):
                    return timed(kids, scheduler=client)

            timed(kids, scheduler=client)  # warm-up of both workers (imports, the model)
            name = "dask LocalCluster processes" + ("" if lean else " (Dask's default settings)")
            out[name] = rounds(one, lambda: timed(kids, scheduler=client))
    print(f"failed runs in the sweeps: {sorted(set(failed))}; wall seconds (1 worker | 2 workers, ABBA order): "
          + "; ".join(f"{k} " + " ".join(f"{x:.2f}" for x in v["walls1"]) + " | "
                      + " ".join(f"{x:.2f}" for x in v["walls2"]) for k, v in out.items()))  # fmt: skip
    return out


def efficiency_only(args: Any) -> int:
    """Target 2 alone: ``efficiency`` over ``--sweep-runs`` runs, ``--repeat`` rounds."""
    load0 = os.getloadavg()
    eff = efficiency(args.sweep_runs, not args.skip_dask, args.repeat, lean=not args.dask_defaults)
    load1 = os.getloadavg()
    print(f"load average before {load0[0]:.2f} {load0[1]:.2f} {load0[2]:.2f}, after {load1[0]:.2f} {load1[1]:.2f} "
          f"{load1[2]:.2f}; {args.repeat} rounds (1, 2, 2, 1 workers) after a warm-up\n")  # fmt: skip
    _print_efficiency(eff, args.sweep_runs)
    Path(args.json).parent.mkdir(parents=True, exist_ok=True)
    Path(args.json).with_name("sweep_bench_efficiency.json").write_text(
        json.dumps({"load": [load0, load1], "runs": args.sweep_runs, "efficiency": eff}, indent=1), encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
