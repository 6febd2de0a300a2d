"""The vectorized planar evaluation equals the per-element reference formulas.

``PlanarModel.evaluate`` / ``constraint_terms`` / ``constraint_jacobian_dot`` /
``conservative_force`` / ``passive_force`` / ``input_matrix`` / ``potential_energy`` use index
arrays built once per model and per active set; ``_reference_*`` evaluate the same quantities
joint by joint and element by element with :meth:`Joint.terms` (the formulas of
``_elements.py``, themselves checked against finite differences in ``test_planar_builder.py``).
Agreement is demanded to ``REL_TOL`` (round-off: the two paths sum the same terms in another
order). (The engine's evaluation of the same primitives: test_planar_program.py.)
"""

from __future__ import annotations

import math
import pickle
from dataclasses import dataclass
from itertools import combinations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from nonmin import library
from nonmin.errors import NonFiniteError, ShapeError, UnknownNameError
from nonmin.model.planar import (
    Body,
    Joint,
    PlanarBuilder,
    PlanarModel,
    Point,
    Revolute,
)
from nonmin.model.planar._model import _Kin

#: agreement of the compiled and the reference evaluation (relative to max(1, |reference|))
REL_TOL = 1e-13


def _profile(t: float) -> tuple[float, float, float]:
    return 0.3 + 0.7 * math.sin(2.0 * t), 1.4 * math.cos(2.0 * t), -2.8 * math.sin(2.0 * t)


def every_element_model() -> PlanarModel:
    """Every joint, force and actuator type; joints to the ground, to point masses, between two
    points of one body (coinciding entries of A), and zero-stiffness / zero-damping elements."""
    b = PlanarBuilder("every_element", gravity=(0.3, -9.81))
    b.body("b1", mass=1.2, inertia=0.1, points={"P1": (0.4, -0.1)})
    b.body("b2", mass=0.7, inertia=0.05, points={"P2": (-0.3, 0.2)})
    b.body("b3", mass=2.0, inertia=0.3)
    b.point_mass("pm", mass=0.5, points=["PM"])
    b.point_mass("pm2", mass=0.8, points=["PM2"])
    b.ground_point("O", (0.1, -0.2))
    b.revolute("rev", "O", ("b1", (-0.5, 0.05)))
    b.revolute("rev2", ("b1", (0.5, 0.0)), ("b2", (-0.4, 0.1)))
    b.revolute("rev_pm", ("b3", (0.1, -0.3)), "PM")
    b.revolute("rev_pm_ground", "PM2", ("ground", (0.4, 0.4)))
    b.revolute("rev_self", ("b2", (0.1, 0.2)), ("b2", (-0.3, 0.5)))  # one body: coinciding entries
    b.weld("weld", ("b2", (0.2, 0.3)), ("b3", (-0.1, 0.4)), angle=0.4)
    b.weld("weld_ground", ("ground", (1.0, 1.0)), ("b3", (0.2, 0.0)), angle=-0.3)
    b.prismatic("pris", ("b1", (0.1, 0.2)), ("b3", (0.3, -0.2)), axis=(0.6, 0.8), angle=-0.2)
    b.prismatic("pris_ground", ("ground", (0.0, 0.5)), ("b2", (0.1, 0.1)), axis=(1.0, 0.0))
    b.point_on_line("pol", ("b2", (0.05, -0.1)), "PM", axis=(1.0, 2.0))
    b.point_on_line("pol_self", ("b1", (0.0, 0.1)), ("b1", (0.3, -0.2)), axis=(0.0, 1.0))
    b.point_on_line("wall", ("ground", (1.5, 0.0)), "P2", axis=(0.0, 1.0), unilateral=True)
    b.rod("rod", ("b3", (0.2, 0.1)), "PM", length=0.9)
    b.rod("rope", "P1", ("ground", (-1.0, 1.0)), length=2.0, unilateral=True)
    b.rod("rod_pm_ground", "PM", ("ground", (0.0, 0.0)), length=1.3)
    b.rod("rod_pm_pm", "PM", "PM2", length=0.7)
    b.gear("gear", "b1", "b2", ratio=2.5, offset=0.1, carrier="b3")
    b.gear("gear_ground", "b1", "b3", ratio=-0.5)
    b.gear("gear_same", "b1", "b1", ratio=0.5, carrier="b2")
    b.drive_angle("drive", "b2", body_a="b1", profile=_profile)
    b.drive_angle("drive_const", "b3", start=0.2, speed=1.7)
    b.spring("spring", "P1", "PM", stiffness=30.0, rest_length=0.4, damping=0.7)
    b.spring("spring_ground", "P2", ("ground", (0.3, -0.4)), stiffness=12.0, rest_length=0.2)
    b.spring("damper_only", ("b3", (0.1, 0.1)), "PM2", damping=1.3)
    b.rotational_spring("tspring", "b1", "b2", stiffness=5.0, rest_angle=0.3, damping=0.2)
    b.rotational_spring("tspring_ground", "ground", "b3", stiffness=2.0, rest_angle=-0.1)
    b.actuator("tau", "rev2")
    b.actuator("push", "pris")
    b.actuator("push_ground", "pris_ground")
    b.torque("tau_free", "b3", body_a="b1")
    b.torque("tau_ground", "b2")
    b.force("fx", "P2", direction=(1.0, 1.0))
    b.force("f_pm", "PM", direction=(0.0, 1.0))
    b.force("f_ground", ("ground", (0.0, 0.0)), direction=(1.0, 0.0))
    return b.build()


