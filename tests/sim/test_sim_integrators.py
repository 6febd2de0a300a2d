"""Integrators: convergence order (log-log), dense output, adaptive error control."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from conftest import G, make_pendulum
from nonmin.sim import RK4, DormandPrince5, ImplicitMidpoint, simulate

T_END = 1.0


def _pendulum_reference(t: float) -> np.ndarray:
    """Exact-to-1e-13 position of the A01 pendulum from the angle ODE θ'' = −g sin θ."""
    sol = solve_ivp(
        lambda _t, y: [y[1], -G * np.sin(y[0])], (0.0, t), [np.pi / 2, 0.0],
        method="DOP853", rtol=1e-13, atol=1e-14,
    )
    th = sol.y[0, -1]
    return np.array([np.sin(th), -np.cos(th)])


def _order(errors: list[float], steps: list[float]) -> float:
    return float(np.polyfit(np.log(steps), np.log(errors), 1)[0])


@pytest.mark.parametrize("stabilization", ["projection", "none"])
def test_rk4_converges_with_order_four(stabilization: str) -> None:
    model = make_pendulum()
    ref = _pendulum_reference(T_END)
    dts = [0.04, 0.02, 0.01]
    errs = []
    for dt in dts:
        tr = simulate(model, (0.0, T_END), [1.0, 0.0], dt=dt, stabilization=stabilization)
        errs.append(float(np.linalg.norm(tr.q[-1] - ref)))
    order = _order(errs, dts)
    assert 3.6 < order < 4.6, (order, errs)


def test_midpoint_converges_with_order_two_and_conserves_energy() -> None:
    model = make_pendulum()
    ref = _pendulum_reference(T_END)
    dts = [0.04, 0.02, 0.01]
    errs = [
        float(np.linalg.norm(simulate(model, (0.0, T_END), [1.0, 0.0], dt=dt, method="midpoint").q[-1] - ref))
        for dt in dts
    ]
    assert 1.7 < _order(errs, dts) < 2.3, errs
    # bounded energy error (no drift) over many periods with a coarse step
    # energy error bounded, not drifting (coarse step, ~2.5 periods): the second half of the
    # run is no worse than the first (RK4 at this step drifts 4x between the halves)
    tr = simulate(model, (0.0, 6.0), [1.0, 0.0], dt=0.04, method="midpoint")
    err = np.abs(tr.energy - tr.energy[0])
    half = len(tr) // 2
    assert err[half:].max() <= 1.1 * err[:half].max()
    assert tr.energy_drift < 0.1


def test_dopri5_meets_tolerance_and_uses_few_steps() -> None:
    model = make_pendulum()
    ref = _pendulum_reference(T_END)
    errs = []
    for tol in (1e-6, 1e-9):
        tr = simulate(model, (0.0, T_END), [1.0, 0.0], method="dopri5", rtol=tol, atol=tol * 1e-2)
        errs.append(float(np.linalg.norm(tr.q[-1] - ref)))
        assert tr.n_steps < 200
    assert errs[1] < 1e-7
    assert errs[1] < errs[0]


def _oscillator(t: float, y: np.ndarray) -> np.ndarray:
    return np.array([y[1], -y[0]])


@pytest.mark.parametrize(("integ", "order"), [(RK4(), 4), (DormandPrince5(), 5), (ImplicitMidpoint(), 2)])
def test_raw_step_order_on_harmonic_oscillator(integ: object, order: int) -> None:
    """Global error of the raw stepper (no mechanics) scales like h^order."""
    errs, hs = [], [0.1, 0.05, 0.025]
    for h in hs:
        y = np.array([1.0, 0.0])
        t = 0.0
        for _ in range(round(1.0 / h)):
            y = integ.advance(_oscillator, t, y, None, h)  # type: ignore[attr-defined]
            t += h
        errs.append(float(np.linalg.norm(y - [np.cos(1.0), -np.sin(1.0)])))
    assert order - 0.4 < _order(errs, hs) < order + 0.6, errs


def test_dopri5_dense_output_is_accurate_inside_the_step() -> None:
    integ = DormandPrince5(rtol=1e-10, atol=1e-12)
    state = integ.init(_oscillator, 0.0, np.array([1.0, 0.0]), 0.3)
    res = integ.step(_oscillator, state, 10.0)
    assert res.dense is not None
    t0, t1 = 0.0, res.state.t
    for s in np.linspace(t0, t1, 7):
        assert np.allclose(res.dense(s), [np.cos(s), -np.sin(s)], atol=1e-9)
    assert np.array_equal(res.dense(t1), res.state.y)


def test_integrators_are_immutable_values() -> None:
    integ = RK4(dt=0.01)
    with pytest.raises(AttributeError):
        integ.dt = 0.1  # type: ignore[misc]
    assert RK4(dt=0.01) == integ


def test_hermite_extension_is_exact_for_quintics_and_matches_both_ends() -> None:
    from nonmin.sim._integrators import hermite_quintic

    rng = np.random.default_rng(3)
    c = rng.normal(size=(6, 2))  # q(t) = Σ c_k t^k, two coordinates

    def y_f(t: float) -> tuple[np.ndarray, np.ndarray]:
        q = sum(c[k] * t**k for k in range(6))
        v = sum(k * c[k] * t ** (k - 1) for k in range(1, 6))
        a = sum(k * (k - 1) * c[k] * t ** (k - 2) for k in range(2, 6))
        return np.concatenate((q, v)), np.concatenate((v, a))

    t0, h = 0.3, 0.7
    y0, f0 = y_f(t0)
    y1, f1 = y_f(t0 + h)
    for s in (0.0, 0.13, 0.35, 0.61, h):
        np.testing.assert_allclose(hermite_quintic(y0, f0, y1, f1, h, s), y_f(t0 + s)[0], rtol=0, atol=1e-12)
    assert np.array_equal(hermite_quintic(y0, f0, y1, f1, h, 0.0), y0)


def test_rk4_samples_between_steps_keep_the_accuracy_of_the_steps() -> None:
    """Output times inside fixed steps come from the Hermite extension: same error order as
    the step ends, and on the constraints after the projection."""
    model = make_pendulum()
    errs = []
    dts = [0.04, 0.02]
    t_eval = np.array([0.33, 0.5, 0.77, 1.0])
    for dt in dts:
        tr = simulate(model, (0.0, T_END), [1.0, 0.0], dt=dt, t_eval=t_eval)
        assert np.all(np.abs(np.hypot(tr.q[:, 0], tr.q[:, 1]) - 1.0) < 1e-13)
        ref = np.array([_pendulum_reference(t) for t in t_eval])
        errs.append(float(np.max(np.abs(tr.q - ref))))
    assert errs[0] < 1e-4 and _order(errs, dts) > 3.6, errs
