"""The numbers of docs/theory.md's "Impulses of an impact by name" row:
``python tests/sim/measure_impulses.py`` (both drivers; closed forms and a KKT solve with
multipliers, as in tests/sim/test_sim_impulses.py)."""

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import test_sim_impulses as T

from nonmin.sim import simulate

G = 9.81
for engine in ("python", "auto"):
    e = 0.4
    model = T._bar({"l": -1.0, "r": 0.5})
    tr = simulate(
        model, 0.4, [0, 0.5, 0], [0, 0, 0], restitution=e, dt=1e-3, engine=engine, progress=False
    )
    ev = tr.events[0]
    v = np.sqrt(2 * G * 0.5)
    tot = 1.4 * v
    err = max(
        abs(ev.impulses["floor_l"].multipliers[0] - tot / 3),
        abs(ev.impulses["floor_r"].multipliers[0] - 2 * tot / 3),
    )
    # reopen
    bb = 0.2
    model = T._bar({"l": -1.0, "r": bb})
    q0, qd0 = T._tilted_bar_state(bb)
    tr = simulate(
        model,
        1.0,
        q0,
        qd0,
        active={"floor_l"},
        restitution=0.5,
        dt=1e-3,
        engine=engine,
        progress=False,
    )
    ev = next(x for x in tr.events if x.name == "impact:floor_r")
    vx, vy, w = ev.qd_before
    u = vy + bb * w
    lam = -(1.5) * u / (1 + bb * bb / T.I_BAR)
    want = np.array([vx, vy + lam, w + bb * lam / T.I_BAR])
    e2 = np.abs(ev.qd_after - want).max()
    e3 = abs(ev.impulses["floor_r"].multipliers[0] - lam)
    # kept closed vs KKT
    bb = 1.0
    model = T._bar({"l": -1.0, "r": bb})
    q0, qd0 = T._tilted_bar_state(bb)
    tr = simulate(
        model,
        1.0,
        q0,
        qd0,
        active={"floor_l"},
        restitution=0.5,
        dt=1e-3,
        engine=engine,
        progress=False,
    )
    ev = next(x for x in tr.events if x.name == "impact:floor_r")
    M = model.mass_matrix(ev.q_before)
    A = np.array([[0, 1, -1.0], [0, 1, bb]])
    uu = A @ ev.qd_before
    vr, lr = T._kkt_impact(M, A, ev.qd_before, np.array([0, -0.5 * uu[1]]))
    got = [ev.impulses[f"floor_{k}"].multipliers[0] for k in "lr"]
    print(
        engine,
        f"lever {err:.1e} (of {tot:.3f}) | reopen qd {e2:.1e} lam {e3:.1e} (lam {lam:.3f}) | kkt qd {np.abs(ev.qd_after - vr).max():.1e} lam {np.abs(np.array(got) - lr).max():.1e} (lam {lr})",
    )
