"""The rank-revealing certified LQ on a permanently redundant constraint (A04 Bricard, n = 35,
35 rows of rank 34): CPU time of one engine solve (``_engine.core_solve_info``: equilibration,
rank decision, M̄, q̈, f_c) at states along a run, certified LQ with the redundant row skipped
against the SVD fallback that the same build takes when that row is moved 1e-11 off the span
(the path every evaluation took before the rows were skipped).

    python benchmarks/redundant_lq_bench.py [--states 20] [--calls 2000]
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import time

import numpy as np

METHODS = {0: "SVD", 1: "LQ (dense L⁻¹)", 2: "LQ (profile)"}


def main() -> None:
    from nonmin import _engine as E
    from nonmin import library, simulate

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--states", type=int, default=20)
    ap.add_argument("--calls", type=int, default=2000)
    args = ap.parse_args()
    mech = library.get("A04_bricard")
    model = mech.model
    tr = simulate(mech, (0.0, 5.0), method="dop853", rtol=1e-10, atol=1e-12,
                  t_eval=np.linspace(0.0, 5.0, args.states), progress=False)
    per: dict[str, list[float]] = {"certified": [], "fallback": []}
    for q, qd in zip(np.asarray(tr.q), np.asarray(tr.qd), strict=True):
        ct = model.constraint_terms(0.0, q, qd, mech.state.active)
        A = np.ascontiguousarray(ct.A)
        M = np.ascontiguousarray(model.mass_matrix(q))
        h = np.asarray(model.conservative_force(q) - model.coriolis_force(q, qd), dtype=float)
        g = np.asarray(ct.gamma, dtype=float)
        s = np.linalg.svd(A / np.linalg.norm(A, axis=1, keepdims=True))
        d = s[2][-1]  # the right singular vector of the vanishing σ: off the span of the rows
        Ap = A.copy()
        Ap[-1] += 1e-11 * np.linalg.norm(A[-1]) * d
        for key, Ak in (("certified", A), ("fallback", np.ascontiguousarray(Ap))):
            info = E.core_solve_info(M, h, Ak, g, 1e-10)
            want = 2 if key == "certified" else 0
            assert info["method"] == want and info["rank"] == A.shape[0] - 1, (key, info)
            c0 = time.process_time()
            for _ in range(args.calls):
                E.core_solve_info(M, h, Ak, g, 1e-10)
            per[key].append((time.process_time() - c0) / args.calls)
    a, b = np.median(per["certified"]), np.median(per["fallback"])
    print(f"A04 Bricard, {A.shape[0]} rows × {A.shape[1]}, {args.states} states, {args.calls} calls each, CPU per solve (median):")
    print(f"  certified LQ, redundant row skipped (rank 34): {a * 1e6:.1f} µs")
    print(f"  SVD fallback (the row 1e-11 off the span):      {b * 1e6:.1f} µs   ratio {b / a:.1f}×")


if __name__ == "__main__":
    main()
