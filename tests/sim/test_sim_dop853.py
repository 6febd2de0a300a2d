"""DOP853 (``method="dop853"``): the tableau's orders (8 for the step, 7 for the continuous
extension) on ODEs with closed-form solutions, the engine against the general driver, and its
accuracy on the IFToMM mechanisms against their exact references (issue 18)."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from conftest import forced_oscillator, forced_oscillator_exact
from nonmin import library
from nonmin.core import use_backend
from nonmin.library import n_four_bar_reference
from nonmin.sim import DOP853, METHODS, Solver, StepperState, simulate
from nonmin.sim import _dop853_tableau as tab


def test_tableau_conditions() -> None:
    """Row sums of A equal the nodes; b sums to 1 and has the quadrature orders to 8; the error
    estimates annihilate constants."""
    for s in range(1, 16):
        assert abs(tab.A[s, :s].sum() - tab.C[s]) < 1e-14, s
    c = tab.C[:12]
    for k in range(8):  # Σ b_j c_j^k = 1/(k + 1)
        assert abs(tab.B @ c**k - 1.0 / (k + 1)) < 1e-13, k
    assert abs(tab.E5.sum()) < 1e-13 and abs(tab.E3.sum()) < 1e-13


def test_step_is_order_8_and_dense_output_order_7() -> None:
    integ = DOP853()
    y0 = forced_oscillator_exact(0.0)
    errs, dense_errs = [], []
    hs = [0.4, 0.2, 0.1]
    for h in hs:
        y1 = integ.advance(forced_oscillator, 0.0, y0, None, h)
        errs.append(float(np.max(np.abs(y1 - forced_oscillator_exact(h)))))
        res = DOP853(rtol=1e3, atol=1e3).step(forced_oscillator, StepperState(0.0, y0, None, h), 10.0)
        assert res.h == h and res.dense is not None
        dense_errs.append(max(float(np.max(np.abs(res.dense(th) - forced_oscillator_exact(th)))) for th in (0.3 * h, 0.5 * h, 0.77 * h)))
    p_step = np.log2(np.array(errs[:-1]) / np.array(errs[1:]))
    p_dense = np.log2(np.array(dense_errs[:-1]) / np.array(dense_errs[1:]))
    # local errors: O(h^9) for the step, O(h^8) for the interpolant
    assert np.all(p_step > 8.5), p_step
    assert np.all(p_dense > 7.5), p_dense


def test_adaptive_run_meets_its_tolerance_on_an_ode() -> None:
    integ = DOP853(rtol=1e-11, atol=1e-13)
    st = StepperState(0.0, forced_oscillator_exact(0.0), None, 0.0)
    steps = 0
    while st.t < 10.0:
        res = integ.step(forced_oscillator, st, 10.0)
        st = res.state
        steps += 1
    assert st.t == 10.0 and steps < 200
    assert float(np.max(np.abs(st.y - forced_oscillator_exact(10.0)))) < 1e-9


def test_registered_and_resolved() -> None:
    assert METHODS["dop853"] is DOP853
    tr = simulate(library.get("A01_pendulum"), (0.0, 0.5), solver=Solver("dop853", rtol=1e-9), progress=False)
    assert tr.success and tr.metadata["engine"] == "engine"
    assert tr.metadata["options"]["method"] == "dop853"


def _pair(mech: Any, **kw: Any) -> tuple[Any, Any]:
    a = simulate(mech, engine="engine", progress=False, **kw)
    with use_backend("numpy"):
        b = simulate(mech, engine="python", progress=False, **kw)
    return a, b


@pytest.mark.parametrize(("name", "stab"), [("A01_pendulum", "projection"), ("slider_crank", "projection"),
                                           ("crossed_four_bar", "projection"), ("A01_pendulum", "none"),
                                           ("slider_crank", "none")])  # fmt: skip
def test_engine_equals_general_driver(name: str, stab: str) -> None:
    """Same method in C++ and Python: the same steps (to the tolerance's reach, as DOPRI5's
    error on projected solutions is a difference at round-off level) and samples from the
    continuous extension to the tolerance. (Without a projection the crossed four-bar drifts off
    its constraints and the two step sequences part at its first change point, the passage
    zone's discrete choice: q differs by 5.1e-6 there, so that case is not compared.)"""
    mech = library.get(name)
    te = np.linspace(0.0, 0.3, 31)
    a, b = _pair(mech, t_span=(0.0, 0.3), method="dop853", rtol=1e-9, atol=1e-11, t_eval=te, stabilization=stab)
    assert a.metadata["engine"] == "engine" and b.metadata["engine"] == "python"
    assert a.success and b.success
    assert abs(a.n_steps - b.n_steps) <= 1
    tol = 1e-7
    for f in ("q", "qd", "energy"):
        x, y = getattr(a, f), getattr(b, f)
        assert float(np.max(np.abs(x - y))) < tol * max(1.0, float(np.max(np.abs(y)))), f


def test_a01_period_and_energy() -> None:
    """IFToMM A01: P1(10 s) = (0.275087462576117, −0.961419205099125) (published)."""
    mech = library.get("A01_pendulum")
    tr = simulate(mech, (0.0, 10.0), solver=Solver("dop853", rtol=1e-12, atol=1e-14), t_eval=[0.0, 10.0],
                  progress=False)  # fmt: skip
    assert np.max(np.abs(tr.q[-1] - [0.275087462576117, -0.961419205099125])) < 1e-9
    assert abs(tr.energy[-1] - tr.energy[0]) < 1e-10


def test_a02_n2_through_singular_passages() -> None:
    """A02 N = 2, 10 s (every horizontal configuration a rank drop): B0 against the exact
    1-DOF reduction, energy drift, and no reject storm at the passages."""
    mech = library.get("A02_n_four_bar", N=2)
    te = np.linspace(0.0, 10.0, 1001)
    tr = simulate(mech, (0.0, 10.0), solver=Solver("dop853", rtol=1e-10, atol=1e-12), t_eval=te, progress=False)
    assert tr.success
    ref = n_four_bar_reference(te, N=2)
    b0 = tr.outputs(mech.model)["B0.position"]
    err = float(np.max(np.linalg.norm(b0 - ref["B0.position"], axis=1)))
    assert err < 1e-8, err  # measured 4.3e-9 m (DOPRI5 at the same rtol: 5.8e-7 m)
    # samples from the 7th-order continuous extension of steps ~0.05 s long: 1.2e-8 J measured
    # (the step ends: 1.3e-9 J)
    assert float(np.max(np.abs(tr.energy - tr.energy[0]))) < 3e-8
    assert tr.n_rejected < 0.25 * tr.n_steps, (tr.n_rejected, tr.n_steps)  # 38 of 193
