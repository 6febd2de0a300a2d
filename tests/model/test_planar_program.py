"""The engine's PlanarProgram (C++) equals the Python planar evaluation to round-off.

``PlanarModel.engine_program()`` compiles the model once to a plain-data description
(``planar/_program.py``) that the C++ ``PlanarProgram`` evaluates for any active set (a mask
over the constraints). Every output — M, h, f_passive, B, the rows of A, γ, φ and the velocity
residual of the active constraints, kinetic and potential energy — is compared with
:meth:`PlanarModel.evaluate` (itself tested against the per-joint reference formulas and finite
differences) at random states and random active sets, on a model with every element type and
on every planar mechanism of the library (A02 up to N = 40).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from program_check import active_rows as _rows
from program_check import check_terms, close
from test_planar_vectorized import XFix, every_element_model

from nonmin import _engine, library
from nonmin.errors import ModelError, NonFiniteError, ShapeError
from nonmin.model.planar import PlanarBuilder, PlanarModel

#: agreement of the engine and the Python evaluation (relative to max(1, |Python|))
REL_TOL = 1e-13

MODEL = every_element_model()
NAMES = MODEL.constraint_names


def _close(got: np.ndarray, ref: np.ndarray, what: str) -> None:
    close(got, ref, what, REL_TOL)


def check(model: PlanarModel, t: float, q: np.ndarray, qd: np.ndarray, active: frozenset[str]) -> None:
    check_terms(model, t, q, qd, active, REL_TOL)


def _state(model: PlanarModel, seed: int) -> tuple[float, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    return float(rng.uniform(-2.0, 2.0)), rng.standard_normal(model.n), 2.0 * rng.standard_normal(model.n)


def test_program_shape_and_constraint_table() -> None:
    prog = MODEL.engine_program()
    assert prog is MODEL.engine_program()  # built once per model
    assert (prog.n, prog.k, prog.m_all) == (MODEL.n, MODEL.k, MODEL.num_rows(frozenset(NAMES)))
    assert prog.constant_mass
    assert not prog.thread_safe  # the Python drive profile of "drive"
    slices = MODEL.row_slices(frozenset(NAMES))
    kinds = {"holonomic": 0, "rheonomic": 1, "nonholonomic": 2, "unilateral": 3}
    for (name, kind, row, dim), spec in zip(prog.constraints, MODEL.constraints, strict=True):
        assert name == spec.name and kind == kinds[spec.kind] and dim == spec.dim
        assert slice(row, row + dim) == slices[name]


@pytest.mark.parametrize("seed", range(4))
def test_every_element_all_default_and_empty_active_sets(seed: int) -> None:
    t, q, qd = _state(MODEL, seed)
    for active in (frozenset(NAMES), MODEL.default_active, frozenset()):
        check(MODEL, t, q, qd, active)


@given(
    seed=st.integers(0, 2**31 - 1),
    mask=st.lists(st.booleans(), min_size=len(NAMES), max_size=len(NAMES)),
)
def test_every_element_random_active_subsets(seed: int, mask: list[bool]) -> None:
    t, q, qd = _state(MODEL, seed)
    check(MODEL, t, q, qd, frozenset(n for n, on in zip(NAMES, mask, strict=True) if on))


def test_each_constraint_alone() -> None:
    t, q, qd = _state(MODEL, 11)
    for name in NAMES:
        check(MODEL, t, q, qd, frozenset({name}))


LIBRARY = [
    ("crossed_four_bar", {}),
    ("A01_pendulum", {}),
    ("A02_n_four_bar", {"N": 1}),
    ("A02_n_four_bar", {"N": 2}),
    ("A02_n_four_bar", {"N": 40}),
    ("five_bar", {}),
    ("arm2r_wall", {}),
    ("slider_crank", {}),
    ("dual_arm_grasp", {}),
]


@pytest.mark.parametrize(("name", "kw"), LIBRARY, ids=[f"{n}{kw}" for n, kw in LIBRARY])
def test_library_mechanisms(name: str, kw: dict[str, int]) -> None:
    mech = library.get(name, **kw)
    model = mech.model
    assert isinstance(model, PlanarModel)
    s = mech.state
    everything = frozenset(model.constraint_names)
    check(model, float(s.t), s.q, s.qd, s.active)
    check(model, float(s.t), s.q, s.qd, everything)
    rng = np.random.default_rng(7)
    for seed in range(3):
        t, q, qd = _state(model, seed)
        check(model, t, s.q + 0.3 * q, qd, s.active)
        check(model, t, q, qd, everything)
        subset = frozenset(n for n in model.constraint_names if rng.random() < 0.5)
        check(model, t, q, qd, subset)


def test_spring_damper_and_driver_models_of_the_builder() -> None:
    b = PlanarBuilder("sdd", gravity=(0.0, -9.81))
    b.body("a", mass=1.0, inertia=0.1)
    b.body("c", mass=2.0, inertia=0.2)
    b.revolute("pin", ("ground", (0.0, 0.0)), ("a", (-0.5, 0.0)))
    b.drive_angle("drive", "a", start=0.1, speed=2.0)
    b.spring("s", ("a", (0.5, 0.0)), ("c", (0.1, 0.2)), stiffness=40.0, rest_length=0.3, damping=1.5)
    b.rotational_spring("r", "a", "c", stiffness=3.0, rest_angle=0.2, damping=0.4)
    model = b.build()
    prog = model.engine_program()
    assert prog.thread_safe  # constant-speed driver: data, no Python
    for seed in range(5):
        t, q, qd = _state(model, seed)
        check(model, t, q, qd, frozenset(model.constraint_names))


def test_inactive_rows_are_left_alone_and_buffers_are_reused() -> None:
    prog = MODEL.engine_program()
    terms = prog.make_terms()
    ws = prog.make_workspace()
    t, q, qd = _state(MODEL, 2)
    terms.A[:] = 7.0
    terms.gamma[:] = 7.0
    active = frozenset(NAMES[:5])
    mask = MODEL.active_mask(active)
    prog.evaluate_into(terms, ws, t, q, qd, mask)
    rows = _rows(prog, mask)
    others = np.setdiff1d(np.arange(prog.m_all), rows)
    assert np.all(terms.A[others] == 7.0) and np.all(terms.gamma[others] == 7.0)
    ref = MODEL.constraint_terms(t, q, qd, active)
    _close(terms.A[rows], ref.A, "A")
    # a second state into the same buffers
    t2, q2, qd2 = _state(MODEL, 3)
    prog.evaluate_into(terms, ws, t2, q2, qd2, mask, _engine.NEED_A | _engine.NEED_PHI)
    ref2 = MODEL.constraint_terms(t2, q2, qd2, active)
    _close(terms.A[rows], ref2.A, "A (second state)")
    _close(terms.phi[rows], ref2.phi, "phi (second state)")


def test_batch_equals_single_evaluations() -> None:
    mech = library.get("A02_n_four_bar", N=3)
    model = mech.model
    prog = model.engine_program()
    rng = np.random.default_rng(0)
    N = 6
    t = rng.uniform(0, 1, N)
    q = mech.state.q + 0.1 * rng.standard_normal((N, model.n))
    qd = rng.standard_normal((N, model.n))
    mask = model.active_mask(None)
    out = prog.evaluate_batch(t, q, qd, mask)
    threaded = prog.evaluate_batch(t, q, qd, mask, _engine.NEED_ALL, 3)
    for key, val in out.items():
        np.testing.assert_array_equal(threaded[key], val)
    for i in range(N):
        T = prog.evaluate(t[i], q[i], qd[i], mask)
        for key in ("M", "h", "f_passive", "A", "gamma", "phi", "velocity"):
            np.testing.assert_array_equal(out[key][i], getattr(T, key))
        assert out["kinetic"][i] == T.kinetic and out["potential"][i] == T.potential


def test_user_defined_joint_has_no_program() -> None:
    model = MODEL.replace(joints=(*MODEL.joints, XFix("xfix", "b1", 0.2)))
    assert model.engine_program() is None


def test_python_profile_errors_propagate() -> None:
    def bad(t: float) -> tuple[float, float, float]:
        raise ZeroDivisionError("profile failed")

    b = PlanarBuilder("bad_profile")
    b.body("a", mass=1.0, inertia=0.1)
    b.drive_angle("drive", "a", profile=bad)
    model = b.build()
    prog = model.engine_program()
    # a user profile's failure is a ModelError naming the driver and the time (issue 19), the
    # original exception as its cause
    with pytest.raises(ModelError, match="driver 'drive': profile raised ZeroDivisionError") as info:
        prog.evaluate(0.0, np.zeros(3), np.zeros(3), model.active_mask(None))
    assert isinstance(info.value.__cause__, ZeroDivisionError)

    b2 = PlanarBuilder("nan_profile")
    b2.body("a", mass=1.0, inertia=0.1)
    b2.drive_angle("drive", "a", profile=lambda t: (math.nan, 0.0, 0.0))
    m2 = b2.build()
    with pytest.raises(ModelError, match="three finite numbers"):
        m2.engine_program().evaluate(0.0, np.zeros(3), np.zeros(3), m2.active_mask(None))


def test_bad_input_raises_typed_errors() -> None:
    prog = MODEL.engine_program()
    n = MODEL.n
    mask = MODEL.active_mask(None)
    with pytest.raises(ShapeError, match=r"q must have shape"):
        prog.evaluate(0.0, np.zeros(n + 1), np.zeros(n), mask)
    with pytest.raises(ShapeError, match=r"active must be a mask"):
        prog.evaluate(0.0, np.zeros(n), np.zeros(n), mask[:-1])
    q = np.zeros(n)
    q[3] = np.nan
    with pytest.raises(NonFiniteError):
        prog.evaluate(0.0, q, np.zeros(n), mask)
    other = library.get("A01_pendulum").model.engine_program()
    with pytest.raises(ShapeError, match="another program"):
        prog.evaluate_into(other.make_terms(), prog.make_workspace(), 0.0, np.zeros(n), np.zeros(n), mask)


def test_bad_descriptions_are_model_errors() -> None:
    d = _engine.PlanarDescription()
    d.add_body(1.0, 0.1)
    c = d.add_constraint("pin", 0, 2)
    d.add_pin(c, 0, (5, 0.0, 0.0), (-1, 0.0, 0.0))
    with pytest.raises(ModelError, match="out of range"):
        _engine.PlanarProgram(d)
    d = _engine.PlanarDescription()
    d.add_body(1.0, 0.1)
    d.add_constraint("pin", 0, 2)  # rows not defined by any primitive
    with pytest.raises(ModelError, match="defined 0 times"):
        _engine.PlanarProgram(d)
    d = _engine.PlanarDescription()
    d.add_body(1.0, -1.0)  # a point mass
    c = d.add_constraint("angle", 0, 1)
    d.add_angle(c, 0, [0], [1.0], 0.0)
    with pytest.raises(ModelError, match="point mass"):
        _engine.PlanarProgram(d)


@settings(max_examples=20)
@given(seed=st.integers(0, 2**31 - 1))
def test_large_chain_random_states(seed: int) -> None:
    model = library.get("A02_n_four_bar", N=40).model
    t, q, qd = _state(model, seed)
    check(model, t, q, qd, model.default_active)
