"""Cost of the derivatives of the constrained dynamics: nonmin against Pinocchio (issue 21).

Per call, from Python, at the same state, from (q, v, τ) to ∂q̈/∂q, ∂q̈/∂v, ∂q̈/∂τ of a UR5
whose end effector is held at a point (3 closure rows, n = 6):

* ``pinocchio``: ``constraintDynamics`` then ``computeConstraintDynamicsDerivatives``
  (analytical derivatives of the KKT solution; the forward pass is required first, so it is
  timed with it).
* ``nonmin-engine``: ``nonmin.linear.dynamics_derivatives`` (the pipeline in C++: the kernel at
  the state, the tangents of three residuals of the model terms in multi-direction forward
  mode, the kernel's derivative at its rank), with its Python validation and result object.
* ``nonmin-raw``: the engine's binding alone (``_engine.forward_derivatives``), to separate
  the wrapper's cost.
* ``nonmin-numpy``: the NumPy specification (terms' tangents from the engine, kernel in NumPy).

Two measures: wall time (interleaved repeats, median of per-call times; the load average is
recorded, the machine is shared) and, with ``--instructions``, the instructions per call
counted by callgrind (each peer in its own process, run for 0 and for ``--calls`` calls: the
difference over the calls; reproducible under load, blind to cache and memory effects).
Run: ``python benchmarks/derivative_bench.py [--repeat R] [--calls C] [--instructions]``.
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


def _ur5() -> tuple[Any, np.ndarray, Any]:
    from nonmin.model.robots import pinocchio_point_constraint, ur5_point_closure

    model, state = ur5_point_closure()
    return model, state.q, pinocchio_point_constraint(model)


def _per_call(fn: Callable[[], Any], calls: int) -> float:
    t0 = time.perf_counter()
    for _ in range(calls):
        fn()
    return (time.perf_counter() - t0) / calls


def _peers(with_numpy: bool = True) -> tuple[dict[str, Callable[[], Any]], Any, dict[str, Any]]:
    """The peers at one state, ready to call; Pinocchio's reference Jacobians; case facts."""
    import pinocchio as pin

    from nonmin import _engine
    from nonmin.linear import dynamics_derivatives

    model, q0, cm = _ur5()
    pm = model.pinocchio_model
    pd = pm.createData()
    cms = pin.StdVec_RigidConstraintModel()
    cms.append(cm)
    cds = pin.StdVec_RigidConstraintData()
    cds.append(cm.createData())
    pin.initConstraintDynamics(pm, pd, cms, cds)
    prox = pin.ProximalSettings(1e-14, 1e-14, 1)
    rng = np.random.default_rng(0)
    A = model.constraint_jacobian(0.0, q0)
    Z = np.linalg.svd(A)[2][A.shape[0] :].T
    v = Z @ rng.standard_normal(Z.shape[1])
    tau = rng.standard_normal(pm.nv)

    def pin_call() -> Any:
        pin.constraintDynamics(pm, pd, q0, v, tau, cms, cds, prox)
        return pin.computeConstraintDynamicsDerivatives(pm, pd, cms, cds, prox)

    prog = model.engine_program()
    scratch = _engine.DerivativeScratch(prog)
    mask = model.active_mask(None)

    def raw_call() -> Any:
        return _engine.forward_derivatives(prog, scratch, 0.0, q0, v, tau, None, mask, 1e-10)

    peers: dict[str, Callable[[], Any]] = {
        "pinocchio": pin_call,
        "nonmin-engine": lambda: dynamics_derivatives(model, q0, v, f=tau),
        "nonmin-raw": raw_call,
    }
    if with_numpy:
        peers["nonmin-numpy"] = lambda: dynamics_derivatives(model, q0, v, f=tau, backend="numpy")
    ref = [np.array(x) for x in pin_call()[:3]]
    return peers, ref, {"case": "ur5_point", "n": int(model.n), "rows": int(A.shape[0])}


def _instructions(names: list[str], calls: int) -> dict[str, float]:
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
                     sys.executable, __file__, "--peer", name, "--calls", str(c)],
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
    ap.add_argument("--peer", help=argparse.SUPPRESS)  # one peer, `--calls` calls (callgrind runs)
    ap.add_argument(
        "--json", type=Path, default=Path(__file__).parent / "results" / "derivative_bench.json"
    )
    args = ap.parse_args(argv)

    if args.peer is not None:
        peers, _, _ = _peers(with_numpy=args.peer == "nonmin-numpy")
        fn = peers[args.peer]
        fn()  # first call: imports, caches
        for _ in range(args.calls):
            fn()
        return

    peers, ref, case = _peers()
    # agreement at this state (the check the tests make, repeated here)
    for name, fn in peers.items():
        if name == "pinocchio":
            continue
        d = fn()
        got = (
            (d["dqdd_dq"], d["dqdd_dqd"], d["dqdd_df"])
            if isinstance(d, dict)
            else (d.dqdd_dq, d.dqdd_dqd, d.dqdd_df)
        )
        err = max(
            np.abs(a - b).max() / max(1.0, np.abs(b).max()) for a, b in zip(got, ref, strict=True)
        )
        print(f"{name}: max relative difference to Pinocchio {err:.1e}")

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
        f"UR5 + point closure (n = 6, 3 rows), median of {args.repeat} × {args.calls} calls, load {load0:.1f}–{load1:.1f}:"
    )
    for k, t in med.items():
        print(f"  {k:15s} {t * 1e6:9.1f} µs/call   ratio to Pinocchio {t / med['pinocchio']:.2f}")
    out: dict[str, Any] = {
        **case, "median_s": med,
        "ratio_to_pinocchio": {k: t / med["pinocchio"] for k, t in med.items()},
        "repeat": args.repeat, "calls": args.calls, "load": [load0, load1],
        "machine": {"python": platform.python_version(), "processor": platform.processor(), "cpus": os.cpu_count()},
        "date_utc": time.strftime("%Y-%m-%d %H:%M", time.gmtime()),
    }  # fmt: skip
    if args.instructions:
        ins = _instructions(["pinocchio", "nonmin-engine", "nonmin-raw"], max(args.calls, 100))
        print("instructions per call (callgrind):")
        for k, c in ins.items():
            print(f"  {k:15s} {c:11.0f}   ratio to Pinocchio {c / ins['pinocchio']:.2f}")
        out["instructions_per_call"] = ins
        out["instruction_ratio_to_pinocchio"] = {k: c / ins["pinocchio"] for k, c in ins.items()}
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
