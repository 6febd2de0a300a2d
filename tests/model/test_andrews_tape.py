"""Andrews' squeezer (A03) runs in the engine: its shipped expression tape equals its formulas.

``AndrewsModel.engine_program()`` builds a ``TapeProgram`` from ``nonmin/data/tapes/
A03_andrews.json`` (the tape of ``AndrewsModel.symbolic()``, every field a parameter). The
program's M, h, A, γ, φ, velocity residual and energies are checked against the class's own
hand-written formulas (``mass_matrix``, the Christoffel ``C``, ``_constraint_all``) at random
states and active sets, for the default and for changed parameters; the shipped tape against a
fresh SymPy compilation; a run in the engine against the Python driver and the Test Set's
PSIDE reference.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from program_check import check_terms

import nonmin
from nonmin.library import AndrewsModel, a03_andrews
from nonmin.library._andrews import _shipped_tape, tape_record

#: relative agreement of the tape and the hand-written formulas (same terms, other order)
REL_TOL = 1e-12


def _states(seed: int, count: int = 5):
    rng = np.random.default_rng(seed)
    for _ in range(count):
        yield float(rng.uniform(0, 1)), rng.uniform(-3, 3, 7), 50.0 * rng.standard_normal(7)


@pytest.mark.parametrize(
    "model",
    [AndrewsModel(), dataclasses.replace(AndrewsModel(), c0=3000.0, mom=0.05, m=(0.05, *AndrewsModel().m[1:]), zt=0.045)],
    ids=["default", "replaced"],
)
def test_program_equals_the_formulas(model: AndrewsModel) -> None:
    assert model.engine_program() is model.engine_program()  # built once per model
    names = model.constraint_names
    for seed in range(3):
        for t, q, qd in _states(seed):
            for active in (frozenset(names), frozenset(), frozenset(names[:1]), frozenset(names[1:])):
                check_terms(model, t, q, qd, active, REL_TOL)


def test_shipped_tape_is_the_sympy_compilation() -> None:
    pytest.importorskip("sympy")
    fresh = tape_record()
    shipped = _shipped_tape()
    for key in ("n_inputs", "params", "op", "a", "b", "out_target", "out_index", "out_reg"):
        assert fresh[key] == shipped[key], f"{key}: regenerate with nonmin.library._andrews.write_tape()"
    np.testing.assert_array_equal(np.asarray(fresh["c"]), np.asarray(shipped["c"]))


def test_engine_run_matches_python_driver_and_reference() -> None:
    from nonmin.validation._references import load_a03_reference

    mech = a03_andrews()
    kw = dict(method="dopri5", rtol=1e-10, atol=1e-12, progress=False)
    eng = nonmin.simulate(mech, 0.03, **kw)
    assert eng.metadata["engine"] == "engine" and eng.status.name == "SUCCESS"
    short = nonmin.simulate(mech, 0.004, **kw)  # the Python driver calls the formulas back: slow
    py = nonmin.simulate(mech, 0.004, engine="python", **kw)
    assert py.metadata["engine"] == "python" and py.status.name == "SUCCESS"
    np.testing.assert_allclose(short.q[-1], py.q[-1], rtol=0, atol=1e-9)
    _, ref = load_a03_reference()  # y(0.03): the 7 angles first
    assert np.max(np.abs(eng.q[-1] - ref[:7])) < 1e-7
