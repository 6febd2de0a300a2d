"""Benchmark of nonmin.core's dynamics kernels against Pinocchio's constraintDynamics.

Mechanisms: serial chains of ``n`` revolute joints (unit links, 1 kg each) whose tip is pinned
to the world by a loop-closure constraint (Pinocchio ``RigidConstraintModel`` CONTACT_3D between
the tip and the world point it occupies at the reference configuration):

* ``planar``  — all axes along z: the 3 constraint rows have rank 2 (the z row vanishes), so
  nonmin sees a rank-deficient A and Pinocchio relies on its proximal regularization;
* ``spatial`` — axes cycling z, y, x: rank 3.

For each mechanism and state, M (CRBA, symmetrized), h = −nle, A = J (tip point Jacobian,
LOCAL_WORLD_ALIGNED) and γ = classical acceleration of the tip at q̈ = 0 are computed with
Pinocchio once (setup, not timed). Timed, each from Python, in the same run:

* ``nonmin.core.forward_dynamics(M, h, A, γ, τ)`` and ``constraint_force(...)`` — single call
  and batched over N states (one call with arrays of leading dimension N), with the compiled
  (C++ engine) backend and the NumPy backend;
* ``pinocchio.constraintDynamics(model, data, q, v, τ, cmodels, cdatas, prox)`` — proximal
  solver; it computes M, h, J itself, so it does more work than nonmin's kernel;
* ``pinocchio.forwardDynamics(model, data, τ, J, γ, 0)`` — Pinocchio's KKT solve on the M and
  nle already in ``data`` (after ``computeAllTerms``, outside the timing): the same inputs as
  nonmin (fails or is inaccurate where J is rank deficient).

Pinocchio has no batched Python API; its batched time is a Python loop over the N states.
Before timing, nonmin's q̈ is compared with Pinocchio's (constraintDynamics with a tight proximal
accuracy) at every state; the maximum relative difference is recorded.

Usage::

    python benchmarks/core_bench.py            # full run, rewrites the table in README.md
    python benchmarks/core_bench.py --quick    # small sizes, few repeats (smoke test)
    python benchmarks/core_bench.py --batch-n12   # only nonmin's batched path, n = 12, N = 10⁴
    python benchmarks/core_bench.py --engine      # the C++ engine like for like (see engine_bench)

Results: ``benchmarks/results/core_bench.json`` and ``core_bench.csv``; Markdown table between
the markers in ``benchmarks/README.md``.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import platform
import statistics
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results"
README = HERE / "README.md"
#: Pinocchio proximal settings used for both the accuracy check and the timings.
PROX: dict[str, Any] = {"absolute_accuracy": 1e-12, "relative_accuracy": 1e-12, "mu": 1e-10,
                        "max_iter": 100}  # fmt: skip
BEGIN = "<!-- core_bench:begin -->"
END = "<!-- core_bench:end -->"


def _pin() -> Any:
    try:
        import pinocchio
    except ImportError as exc:  # pragma: no cover - environment dependent
        raise SystemExit(
            "core_bench needs Pinocchio: pip install 'nonmin[pin]' (module 'pinocchio')"
        ) from exc
    return pinocchio


# --------------------------------------------------------------------------- mechanisms


@dataclass
class Mechanism:
    """A Pinocchio chain with a loop-closure constraint and a set of states."""

    name: str
    n: int
    model: Any
    data: Any
    cmodels: Any
    cdatas: Any
    frame_id: int
    q: np.ndarray  # (N, n)
    v: np.ndarray  # (N, n)
    tau: np.ndarray  # (N, n)


def build_chain(kind: str, n: int, n_states: int, seed: int = 0) -> Mechanism:
    """Serial chain of ``n`` revolute joints with its tip pinned to the world (see module doc)."""
    pin = _pin()
    rng = np.random.default_rng(seed + 1000 * n + (0 if kind == "planar" else 1))
    model = pin.Model()
    parent = 0
    axes = [np.array([0.0, 0.0, 1.0])]
    if kind == "spatial":
        axes = [np.array([0.0, 0.0, 1.0]), np.array([0.0, 1.0, 0.0]), np.array([1.0, 0.0, 0.0])]
    for i in range(n):
        placement = pin.SE3(np.eye(3), np.array([1.0 if i > 0 else 0.0, 0.0, 0.0]))
        axis = axes[i % len(axes)]
        joint = pin.JointModelRevoluteUnaligned(axis)
        jid = model.addJoint(parent, joint, placement, f"j{i}")
        inertia = pin.Inertia(1.0, np.array([0.5, 0.0, 0.0]), np.diag([0.01, 1.0 / 12, 1.0 / 12]))
        model.appendBodyToJoint(jid, inertia, pin.SE3.Identity())
        parent = jid
    tip = pin.SE3(np.eye(3), np.array([1.0, 0.0, 0.0]))
    frame_id = model.addFrame(pin.Frame("tip", parent, tip, pin.FrameType.OP_FRAME))
    data = model.createData()
    # Reference configuration: generic angles; the tip is pinned where it is there.
    q0 = rng.uniform(-0.8, 0.8, n)
    pin.framesForwardKinematics(model, data, q0)
    anchor = pin.SE3(np.eye(3), data.oMf[frame_id].translation.copy())
    cm = pin.RigidConstraintModel(
        pin.ContactType.CONTACT_3D, model, parent, tip, 0, anchor, pin.ReferenceFrame.LOCAL
    )
    cmodels = pin.StdVec_RigidConstraintModel()
    cmodels.append(cm)
    cdatas = pin.StdVec_RigidConstraintData()
    cdatas.append(cm.createData())
    # States: the reference configuration with random velocities and torques (the constraint
    # holds at position level only at q0; the acceleration-level problem is well posed anywhere).
    q = np.tile(q0, (n_states, 1)) + 0.05 * rng.standard_normal((n_states, n))
    q[0] = q0
    v = rng.standard_normal((n_states, n))
    tau = rng.standard_normal((n_states, n))
    return Mechanism(f"{kind}-{n}", n, model, data, cmodels, cdatas, frame_id, q, v, tau)


def terms(mech: Mechanism) -> dict[str, np.ndarray]:
    """M, h, A, γ for every state (computed with Pinocchio; not timed)."""
    pin = _pin()
    model, data, fid = mech.model, mech.data, mech.frame_id
    N, n = mech.q.shape
    M = np.empty((N, n, n))
    h = np.empty((N, n))
    A = np.empty((N, 3, n))
    gam = np.empty((N, 3))
    zero = np.zeros(n)
    for k in range(N):
        q, v = mech.q[k], mech.v[k]
        Mk = pin.crba(model, data, q)
        Mk = np.triu(Mk) + np.triu(Mk, 1).T
        M[k] = Mk
        h[k] = -pin.rnea(model, data, q, v, zero)
        pin.computeJointJacobians(model, data, q)
        pin.framesForwardKinematics(model, data, q)
        A[k] = pin.getFrameJacobian(model, data, fid, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)[:3]
        pin.forwardKinematics(model, data, q, v, zero)
        acc = pin.getFrameClassicalAcceleration(
            model, data, fid, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
        )
        gam[k] = acc.linear
    return {"M": M, "h": h, "A": A, "gamma": gam, "tau": mech.tau.copy()}


# --------------------------------------------------------------------------- timing


def time_group(
    fns: dict[str, Callable[[], Any]], *, target_s: float, repeats: int
) -> dict[str, dict[str, float]]:
    """Time several functions with *interleaved* repeats (the order rotates every repeat), so
    that they see the same background load.

    Each function is warmed up once, then called ``number`` times per repeat (chosen so that a
    repeat lasts about ``target_s``). Returns, per function, the median and minimum over the
    repeats of the wall time per call and the median process CPU time per call (seconds; CPU
    time is summed over threads and is less sensitive to other jobs on a shared machine)."""
    numbers = {}
    for name, fn in fns.items():
        fn()  # warm-up (JIT, caches)
        t0 = time.perf_counter()
        fn()
        numbers[name] = max(1, int(target_s / max(time.perf_counter() - t0, 1e-7)))
    wall: dict[str, list[float]] = {k: [] for k in fns}
    cpu: dict[str, list[float]] = {k: [] for k in fns}
    names = list(fns)
    for rep in range(repeats):
        for name in names[rep % len(names):] + names[: rep % len(names)]:
            fn, number = fns[name], numbers[name]
            c0 = time.process_time()
            t0 = time.perf_counter()
            for _ in range(number):
                fn()
            wall[name].append((time.perf_counter() - t0) / number)
            cpu[name].append((time.process_time() - c0) / number)
    return {
        k: {
            "median": statistics.median(wall[k]),
            "min": min(wall[k]),
            "cpu_median": statistics.median(cpu[k]),
            "number": numbers[k],
        }
        for k in fns
    }


def _us(t: dict[str, float], per: int = 1) -> dict[str, float]:
    return {
        "median_us": 1e6 * t["median"] / per,
        "min_us": 1e6 * t["min"] / per,
        "cpu_median_us": 1e6 * t["cpu_median"] / per,
        "calls": t["number"],
    }


def machine_info() -> dict[str, Any]:
    """Machine, versions and load (recorded with every run)."""
    import scipy

    pin = _pin()
    try:
        commit = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"], cwd=HERE, capture_output=True, text=True,
            check=False,
        ).stdout.strip()  # fmt: skip
    except OSError:
        commit = ""
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return {
        "date_utc": time.strftime("%Y-%m-%d %H:%M:%S", time.gmtime()),
        "cpu": cpu,
        "logical_cpus": os.cpu_count(),
        "platform": platform.platform(),
        "python": sys.version.split()[0],
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "threads": len(os.sched_getaffinity(0)),
        "pinocchio": pin.__version__,
        "nonmin_commit": commit,
        "loadavg_start": list(os.getloadavg()),
    }


JIT_SCRIPT = """
import time, numpy as np
t0 = time.perf_counter()
import nonmin.core as c
t1 = time.perf_counter()
rng = np.random.default_rng(0)
M = np.eye(6) * 2.0; h = rng.standard_normal(6); A = rng.standard_normal((3, 6)); g = np.zeros(3)
c.forward_dynamics(M, h, A, g)
t2 = time.perf_counter()
c.forward_dynamics(np.stack([M] * 1000), np.stack([h] * 1000), np.stack([A] * 1000), np.zeros((1000, 3)))
t3 = time.perf_counter()
print(t1 - t0, t2 - t1, t3 - t2)
"""


def jit_times() -> dict[str, float]:
    """First-call times in two fresh processes ("cold", "warm"; the engine compiles nothing at run
    time, so the two differ only by the file cache)."""
    import tempfile

    out: dict[str, float] = {}
    with tempfile.TemporaryDirectory() as tmp:
        env = dict(os.environ, NONMIN_BACKEND="engine", TMPDIR=tmp)
        for label in ("cold", "warm"):
            res = subprocess.run(
                [sys.executable, "-c", JIT_SCRIPT], env=env, capture_output=True, text=True,
                check=True,
            )  # fmt: skip
            imp, single, batch = (float(x) for x in res.stdout.split())
            out[f"{label}_import_s"] = imp
            out[f"{label}_first_single_s"] = single
            out[f"{label}_first_batch_s"] = batch
    return out


# --------------------------------------------------------------------------- one mechanism


def bench_mechanism(
    kind: str, n: int, sizes: list[int], *, target_s: float, repeats: int, n_check: int
) -> dict[str, Any]:
    """Accuracy check and timings for one mechanism (see module docstring)."""
    import nonmin.core as core
    from nonmin.core.dynamics import _solve_dynamics_numpy as numpy_path

    pin = _pin()
    n_states = max(max(sizes), n_check)
    mech = build_chain(kind, n, n_states)
    T = terms(mech)
    M, h, A, gam, tau = T["M"], T["h"], T["A"], T["gamma"], T["tau"]
    model, data, cms, cds = mech.model, mech.data, mech.cmodels, mech.cdatas
    pin.initConstraintDynamics(model, data, cms, cds)
    prox = pin.ProximalSettings(
        PROX["absolute_accuracy"], PROX["relative_accuracy"], PROX["mu"], PROX["max_iter"]
    )
    rank = int(np.linalg.matrix_rank(A[0]))
    rec: dict[str, Any] = {"mechanism": mech.name, "kind": kind, "n": n, "m": 3, "rank": rank}

    # ---- accuracy: nonmin (both backends) and Pinocchio's KKT against constraintDynamics
    err_nb = err_np = err_kkt = 0.0
    iters = []
    for k in range(n_check):
        ref = pin.constraintDynamics(model, data, mech.q[k], mech.v[k], tau[k], cms, cds, prox)
        ref = np.array(ref)
        iters.append(prox.iter)
        scale = max(float(np.max(np.abs(ref))), 1.0)
        with core.use_backend("engine"):
            a = core.forward_dynamics(M[k], h[k], A[k], gam[k], tau[k])
        with core.use_backend("numpy"):
            b = core.forward_dynamics(M[k], h[k], A[k], gam[k], tau[k])
        pin.computeAllTerms(model, data, mech.q[k], mech.v[k])
        c = np.array(pin.forwardDynamics(model, data, tau[k], A[k], gam[k], 0.0))
        err_nb = max(err_nb, float(np.max(np.abs(a - ref))) / scale)
        err_np = max(err_np, float(np.max(np.abs(b - ref))) / scale)
        kkt = float(np.max(np.abs(c - ref))) / scale if np.all(np.isfinite(c)) else float("inf")
        err_kkt = max(err_kkt, kkt)
    with core.use_backend("engine"):
        qb = core.forward_dynamics(M[:n_check], h[:n_check], A[:n_check], gam[:n_check], tau[:n_check])
        q1 = np.array([core.forward_dynamics(M[k], h[k], A[k], gam[k], tau[k]) for k in range(n_check)])
    rec["accuracy"] = {
        "states_checked": n_check,
        "max_rel_diff_engine_vs_pin_constraintDynamics": err_nb,
        "max_rel_diff_numpy_vs_pin_constraintDynamics": err_np,
        "max_rel_diff_pin_kkt_vs_pin_constraintDynamics": err_kkt,
        "engine_batch_equals_single_bitwise": bool(np.array_equal(qb, q1)),
        "pin_prox_iterations_max": int(max(iters)),
        "pin_prox_settings": PROX,
    }

    # ---- single call (state 0); all methods timed with interleaved repeats
    q0, v0, t0 = mech.q[0], mech.v[0], tau[0]
    M0, h0, A0, g0 = M[0], h[0], A[0], gam[0]
    pin.computeAllTerms(model, data, q0, v0)
    data_kkt = model.createData()
    pin.computeAllTerms(model, data_kkt, q0, v0)

    # The backend is the engine for the whole run (set in main); the NumPy backend is timed through
    # the function forward_dynamics itself falls back to, so no backend switch is timed.
    def engine_fd() -> Any:
        return core.forward_dynamics(M0, h0, A0, g0, t0)

    def engine_fc() -> Any:
        return core.constraint_force(M0, h0, A0, g0, t0)

    def numpy_fd() -> Any:
        return numpy_path(M0, h0, A0, g0, t0, None, None).qdd

    group = time_group(
        {
            "nonmin_engine_forward_dynamics": engine_fd,
            "nonmin_engine_constraint_force": engine_fc,
            "nonmin_numpy_forward_dynamics": numpy_fd,
            "pin_constraintDynamics": lambda: pin.constraintDynamics(
                model, data, q0, v0, t0, cms, cds, prox
            ),
            "pin_kkt_forwardDynamics": lambda: pin.forwardDynamics(
                model, data_kkt, t0, A0, g0, 0.0
            ),
        },
        target_s=target_s,
        repeats=repeats,
    )
    rec["single"] = {k: _us(v) for k, v in group.items()}

    # ---- batched: one nonmin call on N states; Pinocchio: Python loop over the N states
    batched = []
    for N in sizes:
        Mb, hb, Ab, gb, tb = M[:N], h[:N], A[:N], gam[:N], tau[:N]
        qs, vs = mech.q[:N], mech.v[:N]

        def b_engine_fd() -> Any:
            return core.forward_dynamics(Mb, hb, Ab, gb, tb)  # noqa: B023

        def b_engine_fc() -> Any:
            return core.constraint_force(Mb, hb, Ab, gb, tb)  # noqa: B023

        def b_numpy_fd() -> Any:
            return numpy_path(Mb, hb, Ab, gb, tb, None, None).qdd  # noqa: B023

        def pin_loop() -> None:
            for k in range(N):  # noqa: B023
                pin.constraintDynamics(model, data, qs[k], vs[k], tb[k], cms, cds, prox)  # noqa: B023

        group = time_group(
            {
                "nonmin_engine_forward_dynamics": b_engine_fd,
                "nonmin_engine_constraint_force": b_engine_fc,
                "nonmin_numpy_forward_dynamics": b_numpy_fd,
                "pin_constraintDynamics_loop": pin_loop,
            },
            target_s=target_s,
            repeats=max(3, repeats // 2) if N >= 1000 else repeats,
        )
        row: dict[str, Any] = {"N": N}
        row.update({k: _us(v, N) for k, v in group.items()})
        batched.append(row)
    rec["batched"] = batched
    return rec


# --------------------------------------------------------------------------- reporting


def _f(x: float) -> str:
    return f"{x:.3g}" if x < 100 else f"{x:.0f}"


def markdown(results: dict[str, Any]) -> str:
    """The two result tables (single call; batched per state) and the run's context."""
    info = results["machine"]
    lines = [
        f"Run {info['date_utc']} UTC on {info['cpu']} ({info['logical_cpus']} logical CPUs, "
        f"threads {info['threads']}), Python {info['python']}, NumPy {info['numpy']}, "
        f"Pinocchio {info['pinocchio']}, nonmin {info['nonmin_commit']}. "
        f"Load average (1/5/15 min) at start {', '.join(f'{x:.2f}' for x in info['loadavg_start'])}"
        f", at end {', '.join(f'{x:.2f}' for x in info['loadavg_end'])} — the machine is shared, "
        "so absolute times are noisy; ratios come from the same run.",
        "",
        "**Single call** (µs of wall time, median over repeats interleaved between the methods; "
        "state 0 of each mechanism). "
        "`ratio` = nonmin (engine) forward_dynamics / Pinocchio constraintDynamics from the wall "
        "medians; `ratio CPU` from the medians of process CPU time; `ratio min` from the "
        "fastest repeats (the two last are less disturbed by other jobs on a shared machine). "
        "`max rel. Δq̈` = largest difference to Pinocchio's q̈ over the checked states.",
        "",
        "| mechanism | n | rank A | nonmin fd (engine) | nonmin f_c (engine) | nonmin fd (NumPy) "
        "| pin constraintDynamics | pin KKT forwardDynamics | ratio | ratio CPU | ratio min "
        "| max rel. Δq̈ vs pin |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in results["mechanisms"]:
        s = r["single"]
        nb = s["nonmin_engine_forward_dynamics"]["median_us"]
        pc = s["pin_constraintDynamics"]["median_us"]
        cpu_ratio = (
            s["nonmin_engine_forward_dynamics"]["cpu_median_us"]
            / s["pin_constraintDynamics"]["cpu_median_us"]
        )
        min_ratio = (
            s["nonmin_engine_forward_dynamics"]["min_us"] / s["pin_constraintDynamics"]["min_us"]
        )
        lines.append(
            f"| {r['mechanism']} | {r['n']} | {r['rank']} | {_f(nb)} | "
            f"{_f(s['nonmin_engine_constraint_force']['median_us'])} | "
            f"{_f(s['nonmin_numpy_forward_dynamics']['median_us'])} | {_f(pc)} | "
            f"{_f(s['pin_kkt_forwardDynamics']['median_us'])} | {nb / pc:.2f} | {cpu_ratio:.2f} | "
            f"{min_ratio:.2f} | "
            f"{r['accuracy']['max_rel_diff_engine_vs_pin_constraintDynamics']:.1e} |"
        )
    lines += [
        "",
        "**Batched** (µs per state, median of wall time): nonmin = one call on arrays of N "
        "states (engine: threads over the cores for N ≥ 2048); Pinocchio = Python loop of "
        "constraintDynamics over the N states. `CPU` = process CPU time per state (summed over "
        "threads: the work done, whatever the load). `ratio` = nonmin (engine) forward_dynamics "
        "/ Pinocchio loop (wall).",
        "",
        "| mechanism | N | nonmin fd (engine) | CPU | nonmin f_c (engine) | nonmin fd (NumPy) "
        "| pin constraintDynamics loop | CPU | ratio |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in results["mechanisms"]:
        for b in r["batched"]:
            nb = b["nonmin_engine_forward_dynamics"]["median_us"]
            pl = b["pin_constraintDynamics_loop"]["median_us"]
            lines.append(
                f"| {r['mechanism']} | {b['N']} | {_f(nb)} | "
                f"{_f(b['nonmin_engine_forward_dynamics']['cpu_median_us'])} | "
                f"{_f(b['nonmin_engine_constraint_force']['median_us'])} | "
                f"{_f(b['nonmin_numpy_forward_dynamics']['median_us'])} | {_f(pl)} | "
                f"{_f(b['pin_constraintDynamics_loop']['cpu_median_us'])} | {nb / pl:.2f} |"
            )
    jit = results.get("jit")
    if jit:
        lines += [
            "",
            "**First call** (fresh process, s): first process — import "
            f"{jit['cold_import_s']:.2f}, first single call {jit['cold_first_single_s']:.2f}, "
            f"first batched call {jit['cold_first_batch_s']:.2f}; a second process — "
            f"import {jit['warm_import_s']:.2f}, first single call "
            f"{jit['warm_first_single_s']:.2f}, first batched call {jit['warm_first_batch_s']:.2f}.",
        ]
    return "\n".join(lines)


def write_csv(results: dict[str, Any], path: Path) -> None:
    """Tidy CSV: one row per (mechanism, N, method) with median and minimum µs per state."""
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["mechanism", "kind", "n", "m", "rank", "mode", "N", "method",
                    "median_us_per_state", "min_us_per_state", "cpu_median_us_per_state",
                    "calls_per_repeat"])  # fmt: skip
        for r in results["mechanisms"]:
            base = [r["mechanism"], r["kind"], r["n"], r["m"], r["rank"]]
            for meth, t in r["single"].items():
                w.writerow([*base, "single", 1, meth, f"{t['median_us']:.4g}",
                            f"{t['min_us']:.4g}", f"{t['cpu_median_us']:.4g}",
                            t["calls"]])  # fmt: skip
            for b in r["batched"]:
                for meth, t in b.items():
                    if meth == "N":
                        continue
                    w.writerow([*base, "batched", b["N"], meth, f"{t['median_us']:.4g}",
                                f"{t['min_us']:.4g}", f"{t['cpu_median_us']:.4g}",
                                t["calls"]])  # fmt: skip


def update_readme(table: str, command: str) -> None:
    """Replace the text between the markers in benchmarks/README.md (append them if absent)."""
    block = f"{BEGIN}\n<!-- generated by: {command} -->\n\n{table}\n\n{END}"
    text = README.read_text() if README.exists() else "# Benchmarks\n"
    if BEGIN in text and END in text:
        head, rest = text.split(BEGIN, 1)
        _, tail = rest.split(END, 1)
        text = head + block + tail
    else:
        text = text.rstrip("\n") + "\n\n" + block + "\n"
    README.write_text(text)


def batch_n12(n_states: int = 10_000, repeats: int = 15) -> dict[str, Any]:
    """Only nonmin's compiled batched path at n = 12 (planar and spatial chain), N states per
    call: wall and process CPU time per state, serial and parallel driver (the default choice
    for this N), with the load average. Nothing is written."""
    import nonmin.core as core
    from nonmin.core import _fast

    core.set_backend("engine")
    out: dict[str, Any] = {"machine": machine_info(), "N": n_states, "results": []}
    for kind in ("planar", "spatial"):
        T = terms(build_chain(kind, 12, n_states))
        M, h, A, gam, tau = T["M"], T["h"], T["A"], T["gamma"], T["tau"]
        for fn_name in ("forward_dynamics", "constraint_force"):
            fn = getattr(core, fn_name)
            drivers = {"default": _fast.ENGINE_PARALLEL_MIN_BATCH, "serial": 1 << 62}
            fns = {}
            for drv, threshold in drivers.items():

                def call(threshold: int = threshold, fn: Any = fn, a: Any = (M, h, A, gam, tau)) -> Any:
                    old = _fast.ENGINE_PARALLEL_MIN_BATCH
                    _fast.ENGINE_PARALLEL_MIN_BATCH = threshold
                    try:
                        return fn(*a)
                    finally:
                        _fast.ENGINE_PARALLEL_MIN_BATCH = old

                fns[drv] = call
            group = time_group(fns, target_s=0.05, repeats=repeats)
            for drv, t in group.items():
                row = {"mechanism": f"{kind}-12", "function": fn_name, "driver": drv,
                       **_us(t, n_states)}  # fmt: skip
                out["results"].append(row)
                print(
                    f"{kind}-12 {fn_name:17s} {drv:8s} wall median {row['median_us']:.3f} "
                    f"(min {row['min_us']:.3f}) us/state, CPU median "
                    f"{row['cpu_median_us']:.3f} us/state", flush=True,
                )  # fmt: skip
    out["machine"]["loadavg_end"] = list(os.getloadavg())
    print("load average start", out["machine"]["loadavg_start"], "end",
          out["machine"]["loadavg_end"], "threads", out["machine"]["threads"])  # fmt: skip
    return out


def large() -> None:
    """Single calls of ``forward_dynamics`` at n = 243 (and two random sparse cases), compiled
    against the NumPy backend (LAPACK SVD), interleaved; prints medians and minima."""
    import math

    from nonmin.core import forward_dynamics, use_backend
    from nonmin.library import a02_n_four_bar

    mech = a02_n_four_bar(N=40)
    model = mech.model

    def chain(theta: float) -> tuple[np.ndarray, ...]:
        c, s = math.cos(theta), math.sin(theta)
        q, qd = [], []
        for i in range(41):
            q += [i + 0.5 * c, 0.5 * s, theta]
            qd += [0.5 * s, -0.5 * c, -1.0]
        for i in range(1, 41):
            q += [i - 0.5 + c, s, 0.0]
            qd += [s, -c, 0.0]
        qa, qda = np.array(q), np.array(qd)
        ct = model.constraint_terms(0.0, qa, qda, mech.state.active)
        h = model.conservative_force(qa) - model.coriolis_force(qa, qda)
        return model.mass_matrix(qa), h, np.ascontiguousarray(ct.A), ct.gamma

    rng = np.random.default_rng(0)
    cases: list[tuple[str, tuple[np.ndarray, ...], float]] = [
        ("A02 N=40, crank 1.3 rad, rtol 1e-10", chain(1.3), 1e-10),
        ("A02 N=40, crank 1.3 rad, rtol 1e-2", chain(1.3), 1e-2),
        ("A02 N=40, crank 0.1 rad, rtol 1e-2 (SVD)", chain(0.1), 1e-2),
        ("A02 N=40, horizontal, rtol 1e-10 (SVD)", chain(0.0), 1e-10),
    ]
    for n, m in ((243, 60), (243, 121)):
        A = rng.standard_normal((m, n)) * (rng.uniform(size=(m, n)) < 0.03)
        A[np.arange(m), np.arange(m)] += 1.0
        cases.append((f"random sparse n={n}, m={m}", (np.diag(rng.uniform(1, 2, n)),
                      rng.standard_normal(n), A, rng.standard_normal(m)), 1e-10))  # fmt: skip
    print("| case | compiled median (min) [ms] | NumPy median (min) [ms] | NumPy / compiled |")
    print("|---|---|---|---|")
    for name, (M, h, A, g), rtol in cases:
        times: dict[str, list[float]] = {"engine": [], "numpy": []}
        for b in times:
            with use_backend(b):
                forward_dynamics(M, h, A, g, rtol=rtol)  # compile / warm up
        for _ in range(15):
            for b in times:
                with use_backend(b):
                    t0 = time.perf_counter()
                    forward_dynamics(M, h, A, g, rtol=rtol)
                    times[b].append((time.perf_counter() - t0) * 1e3)
        med = {b: float(np.median(v)) for b, v in times.items()}
        print(f"| {name} | {med['engine']:.2f} ({min(times['engine']):.2f}) | "
              f"{med['numpy']:.2f} ({min(times['numpy']):.2f}) | {med['numpy'] / med['engine']:.1f} |",
              flush=True)  # fmt: skip
    print("load average", os.getloadavg())


ENGINE_BEGIN = "<!-- core_bench_engine:begin -->"
ENGINE_END = "<!-- core_bench_engine:end -->"


def _a02_state(theta: float) -> tuple[np.ndarray, ...]:
    """M, h, A, γ of the A02 N = 40 four-bar (243 coordinates, 242 rows) with every crank at θ."""
    import math

    from nonmin.library import a02_n_four_bar

    mech = a02_n_four_bar(N=40)
    model = mech.model
    c, s = math.cos(theta), math.sin(theta)
    q, qd = [], []
    for i in range(41):
        q += [i + 0.5 * c, 0.5 * s, theta]
        qd += [0.5 * s, -0.5 * c, -1.0]
    for i in range(1, 41):
        q += [i - 0.5 + c, s, 0.0]
        qd += [s, -c, 0.0]
    qa, qda = np.array(q), np.array(qd)
    ct = model.constraint_terms(0.0, qa, qda, mech.state.active)
    h = model.conservative_force(qa) - model.coriolis_force(qa, qda)
    return (np.ascontiguousarray(model.mass_matrix(qa)), np.asarray(h, dtype=float),
            np.ascontiguousarray(ct.A), np.asarray(ct.gamma, dtype=float))  # fmt: skip


def engine_bench(quick: bool = False) -> dict[str, Any]:
    """The C++ engine (``nonmin.core`` backend ``"engine"``) like for like.

    * Chains with n ≤ 6 (``build_chain``): ``forward_dynamics(M, h, J, γ, τ)`` from Python against
      Pinocchio's KKT solve given the same terms, ``pinocchio.forwardDynamics(model, data, τ, J,
      γ, 0)`` on the M and nle that ``computeAllTerms`` left in ``data`` (outside the timing),
      also from Python; planar chains pass the two rows of J that do not vanish to both (the
      KKT solve fails on the zero row). Beside them: the numba backend, and both kernels alone
      in a C++ loop (the engine's Solver; Pinocchio's KKT algorithm written with Eigen:
      LLT(M), LLT(J M⁻¹ Jᵀ)). Batched: one engine call on 10⁴ states (1 thread and the default)
      against a Python loop of ``pinocchio.forwardDynamics`` over the 10⁴ states (Pinocchio has
      no batched API; the loop reuses one ``data``, whose M and nle are those of state 0 — the
      dense solve's cost does not depend on the values).
    * A02 N = 40 (n = 243, A 242 × 243): there is no Pinocchio model of it, so the peer is the
      same dense KKT algorithm in C++ (Eigen, as above) and NumPy's dense solve of the KKT
      matrix from Python; certified state (crank 1.3 rad) and the horizontal singular state
      (SVD; the KKT matrix is singular there). Batched: 200 states (10⁴ states of 243 × 243 M
      and 242 × 243 A do not fit in memory).

    Times are medians over interleaved repeats (wall and process CPU time); the machine is
    shared, so wall times are noisy and CPU times are given beside them.
    """
    import nonmin.core as core
    from nonmin import _engine
    from nonmin.core import _fast

    pin = _pin()
    have_numba = False  # the core's numba backend is gone (issue 17): its columns stay empty
    n_batch = 1000 if quick else 10_000
    target_s, repeats = (0.01, 3) if quick else (0.05, 9)
    out: dict[str, Any] = {"machine": machine_info(), "quick": quick, "chains": [], "large": []}
    core.set_backend("engine")
    # (spatial-3 is left out: its last joint turns about the link carrying the tip, so J has
    # rank 2 with 3 rows and the KKT solve is singular)
    for kind, n in (("planar", 3), ("planar", 6), ("spatial", 4), ("spatial", 6)):
        mech = build_chain(kind, n, n_batch)
        T = terms(mech)
        rows = [0, 1] if kind == "planar" else [0, 1, 2]
        M, h, tau = T["M"], T["h"], T["tau"]
        J = np.ascontiguousarray(T["A"][:, rows])
        gam = np.ascontiguousarray(T["gamma"][:, rows])
        model = mech.model
        data_kkt = model.createData()
        pin.computeAllTerms(model, data_kkt, mech.q[0], mech.v[0])
        M0, h0, J0, g0, t0 = M[0], h[0], J[0], gam[0], tau[0]
        ref = np.array(pin.forwardDynamics(model, data_kkt, t0, J0, g0, 0.0))
        got = core.forward_dynamics(M0, h0, J0, g0, t0)
        rel = float(np.max(np.abs(got - ref)) / max(np.max(np.abs(ref)), 1.0))
        fns: dict[str, Callable[[], Any]] = {
            "engine_forward_dynamics": lambda: core.forward_dynamics(M0, h0, J0, g0, t0),  # noqa: B023
            "pin_kkt_forwardDynamics": lambda: pin.forwardDynamics(model, data_kkt, t0, J0, g0, 0.0),  # noqa: B023
        }
        group = time_group(fns, target_s=target_s, repeats=repeats)
        rec: dict[str, Any] = {"mechanism": f"{kind}-{n}", "n": n, "m": len(rows),
                               "max_rel_diff_vs_pin_kkt": rel,
                               "single": {k: _us(v) for k, v in group.items()}}  # fmt: skip
        if have_numba:
            core.set_backend("engine")
            g2 = time_group({"numba_forward_dynamics": lambda: core.forward_dynamics(M0, h0, J0, g0, t0)},  # noqa: B023
                            target_s=target_s, repeats=repeats)  # fmt: skip
            core.set_backend("engine")
            rec["single"].update({k: _us(v) for k, v in g2.items()})
        g0v = h0 + t0
        kern = [_engine.core_time_solve(M0, g0v, J0, g0, 20000 if not quick else 2000) for _ in range(repeats)]
        kkt = [_engine.core_time_kkt(M0, g0v, J0, g0, 20000 if not quick else 2000) for _ in range(repeats)]
        rec["kernel_cxx_loop_us"] = {"engine_solver": 1e6 * statistics.median(kern),
                                     "eigen_kkt": 1e6 * statistics.median(kkt)}  # fmt: skip
        # batched: one engine call on N states vs a Python loop of Pinocchio's KKT solve
        def eng_default(a: Any = (M, h, J, gam, tau)) -> Any:
            return core.forward_dynamics(*a)

        def eng_serial(a: Any = (M, h, J, gam, tau)) -> Any:
            old = _fast.ENGINE_PARALLEL_MIN_BATCH
            _fast.ENGINE_PARALLEL_MIN_BATCH = 1 << 62
            try:
                return core.forward_dynamics(*a)
            finally:
                _fast.ENGINE_PARALLEL_MIN_BATCH = old

        def pin_loop() -> None:
            for k in range(n_batch):
                pin.forwardDynamics(model, data_kkt, tau[k], J[k], gam[k], 0.0)  # noqa: B023

        qb = eng_default()
        single = np.array([core.forward_dynamics(M[k], h[k], J[k], gam[k], tau[k]) for k in range(0, n_batch, 97)])
        rec["batch_equals_single_bitwise"] = bool(np.array_equal(qb[::97], single))
        gb = time_group({"engine_forward_dynamics_default": eng_default,
                         "engine_forward_dynamics_1_thread": eng_serial,
                         "pin_kkt_forwardDynamics_loop": pin_loop},
                        target_s=target_s * 4, repeats=max(3, repeats // 2))  # fmt: skip
        rec["batched"] = {"N": n_batch, "threads_default": _fast.engine_threads(n_batch),
                          **{k: _us(v, n_batch) for k, v in gb.items()}}  # fmt: skip
        out["chains"].append(rec)
        s1 = rec["single"]
        print(f"{rec['mechanism']}: engine fd {s1['engine_forward_dynamics']['median_us']:.2f} us, "
              f"pin KKT {s1['pin_kkt_forwardDynamics']['median_us']:.2f} us, rel diff {rel:.1e}",
              flush=True)  # fmt: skip
    # ---- A02 N = 40
    for label, theta in (("A02 N=40 crank 1.3 rad (certified LQ)", 1.3),
                         ("A02 N=40 horizontal (singular: SVD)", 0.0)):  # fmt: skip
        M, h, A, g = _a02_state(theta)
        n, m = A.shape[1], A.shape[0]
        K = np.block([[M, -A.T], [A, np.zeros((m, m))]])
        rhs = np.concatenate([h, -g])
        info = _engine.core_solve_info(M, h, A, g, 1e-10)

        def np_kkt(K: Any = K, rhs: Any = rhs) -> Any:
            return np.linalg.solve(K, rhs)

        def eng(a: Any = (M, h, A, g)) -> Any:
            return core.forward_dynamics(*a)

        fns = {"engine_forward_dynamics": eng}
        if info["rank"] == m:
            fns["numpy_dense_kkt_solve"] = np_kkt
        group = time_group(fns, target_s=target_s * 4, repeats=max(3, repeats // 2))
        rec = {"case": label, "n": n, "m": m, "rank": info["rank"], "method": info["method"],
               "single": {k: _us(v) for k, v in group.items()}}  # fmt: skip
        kern = [_engine.core_time_solve(M, h, A, g, 20 if info["method"] else 3) for _ in range(3)]
        rec["kernel_cxx_loop_us"] = {"engine_solver": 1e6 * statistics.median(kern)}
        if info["rank"] == m:
            kkt = [_engine.core_time_kkt(M, h, A, g, 3) for _ in range(3)]
            rec["kernel_cxx_loop_us"]["eigen_kkt"] = 1e6 * statistics.median(kkt)
            qn = np.linalg.solve(K, rhs)[:n]
            qe = eng()
            rec["max_rel_diff_vs_numpy_kkt"] = float(np.max(np.abs(qe - qn)) / np.max(np.abs(qn)))
        if have_numba:
            core.set_backend("engine")
            g2 = time_group({"numba_forward_dynamics": eng}, target_s=target_s * 4,
                            repeats=max(3, repeats // 2))  # fmt: skip
            core.set_backend("engine")
            rec["single"].update({k: _us(v) for k, v in g2.items()})
        out["large"].append(rec)
        print(f"{label}: engine {rec['single']['engine_forward_dynamics']['median_us']:.1f} us",
              flush=True)  # fmt: skip
    Ms, hs, As, gs = zip(*(_a02_state(th) for th in np.linspace(0.2, 1.4, 200)))
    Mb, hb, Ab, gb_ = np.array(Ms), np.array(hs), np.array(As), np.array(gs)
    gt = time_group({"engine_forward_dynamics_batch_200": lambda: core.forward_dynamics(Mb, hb, Ab, gb_),
                     "engine_forward_dynamics_loop_200": lambda: [core.forward_dynamics(Mb[k], hb[k], Ab[k], gb_[k]) for k in range(200)]},
                    target_s=target_s * 4, repeats=max(3, repeats // 2))  # fmt: skip
    out["large_batched"] = {"N": 200, **{k: _us(v, 200) for k, v in gt.items()}}
    out["machine"]["loadavg_end"] = list(os.getloadavg())
    return out


def _opt(t: dict[str, float] | None, spec: str = ".2f", cpu: bool = False) -> str:
    """A timing's median (and CPU median) as text, or '' when it was not measured."""
    if t is None:
        return ""
    med = format(t["median_us"], spec)
    return f"{med} / {format(t['cpu_median_us'], spec)}" if cpu else med


def engine_markdown(res: dict[str, Any]) -> str:
    """Tables of :func:`engine_bench`."""
    info = res["machine"]
    L = [
        f"Run {info['date_utc']} UTC, nonmin {info['nonmin_commit']}, Pinocchio "
        f"{info['pinocchio']}, {info['cpu']} ({info['logical_cpus']} logical CPUs). Load average "
        f"at start {', '.join(f'{x:.2f}' for x in info['loadavg_start'])}, at end "
        f"{', '.join(f'{x:.2f}' for x in info['loadavg_end'])}: the machine is shared, wall "
        "times are noisy (CPU times beside them); ratios come from the same run, interleaved.",
        "",
        "**Single call, given M, h, J, γ** (µs, median wall / median CPU). `ratio` = engine "
        "forward_dynamics / Pinocchio forwardDynamics (KKT), both called from Python; `C++ "
        "loop`: the kernels alone (engine Solver; Pinocchio's KKT algorithm in Eigen).",
        "",
        "| mechanism | n | rows of J | engine fd | numba fd | pin KKT | ratio wall | ratio CPU "
        "| C++ loop engine | C++ loop Eigen KKT | max rel. Δq̈ |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in res["chains"]:
        s = r["single"]
        e, p = s["engine_forward_dynamics"], s["pin_kkt_forwardDynamics"]
        nb = s.get("numba_forward_dynamics")
        L.append(
            f"| {r['mechanism']} | {r['n']} | {r['m']} | {e['median_us']:.2f} / {e['cpu_median_us']:.2f} | "
            f"{_opt(nb)} | "
            f"{p['median_us']:.2f} / {p['cpu_median_us']:.2f} | {e['median_us'] / p['median_us']:.2f} | "
            f"{e['cpu_median_us'] / p['cpu_median_us']:.2f} | "
            f"{r['kernel_cxx_loop_us']['engine_solver']:.2f} | {r['kernel_cxx_loop_us']['eigen_kkt']:.2f} | "
            f"{r['max_rel_diff_vs_pin_kkt']:.1e} |"
        )
    L += ["", "**Batched, 10⁴ states** (µs per state, median wall / CPU): one engine call "
          "(default threads and 1 thread) against a Python loop of Pinocchio's KKT solve.", "",
          "| mechanism | engine (threads) | engine 1 thread | pin KKT loop | ratio (default) | "
          "bitwise = single |", "|---|---:|---:|---:|---:|---|"]  # fmt: skip
    for r in res["chains"]:
        b = r["batched"]
        e, e1, p = (b["engine_forward_dynamics_default"], b["engine_forward_dynamics_1_thread"],
                    b["pin_kkt_forwardDynamics_loop"])  # fmt: skip
        L.append(f"| {r['mechanism']} | {e['median_us']:.3f} / {e['cpu_median_us']:.3f} "
                 f"({b['threads_default']}) | {e1['median_us']:.3f} / {e1['cpu_median_us']:.3f} | "
                 f"{p['median_us']:.3f} / {p['cpu_median_us']:.3f} | "
                 f"{e['median_us'] / p['median_us']:.2f} | {r['batch_equals_single_bitwise']} |")  # fmt: skip
    L += ["", "**A02 N = 40** (n = 243, 242 rows; µs, median wall / CPU). No Pinocchio model: "
          "the peer is the dense KKT solve (NumPy from Python; Eigen in a C++ loop).", "",
          "| state | rank (method) | engine fd | numba fd | NumPy dense KKT | C++ loop engine "
          "| C++ loop Eigen KKT | ratio engine / NumPy KKT |", "|---|---:|---:|---:|---:|---:|---:|---:|"]  # fmt: skip
    meth = {0: "SVD", 1: "LQ", 2: "LQ profile"}
    for r in res["large"]:
        s, k = r["single"], r["kernel_cxx_loop_us"]
        e = s["engine_forward_dynamics"]
        npk = s.get("numpy_dense_kkt_solve")
        nb = s.get("numba_forward_dynamics")
        ratio = "" if npk is None else f"{e['median_us'] / npk['median_us']:.3f}"
        L.append(f"| {r['case']} | {r['rank']} ({meth[r['method']]}) | {_opt(e, '.0f', True)} | "
                 f"{_opt(nb, '.0f')} | {_opt(npk, '.0f', True) if npk else 'singular'} | "
                 f"{k['engine_solver']:.0f} | {k.get('eigen_kkt', float('nan')):.0f} | "
                 f"{ratio} |")  # fmt: skip
    lb = res["large_batched"]
    L += ["", f"A02 N = 40, 200 states (crank 0.2…1.4 rad): one batched engine call "
          f"{lb['engine_forward_dynamics_batch_200']['median_us']:.0f} µs/state (CPU "
          f"{lb['engine_forward_dynamics_batch_200']['cpu_median_us']:.0f}), a loop of single "
          f"calls {lb['engine_forward_dynamics_loop_200']['median_us']:.0f} µs/state."]  # fmt: skip
    return "\n".join(L)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="small sizes, few repeats")
    parser.add_argument("--no-readme", action="store_true", help="do not rewrite README.md")
    parser.add_argument(
        "--batch-n12", action="store_true",
        help="only nonmin's batched path at n = 12 over 10^4 states (no files written)",
    )  # fmt: skip
    parser.add_argument(
        "--large", action="store_true",
        help="only single calls at n = 243 (A02 N = 40 and random sparse), compiled vs NumPy",
    )  # fmt: skip
    parser.add_argument(
        "--engine", action="store_true",
        help="the C++ engine like for like (chains n ≤ 6 and A02 N = 40; see engine_bench)",
    )  # fmt: skip
    args = parser.parse_args(argv)
    if args.engine:
        res = engine_bench(args.quick)
        RESULTS.mkdir(parents=True, exist_ok=True)
        stem = "core_bench_engine_quick" if args.quick else "core_bench_engine"
        (RESULTS / f"{stem}.json").write_text(json.dumps(res, indent=1))
        table = engine_markdown(res)
        print(table)
        if not args.quick and not args.no_readme:
            block = (f"{ENGINE_BEGIN}\n<!-- generated by: python benchmarks/core_bench.py "
                     f"--engine -->\n\n{table}\n\n{ENGINE_END}")  # fmt: skip
            text = README.read_text() if README.exists() else "# Benchmarks\n"
            if ENGINE_BEGIN in text and ENGINE_END in text:
                head, rest = text.split(ENGINE_BEGIN, 1)
                text = head + block + rest.split(ENGINE_END, 1)[1]
            else:
                text = text.rstrip("\n") + "\n\n" + block + "\n"
            README.write_text(text)
        return 0
    if args.large:
        large()
        return 0
    if args.batch_n12:
        batch_n12()
        return 0
    if args.quick:
        mechs = [("planar", 3), ("planar", 12), ("spatial", 6)]
        sizes, target_s, repeats, n_check = [1, 100, 1000], 0.01, 3, 20
    else:
        mechs = [("planar", 3), ("planar", 6), ("planar", 12), ("planar", 20), ("planar", 30),
                 ("spatial", 6), ("spatial", 12), ("spatial", 20), ("spatial", 30)]  # fmt: skip
        sizes, target_s, repeats, n_check = [1, 10, 100, 1000, 10000], 0.05, 7, 200
    import nonmin.core as core

    core.set_backend("engine")
    info = machine_info()
    results: dict[str, Any] = {"machine": info, "quick": args.quick, "mechanisms": []}
    print("first-call (JIT) times ...", flush=True)
    results["jit"] = jit_times()
    for kind, n in mechs:
        print(f"{kind}-{n} ...", flush=True)
        rec = bench_mechanism(kind, n, sizes, target_s=target_s, repeats=repeats, n_check=n_check)
        results["mechanisms"].append(rec)
        s = rec["single"]
        print(
            f"  single: engine {s['nonmin_engine_forward_dynamics']['median_us']:.2f} us, "
            f"pin {s['pin_constraintDynamics']['median_us']:.2f} us; max rel diff "
            f"{rec['accuracy']['max_rel_diff_engine_vs_pin_constraintDynamics']:.1e}",
            flush=True,
        )
    info["loadavg_end"] = list(os.getloadavg())
    RESULTS.mkdir(parents=True, exist_ok=True)
    stem = "core_bench_quick" if args.quick else "core_bench"
    (RESULTS / f"{stem}.json").write_text(json.dumps(results, indent=1))
    write_csv(results, RESULTS / f"{stem}.csv")
    table = markdown(results)
    print(table)
    if not args.quick and not args.no_readme:
        update_readme(table, "python benchmarks/core_bench.py")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
