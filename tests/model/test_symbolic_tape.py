"""SymPy models compiled to an expression tape (engine ``TapeProgram``) equal the lambdify path.

``SymbolicModel.engine_program()`` compiles the model's SymPy expressions once (``sympy.cse``
then hash-consed SSA instructions, ``symbolic/_tape.py``); the C++ tape evaluates M,
``h = f_g − C qd``, f_passive, B, A, γ, φ, the velocity residual and the energies. Every output
is compared with :meth:`SymbolicModel.evaluate` (``sympy.lambdify`` with NumPy) at random
states and active sets, on the symbolic models of the test suite and on a model that uses
every instruction of the tape.
"""

from __future__ import annotations

import pickle

import numpy as np
import pytest
from program_check import check_terms, close
from test_cross_source_planar_symbolic import _symbolic as planar_fourbar_sympy
from test_cross_source_spatial_symbolic import _sympy_top
from test_cross_source_symbolic_function import _sympy_fourbar
from test_symbolic_model import double_pendulum, slider_pendulum  # noqa: F401  (fixtures)

from nonmin import _engine
from nonmin.errors import ModelError, NonFiniteError
from nonmin.model.symbolic import SymbolicConstraint, SymbolicModel
from nonmin.model.symbolic._tape import OPS, compile_tape

#: agreement of the tape and lambdify (relative to max(1, |lambdify|)): both sum the same
#: terms, in orders that differ after common-subexpression elimination
REL_TOL = 1e-12


def _close(got: np.ndarray, ref: np.ndarray, what: str) -> None:
    close(got, ref, what, REL_TOL)


def check(model: SymbolicModel, t: float, q: np.ndarray, qd: np.ndarray, active: frozenset[str]) -> None:
    check_terms(model, t, q, qd, active, REL_TOL)


def _states(model: SymbolicModel, seed: int, count: int = 4):
    rng = np.random.default_rng(seed)
    for _ in range(count):
        yield float(rng.uniform(-2, 2)), rng.standard_normal(model.n), 2.0 * rng.standard_normal(model.n)


def _subsets(model: SymbolicModel, seed: int):
    names = model.constraint_names
    rng = np.random.default_rng(seed)
    yield frozenset(names)
    yield model.default_active
    yield frozenset()
    for _ in range(3):
        yield frozenset(n for n in names if rng.random() < 0.5)


def every_op_model() -> SymbolicModel:
    """Uses every instruction of the tape (functions that are not differentiated — Abs, sign,
    Min, Max — only in f_passive and B, whose expressions are not differentiated)."""
    import sympy as sp
    x, y, z = sp.symbols("x y z")
    xd, yd, zd = sp.symbols("xd yd zd")
    t = sp.Symbol("t")
    a, b, c = sp.symbols("a b c")
    M = sp.diag(a * (2 + sp.tanh(x) ** 2), b * (1 + sp.exp(-(y**2))), c * sp.cosh(z / 3))
    M[0, 1] = M[1, 0] = sp.Rational(1, 10) * sp.sin(x - y)
    V = a * sp.log(2 + sp.cos(x)) + b * sp.sqrt(1 + y**2) + c * (1 + z**2) ** sp.Rational(3, 2)
    V += sp.atan(x * y) + sp.sinh(z / 4) + (2 + sp.sin(y)) ** (1 + z**2 / 10) + 1 / (3 + x**2) ** 2
    cons = [
        SymbolicConstraint.holonomic("h1", [x**3 - y * sp.tan(z / 4), sp.atan2(y, 2 + sp.cos(x)) - z]),
        SymbolicConstraint.rheonomic("drive", sp.asin(sp.sin(x) / 2) + sp.acos(sp.cos(y) / 3) - t**2 / 5),
        SymbolicConstraint.nonholonomic("nh", [sp.exp(z / 5), 1 / sp.sqrt(2 + y**2), x / (1 + z**2)]),
        SymbolicConstraint.unilateral("gap", 1 - x**2 - (y / 2) ** 4),
    ]
    return SymbolicModel.from_mass_matrix(
        "every_op", q=[x, y, z], qd=[xd, yd, zd], M=M, V=V, constraints=cons, t=t,
        params={a: 1.5, b: 0.7, c: 2.0},
        B=sp.Matrix([[sp.Abs(x), sp.atan2(x, y)], [sp.sign(y), 0], [sp.Max(x, y, z), sp.Min(x, z)]]),
        actuator_names=["u1", "u2"],
        passive=[-a * xd * sp.Abs(xd), -b * sp.sign(yd) - sp.Max(0, yd), -c * sp.Min(zd, 2 * zd)],
    )  # fmt: skip


@pytest.fixture(scope="module")
def every_op() -> SymbolicModel:
    # built when a test asks, not when the module is collected (by every xdist worker)
    return every_op_model()


def test_every_instruction_is_used_and_matches_lambdify(every_op: SymbolicModel) -> None:
    EVERY_OP = every_op
    prog = EVERY_OP.engine_program()
    from nonmin.model.symbolic._model import _tape_of

    tape = _tape_of(EVERY_OP.compiled)
    used = set(tape.op.tolist())
    assert used == set(OPS.values()), f"unused ops: {sorted(set(OPS) - {k for k, v in OPS.items() if v in used})}"
    assert prog.size == tape.size and prog.n_inputs == 1 + 2 * 3 + 3
    for seed in range(3):
        for t, q, qd in _states(EVERY_OP, seed):
            q = 0.4 * q  # inside the domains of the inverse functions
            for active in _subsets(EVERY_OP, seed):
                check(EVERY_OP, t, q, qd, active)


