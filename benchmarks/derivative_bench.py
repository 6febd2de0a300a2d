"""Cost of the derivatives of the constrained dynamics: nonmin against Pinocchio (issue 21).

Per call, from Python, at the same state: ∂q̈/∂q, ∂q̈/∂v, ∂q̈/∂τ of a UR5 whose end effector is
held at a point (3 closure rows, n = 6).

* Pinocchio: ``constraintDynamics`` then ``computeConstraintDynamicsDerivatives`` (analytical
  derivatives of the KKT solution; the forward pass is required first, so it is timed with it).
* nonmin: ``nonmin.linear.dynamics_derivatives`` (forward-mode model terms in the engine, the
  kernel's derivative at its rank) — ``engine`` when the compiled derivative pipeline is there,
  ``numpy`` the reference (terms from the engine, kernel derivative in NumPy).

Interleaved repeats, median of per-call times; the load average is recorded (the machine is
shared). Run: ``python benchmarks/derivative_bench.py [--repeat R] [--json PATH]``.
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


def main(argv: list[str] | None = None) -> None:
    import pinocchio as pin

    from nonmin.linear import dynamics_derivatives

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=15)
    ap.add_argument("--calls", type=int, default=50)
    ap.add_argument(
        "--json", type=Path, default=Path(__file__).parent / "results" / "derivative_bench.json"
    )
    args = ap.parse_args(argv)

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

    peers: dict[str, Callable[[], Any]] = {"pinocchio": pin_call}
    for backend in ("engine", "numpy"):
        try:
            dynamics_derivatives(model, q0, v, f=tau, backend=backend)  # type: ignore[call-arg]
        except TypeError:
            if backend == "numpy":
                peers["nonmin"] = lambda: dynamics_derivatives(model, q0, v, f=tau)
            continue
        peers[f"nonmin-{backend}"] = (
            lambda b: lambda: dynamics_derivatives(model, q0, v, f=tau, backend=b)
        )(backend)

    # agreement at this state (the check the tests make, repeated here)
    ref = [np.array(x) for x in pin_call()[:3]]
    for name, fn in peers.items():
        if name == "pinocchio":
            continue
        d = fn()
        err = max(
            np.abs(a - b).max() / max(1.0, np.abs(b).max())
            for a, b in zip((d.dqdd_dq, d.dqdd_dqd, d.dqdd_df), ref, strict=True)
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
    out = {
        "case": "ur5_point", "n": int(model.n), "rows": int(A.shape[0]), "median_s": med,
        "ratio_to_pinocchio": {k: t / med["pinocchio"] for k, t in med.items()},
        "repeat": args.repeat, "calls": args.calls, "load": [load0, load1],
        "machine": {"python": platform.python_version(), "processor": platform.processor(), "cpus": os.cpu_count()},
        "date_utc": time.strftime("%Y-%m-%d %H:%M", time.gmtime()),
    }  # fmt: skip
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
