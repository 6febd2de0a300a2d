"""RK8: DOP853's 8th-order stages with a fixed step and no error estimate (issue 18, target 4:
the coarse setting at Pinocchio's accuracy on A02 N = 2)."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from conftest import forced_oscillator, forced_oscillator_exact
from nonmin import library
from nonmin.core import use_backend
from nonmin.errors import InputError
from nonmin.library import n_four_bar_reference
from nonmin.sim import DOP853, METHODS, RK8, Solver, StepperState, simulate
from nonmin.sim import _dop853_tableau as tab


def test_one_step_is_dop853s_y1_and_order_8() -> None:
    """A step is DOP853's y₁ = y + hΣb_j k_j (the same stages, to round-off), whose local error
    is O(h⁹); over a fixed span the global error falls at order 8."""
    y0 = forced_oscillator_exact(0.0)
    for h in (0.4, 0.2):
        a = RK8(dt=h).advance(forced_oscillator, 0.0, y0, None, h)
        K = np.empty((12, 2))
        K[0] = forced_oscillator(0.0, y0)
        for s in range(1, 12):
            K[s] = forced_oscillator(tab.C[s] * h, y0 + h * (tab.A[s, :s] @ K[:s]))
        assert float(np.max(np.abs(a - (y0 + h * (tab.B @ K))))) < 1e-15
        assert float(np.max(np.abs(a - DOP853().advance(forced_oscillator, 0.0, y0, None, h)))) < 1e-15
    errs = []
    hs = [0.5, 0.25, 0.125]
    for h in hs:
        st = StepperState(0.0, y0, None, h)
        while st.t < 5.0 - 1e-12:
            st = RK8(dt=h).step(forced_oscillator, st, 5.0).state
        errs.append(float(np.max(np.abs(st.y - forced_oscillator_exact(5.0)))))
    p = np.log2(np.array(errs[:-1]) / np.array(errs[1:]))
    assert np.all(p > 7.5), (errs, p)


def test_registered_and_resolved() -> None:
    assert METHODS["rk8"] is RK8
    tr = simulate(library.get("A01_pendulum"), (0.0, 0.5), solver=Solver("rk8", dt=0.05), progress=False)
    assert tr.success and tr.metadata["engine"] == "engine"
    assert tr.metadata["options"]["method"] == "rk8" and tr.n_steps == 10


def _pair(mech: Any, **kw: Any) -> tuple[Any, Any]:
    a = simulate(mech, engine="engine", progress=False, **kw)
    with use_backend("numpy"):
        b = simulate(mech, engine="python", progress=False, **kw)
    return a, b


@pytest.mark.parametrize(("name", "dt", "t_eval"), [("A01_pendulum", 0.05, False), ("slider_crank", 0.01, True),
                                                    ("crossed_four_bar", 0.005, True),
                                                    ("A02_n_four_bar", 0.05, False)])  # fmt: skip
def test_engine_equals_general_driver(name: str, dt: float, t_eval: bool) -> None:
    """The engine's RK8 (``d8_advance`` as the fixed step) and the general driver's: the same
    steps and samples (Hermite interpolant between step ends) to round-off."""
    mech = library.get(name)
    te = np.linspace(0.0, 0.5, 51) if t_eval else None
    a, b = _pair(mech, t_span=(0.0, 0.5), method=RK8(dt=dt), t_eval=te)
    assert a.metadata["engine"] == "engine" and b.metadata["engine"] == "python"
    assert a.success and b.success and a.n_steps == b.n_steps
    for f in ("q", "qd", "energy", "work"):
        x, y = getattr(a, f), getattr(b, f)
        assert float(np.max(np.abs(x - y))) < 1e-9 * max(1.0, float(np.max(np.abs(y)))), f


def test_a02_n2_coarse_steps_at_pinocchios_accuracy() -> None:
    """A02 N = 2, 10 s at the step ends, dt = 0.25 s without the passage placement: B0 within
    the exact 1-DOF reduction's 2e-2 m (measured 1.1e-2 m) and energy 1e-2 J (4.9e-3 J) in 40
    steps — Pinocchio's semi-implicit Euler at dt 5e-2 is 7.3e-2 m and 4.6 J off
    (benchmarks/README.md). With the placement (default) dt = 0.2 s stays on the branch."""
    mech = library.get("A02_n_four_bar", N=2)
    for integ, err_max, de_max in ((RK8(dt=0.25, passages=False), 2e-2, 1e-2), (RK8(dt=0.2), 1e-2, 5e-3)):
        tr = simulate(mech, (0.0, 10.0), method=integ, progress=False)
        assert tr.success
        ref = n_four_bar_reference(tr.t, N=2)
        b0 = tr.outputs(mech.model)["B0.position"]
        err = float(np.max(np.linalg.norm(b0 - ref["B0.position"], axis=1)))
        assert err < err_max, (integ, err)
        assert float(np.max(np.abs(tr.energy - tr.energy[0]))) < de_max, integ
        assert float(np.max(tr.phi_norm)) < 1e-12


def test_bad_input_is_a_typed_error() -> None:
    mech = library.get("A01_pendulum")
    for bad in (-0.1, 0.0, float("nan"), "0.1"):
        with pytest.raises(InputError, match="dt"):
            simulate(mech, (0.0, 0.1), solver=Solver("rk8", dt=bad), progress=False)  # type: ignore[arg-type]


def test_crossed_four_bar_stays_on_branch_through_its_change_points() -> None:
    """Crossed four-bar, 10 s (18 change points), RK8 at dt 1e-2 with the passage placement:
    on the anti-parallelogram branch at every step end, the crank within 0.1 rad of the exact
    reduction (measured 3.2e-2 m at B, energy 6.3e-2 J: less accurate than RK4 at equal dt)."""
    mech = library.get("crossed_four_bar")
    tr = simulate(mech, (0.0, 10.0), method=RK8(dt=1e-2), progress=False)
    assert tr.success and tr.t[-1] == pytest.approx(10.0)
    res = [mech.model.outputs(t, q, qd)["anti_branch_residual"] for t, q, qd in zip(tr.t, tr.q, tr.qd, strict=True)]
    assert float(np.max(np.abs(res))) < 1e-8
    ref = library.crossed_four_bar_reference(tr.t)
    assert float(np.max(np.abs(tr.q[:, 2] - ref["theta"]))) < 0.1
    assert tr.energy_drift < 0.1