def test_slider_pendulum(slider_pendulum: SymbolicModel) -> None:  # noqa: F811
    for seed in range(2):
        for t, q, qd in _states(slider_pendulum, seed):
            for active in _subsets(slider_pendulum, seed):
                check(slider_pendulum, t, q, qd, active)


def test_double_pendulum_and_replaced_parameters(double_pendulum: SymbolicModel) -> None:  # noqa: F811
    other = double_pendulum.replace(params={"m2": 3.5, "g": 1.62})
    from nonmin.model.symbolic._model import _tape_of

    assert _tape_of(other.compiled) is _tape_of(double_pendulum.compiled)  # compiled once
    assert other.engine_program() is not double_pendulum.engine_program()
    for model in (double_pendulum, other):
        for t, q, qd in _states(model, 3):
            check(model, t, q, qd, frozenset())


@pytest.mark.parametrize(
    "build",
    [_sympy_fourbar, planar_fourbar_sympy, lambda: _sympy_top(0.5, 0.1, 2.5e-3, 3.0e-3, 9.81)],
    ids=["fourbar_sympy", "fourbar_planar_sympy", "top_sympy"],
)
def test_cross_source_models(build) -> None:
    model = build()
    for seed in range(2):
        for t, q, qd in _states(model, seed):
            for active in _subsets(model, seed):
                check(model, t, q, qd, active)


def test_partial_needs_compute_what_is_asked(every_op: SymbolicModel) -> None:
    EVERY_OP = every_op
    prog = EVERY_OP.engine_program()
    mask = EVERY_OP.active_mask(frozenset(EVERY_OP.constraint_names))
    t, q, qd = next(_states(EVERY_OP, 9))
    q = 0.4 * q
    full = prog.evaluate(t, q, qd, mask)
    for need, names in (
        (_engine.NEED_PHI, ("phi",)),
        (_engine.NEED_A | _engine.NEED_GAMMA, ("A", "gamma")),
        (_engine.NEED_H, ("h", "f_passive")),
        (_engine.NEED_M | _engine.NEED_B | _engine.NEED_VELOCITY, ("M", "B", "velocity")),
    ):
        part = prog.evaluate(t, q, qd, mask, need)
        for name in names:
            np.testing.assert_array_equal(getattr(part, name), getattr(full, name))
    energy = prog.evaluate(t, q, qd, mask, _engine.NEED_ENERGY)
    assert energy.kinetic == full.kinetic and energy.potential == full.potential
    assert not np.any(energy.M)  # M was not asked: left zero, the kinetic energy computed anyway


def test_unsupported_function_falls_back_to_the_callback() -> None:
    import sympy as sp
    x, xd = sp.symbols("x xd")
    model = SymbolicModel.from_energy("gamma_fn", q=[x], qd=[xd], T=xd**2 / 2, V=sp.gamma(2 + x**2))
    assert model.engine_program() is None
    with pytest.raises(ModelError, match="cannot compile gamma"):
        compile_tape(sp, [sp.Symbol("t"), x, xd], {"V": model.compiled.V})


def test_non_finite_outputs_are_reported() -> None:
    import sympy as sp
    x, xd = sp.symbols("x xd")
    model = SymbolicModel.from_energy("log", q=[x], qd=[xd], T=xd**2 / 2, V=sp.log(x))
    prog = model.engine_program()
    prog.evaluate(0.0, np.array([2.0]), np.array([0.0]), model.active_mask(None))
    with pytest.raises(NonFiniteError):
        prog.evaluate(0.0, np.array([-1.0]), np.array([0.0]), model.active_mask(None))


def test_pickled_model_compiles_again(slider_pendulum: SymbolicModel) -> None:  # noqa: F811
    model = pickle.loads(pickle.dumps(slider_pendulum))
    for t, q, qd in _states(model, 5, count=2):
        check(model, t, q, qd, frozenset(model.constraint_names))


def test_batch_equals_single_evaluations(double_pendulum: SymbolicModel) -> None:  # noqa: F811
    prog = double_pendulum.engine_program()
    assert prog.thread_safe and not prog.constant_mass
    rng = np.random.default_rng(1)
    N = 5
    t, q, qd = rng.standard_normal(N), rng.standard_normal((N, 2)), rng.standard_normal((N, 2))
    mask = double_pendulum.active_mask(None)
    out = prog.evaluate_batch(t, q, qd, mask)
    for i in range(N):
        T = prog.evaluate(t[i], q[i], qd[i], mask)
        for key in ("M", "h", "f_passive", "B"):
            np.testing.assert_array_equal(out[key][i], getattr(T, key))


def test_bad_tapes_are_model_errors() -> None:
    i32 = np.int32
    args = dict(n=1, k=0, constraints=[], c=np.zeros(1), out_target=np.zeros(1, i32),
                out_index=np.zeros(1, i32), params=[])  # fmt: skip
    # instruction 0 (register 3) reads register 3: itself
    with pytest.raises(ModelError, match="before it is written"):
        _engine.TapeProgram(op=np.array([1], i32), a=np.array([3], i32), b=np.array([0], i32),
                            out_reg=np.array([3], i32), **args)  # fmt: skip
    with pytest.raises(ModelError, match="unknown op"):
        _engine.TapeProgram(op=np.array([99], i32), a=np.array([0], i32), b=np.array([0], i32),
                            out_reg=np.array([3], i32), **args)  # fmt: skip
    with pytest.raises(ModelError, match="output register"):
        _engine.TapeProgram(op=np.array([1], i32), a=np.array([0], i32), b=np.array([1], i32),
                            out_reg=np.array([9], i32), **args)  # fmt: skip
