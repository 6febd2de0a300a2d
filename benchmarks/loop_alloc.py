"""No allocation per step in the engine's loop: heap allocations counted during steps.

Builds a tiny malloc/realloc-counting library with the system C compiler, re-runs itself with
it preloaded (Linux), and counts the allocations made while the engine loop (``SimLoop.run``,
GIL released, compiled programs: no Python inside) takes 300 steps, after a first run has
grown the sample buffers (which are then reused). Every line should say 0.

    python benchmarks/loop_alloc.py
"""

from __future__ import annotations

import ctypes
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

SHIM = r"""
#define _GNU_SOURCE
#include <dlfcn.h>
#include <stddef.h>
static void* (*real_malloc)(size_t) = 0;
static void* (*real_realloc)(void*, size_t) = 0;
static volatile long count = 0;
static int on = 0;
void nonmin_count_on(void) { count = 0; on = 1; }
long nonmin_count_off(void) { on = 0; return count; }
void* malloc(size_t n) {
    if (!real_malloc) real_malloc = dlsym(RTLD_NEXT, "malloc");
    if (on) __atomic_add_fetch(&count, 1, __ATOMIC_RELAXED);
    return real_malloc(n);
}
void* realloc(void* p, size_t n) {
    if (!real_realloc) real_realloc = dlsym(RTLD_NEXT, "realloc");
    if (on) __atomic_add_fetch(&count, 1, __ATOMIC_RELAXED);
    return real_realloc(p, n);
}
"""


def _count(name: str, model: object, q0: np.ndarray, qd0: np.ndarray, active: frozenset[str],
           integ: object, stab: object, t_out: np.ndarray | None = None) -> None:  # fmt: skip
    from nonmin.sim import _engine as E
    from nonmin.sim._simulate import model_mask

    lib = ctypes.CDLL(None)
    lib.nonmin_count_off.restype = ctypes.c_long
    prog = E.program_for(model)  # type: ignore[arg-type]
    o = E.options(integ, stab, dt=1e-3, t1=5.0, h0=0.0, rank_rtol=None, drift_factor=1.0,
                  project_initial=True, max_steps=10**7)  # fmt: skip
    tv = np.zeros(0) if t_out is None else t_out
    loop = E._engine().SimLoop(prog, model_mask(model, active), o, tv, t_out is None)  # type: ignore[arg-type]
    loop.start(0.0, q0, qd0)
    loop.take()
    lib.nonmin_count_on()
    loop.run(300)
    first = lib.nonmin_count_off()
    loop.take()  # cleared, capacity kept
    lib.nonmin_count_on()
    loop.run(300)
    steady = lib.nonmin_count_off()
    print(f"{name:42s} {type(prog).__name__:14s} first 300 steps: {first:4d}   next 300 steps: {steady}")


def measure() -> None:
    from nonmin import library
    from nonmin.sim import RK4, Baumgarte, DormandPrince5, ImplicitMidpoint, Projection

    mech = library.get("crossed_four_bar")
    st = mech.state
    for integ, stab in ((RK4(), Projection()), (DormandPrince5(), Projection()),
                        (ImplicitMidpoint(), Projection()), (RK4(), Baumgarte())):  # fmt: skip
        _count(f"crossed_four_bar {integ.name} {stab.name}", mech.model, st.q, st.qd, st.active, integ, stab)
    _count("crossed_four_bar rk4 projection t_eval", mech.model, st.q, st.qd, st.active, RK4(), Projection(),
           np.arange(0.0, 5.0, 3e-4))  # fmt: skip
    try:
        sys.path.insert(0, str(Path(__file__).resolve().parent))
        import robot_bench as rb

        for nm in ("ur5_point", "dual_arm_grasp"):
            case = rb.CASES[nm](1.0)
            m = case.model
            _count(nm, m, case.q0, np.zeros(m.n), m.default_active, RK4(), Projection())
    except ImportError as exc:
        print(f"robots skipped ({exc})")


def main() -> None:
    if os.environ.get("NONMIN_ALLOC_CHILD"):
        measure()
        return
    with tempfile.TemporaryDirectory() as d:
        src = Path(d) / "count.c"
        so = Path(d) / "libcount.so"
        src.write_text(SHIM)
        subprocess.run(["cc", "-O2", "-shared", "-fPIC", "-o", str(so), str(src), "-ldl"], check=True)
        env = dict(os.environ, LD_PRELOAD=str(so), NONMIN_ALLOC_CHILD="1")
        subprocess.run([sys.executable, __file__], env=env, check=True)


if __name__ == "__main__":
    main()
