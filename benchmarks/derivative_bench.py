"""Cost of the derivatives of the constrained dynamics: nonmin against Pinocchio (issue 21).

Per call, from Python, at the same state, from (q, v, τ) to ∂q̈/∂q, ∂q̈/∂v, ∂q̈/∂τ of an
example-robot-data arm whose tool is held in the world (``--cases``, default all three):
``ur5_point`` (UR5, a point: 3 rows, n = 6), ``panda_point`` (Panda, 3 rows, n = 9: 7 arm joints
and 2 finger slides) and ``panda_weld`` (Panda, a weld: 6 rows, n = 9). Peers:

* ``pinocchio``: ``constraintDynamics`` then ``computeConstraintDynamicsDerivatives``
  (analytical derivatives of the KKT solution; the forward pass is required first, so it is
  timed with it).
* ``nonmin-engine``: ``nonmin.linear.dynamics_derivatives`` (the pipeline in C++: the kernel at
  the state, the tangents of three residuals of the model terms in multi-direction forward
  mode, the kernel's derivative at its rank), with its Python validation and result object.
* ``nonmin-out``: the same call with ``out=`` (the previous call's result overwritten in
  place: no allocation, no new arrays; the loop form, as Pinocchio's calls reuse its ``Data``).
* ``nonmin-raw``: the engine's binding alone (``_engine.forward_derivatives`` into a new
  output block, views of the three Jacobians), to separate the wrapper's cost.
* ``nonmin-numpy``: the NumPy specification (terms' tangents from the engine, kernel in NumPy).

Two measures: wall time (interleaved repeats, median of per-call times; the load average is
recorded, the machine is shared) and, with ``--instructions``, the instructions per call
counted by callgrind (each peer in its own process, run for 0 and for ``--calls`` calls with
the cyclic garbage collector off after the first call: the difference over the calls;
reproducible under load, blind to cache and memory effects).
Run: ``python benchmarks/derivative_bench.py [--repeat R] [--calls C] [--instructions]
[--cases ur5_point,panda_point,panda_weld]``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

CASES = ("ur5_point", "panda_point", "panda_weld", "dual_arm_grasp")


def _robot(case: str) -> tuple[Any, np.ndarray, list[Any]]:
    from nonmin.model.robots import example_robot_closure, pinocchio_frame_constraint

    if case == "dual_arm_grasp":  # robot_bench.py's: two arms, a free-flying box (a quaternion)
        import robot_bench

        c = robot_bench.case_dual_arm(1.0)
        return c.model, c.q0, c.pin_constraints(c.model.pinocchio_model)
    arm, closure = case.split("_")
    model, state = example_robot_closure(arm, closure)
    return model, state.q, [pinocchio_frame_constraint(model)]


def _per_call(fn: Callable[[], Any], calls: int) -> float:
    """CPU time per call (process time: less sensitive to the shared machine's load)."""
    t0 = time.process_time()
    for _ in range(calls):
        fn()
    return (time.process_time() - t0) / calls


def _peers(
    case: str, with_numpy: bool = True
) -> tuple[dict[str, Callable[[], Any]], Any, dict[str, Any]]:
    """The peers at one state, ready to call; Pinocchio's reference Jacobians; case facts."""
    import pinocchio as pin

    from nonmin import _engine
    from nonmin.linear import dynamics_derivatives

    model, q0, cml = _robot(case)
    pm = model.pinocchio_model
    pd = pm.createData()
    cms = pin.StdVec_RigidConstraintModel()
    cds = pin.StdVec_RigidConstraintData()
    for cm in cml:
        cms.append(cm)
        cds.append(cm.createData())
    pin.initConstraintDynamics(pm, pd, cms, cds)
    prox = pin.ProximalSettings(1e-14, 1e-14, 1)
    rng = np.random.default_rng(0)
    A = model.constraint_jacobian(0.0, q0)
    Z = np.linalg.svd(A)[2][np.linalg.matrix_rank(A) :].T
    v = Z @ rng.standard_normal(Z.shape[1])
    tau = rng.standard_normal(model.n)
    # with a quaternion (n = nq > nv) the two are not the same coordinates: Pinocchio at a
    # tangent velocity of its own, timed only (the agreement is not computed)
    same = model.n == pm.nv
    qp = model.pinocchio_configuration(q0)
    vp = v if same else rng.standard_normal(pm.nv)
    taup = tau if same else rng.standard_normal(pm.nv)

    def pin_call() -> Any:
        pin.constraintDynamics(pm, pd, qp, vp, taup, cms, cds, prox)
        return pin.computeConstraintDynamicsDerivatives(pm, pd, cms, cds, prox)

    prog = model.engine_program()
    scratch = _engine.DerivativeScratch(prog)
    mask = model.active_mask(None)

    n, k = int(model.n), int(model.k)

    def raw_call() -> Any:
        blk = np.empty((2 + 6 * n + 2 * k, n))
        _engine.forward_derivatives(prog, scratch, 0.0, q0, v, tau, None, mask, 1e-10, blk)
        return blk[2 : 2 + n], blk[2 + n : 2 + 2 * n], blk[2 + 2 * n : 2 + 3 * n]

    held = dynamics_derivatives(model, q0, v, f=tau)
    peers: dict[str, Callable[[], Any]] = {
        "pinocchio": pin_call,
        "nonmin-engine": lambda: dynamics_derivatives(model, q0, v, f=tau),
        "nonmin-out": lambda: dynamics_derivatives(model, q0, v, f=tau, out=held),
        "nonmin-raw": raw_call,
    }
    if with_numpy:
        peers["nonmin-numpy"] = lambda: dynamics_derivatives(model, q0, v, f=tau, backend="numpy")
    ref = [np.array(x) for x in pin_call()[:3]] if same else None
    return peers, ref, {"case": case, "n": int(model.n), "nv": int(pm.nv), "rows": int(A.shape[0])}


def _instructions(case: str, names: list[str], calls: int) -> dict[str, float]:
    """Instructions per call of each peer: callgrind over 0 and over `calls` calls."""
    import re
    import subprocess
    import sys
    import tempfile

    out: dict[str, float] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name in names:
            total = []
            for c in (0, calls):
                res = subprocess.run(
                    ["valgrind", "--tool=callgrind", f"--callgrind-out-file={tmp}/cg.out",
                     sys.executable, __file__, "--peer", name, "--calls", str(c),
                     "--cases", case],
                    capture_output=True, text=True, check=True,
                )  # fmt: skip
                m = re.search(r"Collected : (\d+)", res.stderr)
                if m is None:
                    raise RuntimeError(f"callgrind gave no count for {name}: {res.stderr[-500:]}")
                total.append(int(m.group(1)))
            out[name] = (total[1] - total[0]) / calls
    return out


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=15)
    ap.add_argument("--calls", type=int, default=50)
    ap.add_argument(
        "--instructions", action="store_true", help="also count instructions (valgrind)"
    )
    ap.add_argument("--cases", default=",".join(CASES), help="comma-separated, of " + ", ".join(CASES))
    ap.add_argument("--peer", help=argparse.SUPPRESS)  # one peer, `--calls` calls (callgrind runs)
    ap.add_argument(
        "--json", type=Path, default=Path(__file__).parent / "results" / "derivative_bench.json"
    )
    args = ap.parse_args(argv)

    cases = args.cases.split(",")
    for case in cases:
        if case not in CASES:
            raise SystemExit(f"--cases: unknown case {case!r} (known: {', '.join(CASES)})")
    if args.peer is not None:
        import gc

        peers, _, _ = _peers(cases[0], with_numpy=args.peer == "nonmin-numpy")
        fn = peers[args.peer]
        fn()  # first call: imports, caches
        # the cyclic collector's passes over the whole heap (Pinocchio's and NumPy's objects)
        # would land in one run and not the other: counted work per call only
        gc.disable()
        for _ in range(args.calls):
            fn()
        return
    results: dict[str, Any] = {}
    for case in cases:
        results[case] = _run_case(case, args)
    out: dict[str, Any] = {
        "cases": results, "repeat": args.repeat, "calls": args.calls,
        "machine": {"python": platform.python_version(), "processor": platform.processor(), "cpus": os.cpu_count()},
        "date_utc": time.strftime("%Y-%m-%d %H:%M", time.gmtime()),
    }  # fmt: skip
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(out, indent=2))


