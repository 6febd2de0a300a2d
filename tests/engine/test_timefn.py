"""The engine's TimeFunction (engine/include/nonmin/timefn.hpp): pieces, hold, tapes, errors."""

from __future__ import annotations

import numpy as np
import pytest

from nonmin import _engine
from nonmin.errors import ModelError


def test_pieces_match_numpy_polynomials_inside_and_outside() -> None:
    breaks = [0.0, 1.0, 2.5, 4.0]
    rng = np.random.default_rng(0)
    coefs = rng.normal(size=(3, 4))
    for hold in (False, True):
        fn = _engine.TimeFunction.pieces(breaks, coefs.ravel().tolist(), 3, hold)
        for t in np.linspace(-1.0, 5.0, 37):
            tc = min(max(t, 0.0), 4.0) if hold else t
            i = 0 if tc < 1.0 else (1 if tc < 2.5 else 2)
            c = np.polynomial.Polynomial(coefs[i])
            tau = tc - breaks[i]
            want = [c(tau), c.deriv(1)(tau), c.deriv(2)(tau)]
            if hold and (t <= 0.0 or t >= 4.0):
                want[1] = want[2] = 0.0
            np.testing.assert_allclose(fn(t), want, rtol=1e-13, atol=1e-13)


def test_constant_polynomial_everywhere() -> None:
    fn = _engine.TimeFunction.pieces([0.0, 0.0], [2.0, -1.0, 0.5], 2, False)
    assert fn(3.0) == pytest.approx((2.0 - 3.0 + 4.5, -1.0 + 3.0, 1.0))


def test_tape_ops() -> None:
    # registers: 0 = t; 1 = const 2; 2 = t^-2 (powi); 3 = sin(t); 4 = 2·sin t; 5 = atan2(t, 2)
    op = [0, 6, 9, 3, 17]
    a = [0, 0, 0, 1, 0]
    b = [0, 0, 0, 3, 1]
    c = [2.0, -2.0, 0.0, 0.0, 0.0]
    fn = _engine.TimeFunction.tape(op, a, b, c, [2, 4, 5])
    t = 0.7
    assert fn(t) == pytest.approx((t**-2, 2 * np.sin(t), np.arctan2(t, 2.0)), rel=1e-15)
    fn0 = _engine.TimeFunction.tape([0], [0], [0], [1.5], [1, -1, -1])
    assert fn0(9.0) == (1.5, 0.0, 0.0)


def test_bad_descriptions_are_model_errors() -> None:
    with pytest.raises(ModelError, match="strictly increasing"):
        _engine.TimeFunction.pieces([0.0, 1.0, 1.0], [0.0] * 4, 1, False)
    with pytest.raises(ModelError, match="coefficients"):
        _engine.TimeFunction.pieces([0.0, 1.0], [0.0] * 3, 1, False)
    with pytest.raises(ModelError, match="finite"):
        _engine.TimeFunction.pieces([0.0, 1.0], [np.nan, 0.0], 1, False)
    with pytest.raises(ModelError, match="operand"):
        _engine.TimeFunction.tape([1], [0], [5], [0.0], [1, -1, -1])
    with pytest.raises(ModelError, match="output register"):
        _engine.TimeFunction.tape([0], [0], [0], [0.0], [7, -1, -1])


def test_callback_errors_propagate() -> None:
    def boom(t):
        raise RuntimeError("boom")

    fn = _engine.TimeFunction.callback(boom)
    with pytest.raises(RuntimeError, match="boom"):
        fn(0.0)
    ok = _engine.TimeFunction.callback(lambda t: (t, 1.0, 0.0))
    assert ok(2.0) == (2.0, 1.0, 0.0)
