"""Forward-mode model terms and the analytic kernel derivative against central differences.

References: central differences of the engine's own evaluation and forward dynamics (the
same functions, differentiated numerically with a step where truncation ~h² and round-off
~eps/h are both below the tolerance), at consistent states of library mechanisms.
"""

import numpy as np
import pytest

import nonmin
from nonmin import library
from nonmin.linear import dynamics_derivatives, term_tangents

#: Central differences with h = 1e-5 (truncation ~1e-10, round-off ~1e-11 relative).
FD_STEP = 1e-5
#: Agreement asked of the exact derivatives with central differences (relative to the
#: largest entry of the Jacobian).
FD_RTOL = 1e-7

MECHANISMS = {
    "crossed_four_bar": lambda: library.crossed_four_bar(),
    "slider_crank": lambda: library.slider_crank(),
    "five_bar": lambda: library.five_bar(),
    "A02_N2": lambda: library.a02_n_four_bar(N=2),
    "A01": lambda: library.a01_pendulum(),
    "A03": lambda: library.a03_andrews(),  # its shipped expression tape
}


def _state(name):
    mech = MECHANISMS[name]()
    st = mech.state
    return mech.model, st.q, st.qd + 0.0, st.active


def _fd(fun, x, h=FD_STEP):
    cols = []
    for i in range(x.size):
        e = np.zeros_like(x)
        e[i] = h
        cols.append((fun(x + e) - fun(x - e)) / (2 * h))
    return np.stack(cols, axis=-1)


@pytest.mark.parametrize("name", sorted(MECHANISMS))
def test_term_tangents_match_central_differences(name):
    model, q, qd, act = _state(name)
    prog = model.engine_program()
    from nonmin import _engine

    mask = model.active_mask(act)
    rng = np.random.default_rng(1)
    dq = rng.standard_normal(model.n)
    dv = rng.standard_normal(model.n)
    tt = term_tangents(model, q, qd, dq, dv, active=act)
    rows = np.concatenate(
        [np.arange(c[2], c[2] + c[3]) for c in prog.constraints if c[0] in act]
    ).astype(int)

    def ev(s):
        T = prog.evaluate(0.0, q + s * dq, qd + s * dv, mask)
        return {
            "M": np.array(T.M), "h": np.array(T.h), "f_passive": np.array(T.f_passive), "B": np.array(T.B),
            "A": np.array(T.A)[rows], "gamma": np.array(T.gamma)[rows], "phi": np.array(T.phi)[rows],
            "velocity": np.array(T.velocity)[rows],
        }  # fmt: skip

    p, m = ev(FD_STEP), ev(-FD_STEP)
    for key in ("M", "h", "f_passive", "B", "A", "gamma", "phi", "velocity"):
        fd = (p[key] - m[key]) / (2 * FD_STEP)
        exact = tt["d" + key][0]
        scale = max(1.0, float(np.abs(fd).max(initial=0.0)))
        assert np.abs(exact - fd).max(initial=0.0) <= FD_RTOL * scale, key
    assert _engine.differentiable(prog)


@pytest.mark.parametrize("name", sorted(MECHANISMS))
def test_dynamics_derivatives_match_central_differences(name):
    model, q, qd, act = _state(name)
    rng = np.random.default_rng(2)
    u = rng.standard_normal(model.k)
    f = rng.standard_normal(model.n)
    d = dynamics_derivatives(model, q, qd, u=u, f=f, active=act)

    def acc(qq, vv, ff=f, uu=u):
        g = ff + model.input_matrix(qq) @ uu if model.k else ff
        return model.forward_dynamics(qq, vv, active=act, f=g)

    ref = acc(q, qd)
    assert np.allclose(d.qdd, ref.qdd, rtol=1e-11, atol=1e-11 * (1 + np.abs(ref.qdd).max()))
    assert np.allclose(d.f_c, ref.f_c, rtol=1e-10, atol=1e-10 * (1 + np.abs(ref.f_c).max()))
    pairs = [
        (d.dqdd_dq, _fd(lambda x: acc(x, qd).qdd, q)),
        (d.dqdd_dqd, _fd(lambda x: acc(q, x).qdd, qd)),
        (d.dqdd_df, _fd(lambda x: acc(q, qd, ff=x).qdd, f)),
        (d.dfc_dq, _fd(lambda x: acc(x, qd).f_c, q)),
        (d.dfc_dqd, _fd(lambda x: acc(q, x).f_c, qd)),
        (d.dfc_df, _fd(lambda x: acc(q, qd, ff=x).f_c, f)),
    ]
    if model.k:
        pairs.append((d.dqdd_du, _fd(lambda x: acc(q, qd, uu=x).qdd, u)))
        pairs.append((d.dfc_du, _fd(lambda x: acc(q, qd, uu=x).f_c, u)))
    for exact, fd in pairs:
        scale = max(1.0, float(np.abs(fd).max()))
        assert np.abs(exact - fd).max() <= FD_RTOL * scale


class _PythonOnlyAndrews(library.AndrewsModel):
    """A hand-written Model subclass without an engine program (the engine calls it back)."""

    def engine_program(self):
        return None


def test_model_without_a_differentiable_program_is_a_model_error():
    mech = library.a03_andrews()
    with pytest.raises(nonmin.errors.ModelError, match=r"no compiled engine program|forward-mode"):
        dynamics_derivatives(_PythonOnlyAndrews(), mech.state.q)


def test_bad_inputs_are_typed_errors():
    mech = library.a01_pendulum()
    with pytest.raises(nonmin.errors.ShapeError, match="q must have shape"):
        dynamics_derivatives(mech.model, [1.0, 0.0, 0.0])
    with pytest.raises(nonmin.errors.NonFiniteError, match="qd"):
        dynamics_derivatives(mech.model, [1.0, 0.0], [np.nan, 0.0])
    with pytest.raises(nonmin.errors.InputError, match="model"):
        dynamics_derivatives("pendulum", [1.0, 0.0])


@pytest.mark.parametrize("name", sorted(MECHANISMS))
def test_engine_pipeline_equals_the_numpy_specification(name):
    model, q, qd, act = _state(name)
    rng = np.random.default_rng(5)
    u = rng.standard_normal(model.k)
    f = rng.standard_normal(model.n)
    e = dynamics_derivatives(model, q, qd, u=u, f=f, active=act, backend="engine")
    p = dynamics_derivatives(model, q, qd, u=u, f=f, active=act, backend="numpy")
    assert e.rank == p.rank
    for key in (
        "qdd",
        "f_c",
        "dqdd_dq",
        "dqdd_dqd",
        "dqdd_df",
        "dqdd_du",
        "dfc_dq",
        "dfc_dqd",
        "dfc_df",
        "dfc_du",
    ):
        a, b = getattr(e, key), getattr(p, key)
        assert np.abs(a - b).max(initial=0.0) <= 1e-10 * max(
            1.0, float(np.abs(b).max(initial=0.0))
        ), key