@dataclass(frozen=True)
class XFix(Joint):
    """A user-defined joint (not known to the compiler): ``x_body − value = 0`` via terms()."""

    body: str = "b1"
    value: float = 0.0

    @property
    def dim(self) -> int:
        return 1

    @property
    def bodies(self) -> tuple[str, ...]:
        return (self.body,)

    def terms(self, kin: _Kin, t: float):  # type: ignore[no-untyped-def]
        pos, rs, _, _ = kin.point(Point(self.body, (0.0, 0.0)))
        J = np.zeros((2, kin.n))
        kin.add_jac(J, self.body, rs, 1.0)
        return (
            np.array([pos[0] - self.value - 0.1 * t]),
            J[:1].copy(),
            np.zeros((1, kin.n)),
            np.zeros(1),
            np.array([-0.1]),
        )


MODEL = every_element_model()
NAMES = MODEL.constraint_names


def _close(a: np.ndarray, b: np.ndarray, what: str) -> None:
    a = np.asarray(a)
    b = np.asarray(b)
    assert a.shape == b.shape, f"{what}: shape {a.shape} != {b.shape}"
    assert a.dtype == b.dtype, f"{what}: dtype {a.dtype} != {b.dtype}"
    if a.size:
        scale = max(1.0, float(np.max(np.abs(b.astype(float)))))
        err = float(np.max(np.abs(a.astype(float) - b.astype(float))))
        assert err <= REL_TOL * scale, f"{what}: max |compiled − reference| = {err:.3g} (scale {scale:.3g})"


def _check_state(model: PlanarModel, t: float, q: np.ndarray, qd: np.ndarray, active: frozenset[str]) -> None:
    _check_state_once(model, t, q, qd, active)


def _check_state_once(
    model: PlanarModel, t: float, q: np.ndarray, qd: np.ndarray, active: frozenset[str]
) -> None:
    ref = model._reference_constraint_terms(t, q, qd, active)
    got = model.constraint_terms(t, q, qd, active)
    for field_, a, b in zip(got._fields, got, ref, strict=True):
        _close(a, b, f"constraint_terms.{field_} {sorted(active)}")
    _close(
        model.constraint_jacobian_dot(t, q, qd, active),
        model._reference_constraint_jacobian_dot(t, q, qd, active),
        "constraint_jacobian_dot",
    )
    ev = model.evaluate(t, q, qd, active)
    _close(ev.M, np.diag(model._mdiag), "M")
    _close(ev.h, model._reference_conservative_force(q), "h")
    _close(ev.f_passive, model._reference_passive_force(q, qd), "f_passive")
    _close(ev.B, model._reference_input_matrix(q), "B")
    for field_, a, b in zip(ev.constraints._fields, ev.constraints, ref, strict=True):
        _close(a, b, f"evaluate.constraints.{field_}")
    _close(np.array(model.potential_energy(q)), np.array(model._reference_potential_energy(q)), "V")


