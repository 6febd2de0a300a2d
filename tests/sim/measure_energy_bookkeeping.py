"""The numbers of docs/theory.md's "Energy bookkeeping" section (issue #23): the friction work
against closed forms, its order on the spring-block oscillator, the impact losses of a bouncing
ball (the cases of tests/sim/test_energy_bookkeeping.py).

    python tests/sim/measure_energy_bookkeeping.py
"""

import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_energy_bookkeeping import (
    G,
    _ball,
    _incline,
    _spring_block,
    _stick_slip_oscillator,
    _up_and_back,
)

from nonmin.sim import simulate
from nonmin.viz import energy_balance

theta, mu, v0, mass = 0.5, 0.3, 2.0, 1.7
m = _incline(theta, mu, mass)
u = np.array([math.cos(theta), math.sin(theta)])
for method in ("rk4", "dopri5", "dop853", "midpoint"):
    for t_eval in (None, np.linspace(0, 1, 7)):
        tr = simulate(m, 1.0, [0.0, 0.0], v0 * u, method=method, dt=1e-3, t_eval=t_eval, progress=False)
        ref = -mu * mass * G * math.cos(theta) * _up_and_back(tr.t, theta, mu, v0)
        b = energy_balance(tr, m)
        assert b is not None
        print(f"incline {method:8s} t_eval={t_eval is not None!s:5s} "
              f"|W_fr - ref| = {np.max(np.abs(tr.friction_work - ref)):.1e} J, W_fr(end) = {tr.friction_work[-1]:.4f} J, "
              f"drift = {np.max(np.abs(b.balance)):.1e} J, max|E - E0| = {np.max(np.abs(tr.energy - tr.energy[0])):.3f} J")  # fmt: skip
mu, k, mass, x0 = 0.1, 10.0, 1.0, 0.3
m = _spring_block(mu, k, mass)
for method in ("rk4", "dopri5", "dop853"):
    for dt in (1e-2, 5e-3, 1e-3):
        tr = simulate(m, 2.5, [x0, 0.0], [0.0, 0.0], method=method, dt=dt, rtol=1e-11, atol=1e-12,
                      t_eval=np.linspace(0, 2.5, 101), progress=False)  # fmt: skip
        _, path = _stick_slip_oscillator(tr.t, x0, mu, k, mass)
        b = energy_balance(tr, m)
        assert b is not None
        print(f"spring-block {method:7s} dt={dt:g}: |W_fr - ref| = {np.max(np.abs(tr.friction_work + mu * mass * G * path)):.1e} J, "
              f"drift = {np.max(np.abs(b.balance)):.1e} J, steps = {tr.n_steps}")  # fmt: skip
e, h, mass = 0.6, 1.0, 0.8
for engine in ("auto", "python"):
    mb = _ball(e, mass)
    tr = simulate(mb, 1.5, [0.0, h], [0.3, 0.0], dt=1e-3, restitution=e, engine=engine,
                  t_eval=np.linspace(0, 1.5, 31), progress=False)  # fmt: skip
    b = energy_balance(tr, mb)
    assert b is not None
    v = math.sqrt(2 * G * h)
    n_imp = sum(ev.name.startswith("impact") for ev in tr.events)
    ref = sum((1 - e**2) * 0.5 * mass * (v * e**i) ** 2 for i in range(n_imp))
    print(f"ball ({engine}): {n_imp} impacts, L_imp = {tr.impact_loss[-1]:.9f} J, closed form {ref:.9f} J, "
          f"drift = {np.max(np.abs(b.balance)):.1e} J")  # fmt: skip
