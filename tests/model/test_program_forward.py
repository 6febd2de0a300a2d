"""Model + kernel in the engine: ``_engine.Forward`` (Program evaluation + core solve) gives
the q̈ of ``nonmin.core.forward_dynamics`` on the model's Python terms (NumPy backend: the
readable specification), single and batched, for planar, spatial and SymPy programs, with all
constraints active and with masks whose active rows are not contiguous."""

from __future__ import annotations

import numpy as np
import pytest
from test_cross_source_symbolic_function import _sympy_fourbar

from nonmin import _engine, library
from nonmin.core import forward_dynamics, use_backend
from nonmin.errors import ShapeError

#: agreement with the NumPy kernel on the Python terms (relative to max(1, |q̈|))
REL_TOL = 1e-10


def _cases():
    yield "crossed_four_bar", library.get("crossed_four_bar")
    yield "A02_N2", library.get("A02_n_four_bar", N=2)
    yield "A02_N12", library.get("A02_n_four_bar", N=12)
    yield "arm2r_wall", library.get("arm2r_wall")
    yield "slider_crank", library.get("slider_crank")
    yield "bricard", library.get("A04_bricard")
    yield "top", library.get("spinning_top")


@pytest.mark.parametrize("name", [c[0] for c in _cases()])
def test_forward_matches_the_numpy_kernel(name: str) -> None:
    mech = dict(_cases())[name]
    model, s = mech.model, mech.state
    prog = model.engine_program()
    names = model.constraint_names
    rng = np.random.default_rng(0)
    sets = [s.active, frozenset(names[1:]) if len(names) > 2 else s.active]
    for active in sets:
        fwd = _engine.Forward(prog, model.active_mask(active))
        qdd = np.zeros(model.n)
        N = 4
        t = rng.uniform(0, 1, N)
        Q = s.q + 1e-3 * rng.standard_normal((N, model.n))  # near the manifold: regular A
        QD = s.qd + 0.1 * rng.standard_normal((N, model.n))
        batch = fwd.batch(t, Q, QD, 2)
        for i in range(N):
            fwd(t[i], Q[i], QD[i], qdd)
            T = model.evaluate(t[i], Q[i], QD[i], active)
            with use_backend("numpy"):
                ref = forward_dynamics(T.M, T.h, T.constraints.A, T.constraints.gamma, T.f_passive)
            scale = max(1.0, float(np.abs(ref).max()))
            assert np.abs(qdd - ref).max() <= REL_TOL * scale, (name, sorted(active))
            np.testing.assert_array_equal(batch[i], qdd)


def test_symbolic_program_forward() -> None:
    model = _sympy_fourbar()
    prog = model.engine_program()
    fwd = _engine.Forward(prog, model.active_mask(None))
    rng = np.random.default_rng(1)
    q, qd = rng.standard_normal(model.n), rng.standard_normal(model.n)
    qdd = np.zeros(model.n)
    fwd(0.2, q, qd, qdd)
    T = model.evaluate(0.2, q, qd)
    with use_backend("numpy"):
        ref = forward_dynamics(T.M, T.h, T.constraints.A, T.constraints.gamma, T.f_passive)
    assert np.abs(qdd - ref).max() <= REL_TOL * max(1.0, float(np.abs(ref).max()))


def test_forward_shapes() -> None:
    model = library.get("crossed_four_bar").model
    prog = model.engine_program()
    with pytest.raises(ShapeError):
        _engine.Forward(prog, model.active_mask(None)[:-1])
    fwd = _engine.Forward(prog, model.active_mask(None))
    with pytest.raises(ShapeError):
        fwd(0.0, np.zeros(model.n), np.zeros(model.n), np.zeros(model.n + 1))


def test_forward_dynamics_bad_numbers_are_named() -> None:
    """A NaN time was "the engine failed at state 0 (status 1)"; text q a raw ValueError."""
    from nonmin.errors import InputError, NonFiniteError

    bar = library.get("crossed_four_bar")
    q, qd = bar.state.q, bar.state.qd
    with pytest.raises(NonFiniteError, match="t must be finite"):
        bar.model.forward_dynamics(q, qd, t=np.nan)
    with pytest.raises(InputError, match="q must be a numeric array, got text"):
        bar.model.forward_dynamics([str(v) for v in q], qd)
    with pytest.raises(InputError, match="qd must be real numbers, got complex"):
        bar.model.forward_dynamics(q, qd + 1j)
    with pytest.raises(ShapeError, match="q must be a numeric array"):
        bar.model.forward_dynamics("abc", qd)