def _run_case(case: str, args: argparse.Namespace) -> dict[str, Any]:
    peers, ref, facts = _peers(case)
    # agreement at this state (the check the tests make, repeated here)
    agreement: dict[str, float] = {}
    for name, fn in peers.items():
        if name == "pinocchio" or ref is None:
            continue
        d = fn()
        got = d if isinstance(d, tuple) else (d.dqdd_dq, d.dqdd_dqd, d.dqdd_df)
        agreement[name] = max(
            float(np.abs(a - b).max() / max(1.0, np.abs(b).max()))
            for a, b in zip(got, ref, strict=True)
        )
    for fn in peers.values():  # warm up
        _per_call(fn, 5)
    times: dict[str, list[float]] = {k: [] for k in peers}
    load0 = os.getloadavg()[0]
    for _ in range(args.repeat):
        for k, fn in peers.items():
            times[k].append(_per_call(fn, args.calls))
    load1 = os.getloadavg()[0]
    med = {k: float(np.median(v)) for k, v in times.items()}
    print(
        f"{case} (n = {facts['n']}, {facts['rows']} rows), median of {args.repeat} × "
        f"{args.calls} calls (CPU time), load {load0:.1f}–{load1:.1f}:"
    )
    for k, t in med.items():
        agree = f"   max rel. diff to Pinocchio {agreement[k]:.1e}" if k in agreement else ""
        print(f"  {k:15s} {t * 1e6:9.1f} µs/call   ratio {t / med['pinocchio']:.2f}{agree}")
    res: dict[str, Any] = {
        **facts, "median_s": med, "ratio_to_pinocchio": {k: t / med["pinocchio"] for k, t in med.items()},
        "agreement": agreement, "load": [load0, load1],
    }  # fmt: skip
    if args.instructions:
        ins = _instructions(
            case, ["pinocchio", "nonmin-engine", "nonmin-out", "nonmin-raw"], max(args.calls, 300)
        )
        print("  instructions per call (callgrind):")
        for k, c in ins.items():
            print(f"  {k:15s} {c:11.0f}   ratio {c / ins['pinocchio']:.2f}")
        res["instructions_per_call"] = ins
        res["instruction_ratio_to_pinocchio"] = {k: c / ins["pinocchio"] for k, c in ins.items()}
    return res


if __name__ == "__main__":
    main()