def _state(model: PlanarModel, seed: int) -> tuple[float, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    return float(rng.uniform(-2.0, 2.0)), rng.standard_normal(model.n), 2.0 * rng.standard_normal(model.n)


@pytest.mark.parametrize("seed", range(4))
def test_every_element_all_default_and_empty_active_sets(seed: int) -> None:
    t, q, qd = _state(MODEL, seed)
    for active in (frozenset(NAMES), MODEL.default_active, frozenset()):
        _check_state(MODEL, t, q, qd, active)


@given(
    seed=st.integers(0, 2**31 - 1),
    mask=st.lists(st.booleans(), min_size=len(NAMES), max_size=len(NAMES)),
)
def test_every_element_random_active_subsets(seed: int, mask: list[bool]) -> None:
    t, q, qd = _state(MODEL, seed)
    _check_state(MODEL, t, q, qd, frozenset(n for n, on in zip(NAMES, mask, strict=True) if on))


def test_single_constraints_and_pairs() -> None:
    t, q, qd = _state(MODEL, 11)
    for name in NAMES:
        _check_state(MODEL, t, q, qd, frozenset({name}))
    for pair in list(combinations(NAMES, 2))[::7]:
        _check_state(MODEL, t, q, qd, frozenset(pair))


def test_user_defined_joint_uses_its_own_terms() -> None:
    model = MODEL.replace(joints=(*MODEL.joints[:3], XFix("xfix", "b1", 0.2), *MODEL.joints[3:]))
    t, q, qd = _state(model, 3)
    for active in (frozenset(model.constraint_names), frozenset({"xfix", "rev2"}), frozenset({"xfix"})):
        _check_state(model, t, q, qd, active)
    rows = model.row_slices(frozenset(model.constraint_names))["xfix"]
    ct = model.constraint_terms(t, q, qd, frozenset(model.constraint_names))
    assert ct.phi[rows][0] == pytest.approx(q[0] - 0.2 - 0.1 * t, abs=1e-15)
    assert ct.velocity[rows][0] == pytest.approx(qd[0] - 0.1, abs=1e-15)


LIBRARY = [
    ("crossed_four_bar", {}),
    ("A01_pendulum", {}),
    ("A02_n_four_bar", {"N": 2}),
    ("A02_n_four_bar", {"N": 12}),
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
    _check_state(model, float(s.t), s.q, s.qd, s.active)
    _check_state(model, float(s.t), s.q, s.qd, everything)
    for seed in range(2):
        t, q, qd = _state(model, seed)
        _check_state(model, t, s.q + 0.3 * q, qd, s.active)
        _check_state(model, t, q, qd, everything)


def test_returned_arrays_are_fresh_and_the_model_is_unchanged() -> None:
    t, q, qd = _state(MODEL, 5)
    act = frozenset(NAMES)
    first = MODEL.evaluate(t, q, qd, act)
    ref = [a.copy() for a in (first.M, first.h, first.f_passive, first.B, *first.constraints)]
    for a in (first.M, first.h, first.f_passive, first.B, first.constraints.A, first.constraints.gamma):
        a += 1.0  # callers may write into what they get
    MODEL.mass_matrix(q)[0, 0] = -5.0
    MODEL.input_matrix(q)[:] = 7.0
    again = MODEL.evaluate(t, q, qd, act)
    for a, b in zip((again.M, again.h, again.f_passive, again.B, *again.constraints), ref, strict=True):
        np.testing.assert_array_equal(a, b)


def test_layout_cache_does_not_leak_between_active_sets_and_survives_pickle() -> None:
    t, q, qd = _state(MODEL, 7)
    sets = [frozenset(NAMES), frozenset({"rev", "rod"}), MODEL.default_active, frozenset({"rev", "rod"})]
    first = [MODEL.constraint_terms(t, q, qd, a) for a in sets]
    clone = pickle.loads(pickle.dumps(MODEL))
    for a, ct in zip(sets, first, strict=True):
        for x, y in zip(MODEL.constraint_terms(t, q, qd, a), ct, strict=True):
            np.testing.assert_array_equal(x, y)
        for x, y in zip(clone.constraint_terms(t, q, qd, a), ct, strict=True):
            np.testing.assert_array_equal(x, y)
    # lists, tuples and single names resolve to the same layout
    np.testing.assert_array_equal(MODEL.constraint_terms(t, q, qd, ["rod", "rev"]).A, first[1].A)
    np.testing.assert_array_equal(MODEL.constraint_terms(t, q, qd, "rev").A, first[1].A[:2])
    # a parameter variant gets its own layouts
    light = MODEL.replace(bodies=(Body("b1", 0.1, 0.01), *MODEL.bodies[1:]))
    assert light.evaluate(t, q, qd).M[0, 0] == 0.1
    assert MODEL.evaluate(t, q, qd).M[0, 0] == 1.2


def test_bad_input_is_rejected_once_with_typed_errors() -> None:
    t, q, qd = _state(MODEL, 1)
    with pytest.raises(UnknownNameError, match="nope"):
        MODEL.evaluate(t, q, qd, frozenset({"rev", "nope"}))
    with pytest.raises(UnknownNameError, match="nope"):
        MODEL.constraint_terms(t, q, qd, ["nope"])
    with pytest.raises(ShapeError, match="q must have shape"):
        MODEL.evaluate(t, q[:-1], qd)
    with pytest.raises(ShapeError, match="qd must have shape"):
        MODEL.constraint_terms(t, q, qd[:, None])
    bad = q.copy()
    bad[2] = np.nan
    with pytest.raises(NonFiniteError, match="q must be finite"):
        MODEL.evaluate(t, bad, qd)
    bad = qd.copy()
    bad[0] = np.inf
    with pytest.raises(NonFiniteError, match="qd must be finite"):
        MODEL.constraint_terms(t, q, bad)
    # huge but finite values (q·q overflows in the quick test) pass the exact test
    big = 1e160 * (1.0 + np.arange(MODEL.n))
    with np.errstate(all="ignore"):
        assert np.isfinite(MODEL.evaluate(t, big, qd, frozenset({"rev2", "weld"})).constraints.A).all()
    # array-likes are accepted
    ev = MODEL.evaluate(t, q.tolist(), tuple(qd))
    _close(ev.constraints.A, MODEL.constraint_terms(t, q, qd).A, "A from lists")


def test_revolute_only_model_built_directly() -> None:
    """A model assembled from element values (not the builder): two pendulums chained."""
    model = PlanarModel(
        "chain",
        bodies=(Body("l1", 1.0, 0.1), Body("l2", 2.0, 0.2)),
        joints=(
            Revolute("j1", Point("ground", (0.0, 0.0)), Point("l1", (-0.5, 0.0))),
            Revolute("j2", Point("l1", (0.5, 0.0)), Point("l2", (-0.5, 0.0))),
        ),
    )
    t, q, qd = _state(model, 2)
    _check_state(model, t, q, qd, frozenset({"j1", "j2"}))
    ct = model.constraint_terms(t, q, qd)
    c1, s1 = math.cos(q[2]), math.sin(q[2])
    assert ct.phi[0] == pytest.approx(0.0 - (q[0] - 0.5 * c1), abs=1e-15)
    assert ct.phi[1] == pytest.approx(0.0 - (q[1] - 0.5 * s1), abs=1e-15)
