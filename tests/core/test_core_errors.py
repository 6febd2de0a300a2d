"""Bad input raises the typed errors of nonmin.errors, naming the argument, expected vs received.

Degenerate but valid input (m = 0, all-zero A, zero rows, singular M fixed by a constraint)
works and gives the right answer.
"""

from __future__ import annotations

import numpy as np
import pytest
from core_testlib import REF_RTOL, rel

from nonmin.core import (
    actuation_projectors,
    baumgarte_bias,
    constraint_force,
    constraint_force_projector,
    constraint_inertia,
    coriolis_bar,
    forward_dynamics,
    impact_map,
    nullspace_projector,
    position_correction,
    solve_dynamics,
)
from nonmin.errors import (
    InfeasibleActuationError,
    InputError,
    NonFiniteError,
    NonminError,
    NotPositiveDefiniteError,
    NotSymmetricError,
    ShapeError,
)

M3 = np.diag([2.0, 3.0, 4.0])
H3 = np.array([0.1, -0.2, 0.3])
A13 = np.array([[1.0, 1.0, 0.0]])
G1 = np.array([0.5])


# --------------------------------------------------------------------------- shapes


@pytest.mark.parametrize(
    "kwargs,arg,expected,received",
    [
        (dict(h=np.zeros(2)), "h", r"\(\.\.\., 3\)", r"\(2,\)"),
        (dict(A=np.zeros((1, 4))), "A", r"\(\.\.\., m, 3\)", r"\(1, 4\)"),
        (dict(A=np.zeros(3)), "A", r"\(\.\.\., m, 3\)", r"\(3,\)"),
        (dict(adot_qd=np.zeros(2)), "adot_qd", r"\(\.\.\., 1\)", r"\(2,\)"),
        (dict(f=np.zeros((3, 1))), "f", r"\(\.\.\., 3\)", r"\(3, 1\)"),
        (dict(M=np.zeros((3, 2))), "M", r"\(\.\.\., n, n\)", r"\(3, 2\)"),
    ],
)
def test_wrong_shapes_name_argument_expected_and_received(kwargs, arg, expected, received):
    args = dict(M=M3, h=H3, A=A13, adot_qd=G1, f=None) | kwargs
    with pytest.raises(ShapeError, match=rf"^{arg} .*{expected}.*got shape {received}") as ei:
        forward_dynamics(**args)
    assert isinstance(ei.value, ValueError) and isinstance(ei.value, NonminError)


def test_batch_shapes_that_do_not_broadcast():
    with pytest.raises(ShapeError, match=r"leading \(batch\) dimensions.*h: \(4,\).*A: \(5,\)"):
        forward_dynamics(M3, np.zeros((4, 3)), np.zeros((5, 1, 3)), np.zeros((5, 1)))


def test_non_numeric_input():
    with pytest.raises(ShapeError, match=r"^M must be a numeric array"):
        forward_dynamics("not a matrix", H3, A13, G1)


@pytest.mark.parametrize(
    "fn",
    [
        lambda: impact_map(M3, A13, np.zeros(2)),
        lambda: position_correction(M3, A13, np.zeros(2)),
        lambda: constraint_inertia(M3, np.eye(2), 1.0),
        lambda: coriolis_bar(M3, np.eye(3), A13, np.zeros((2, 3)), 1.0),
        lambda: actuation_projectors(np.zeros((2, 1)), np.eye(3)),
        lambda: nullspace_projector(np.zeros(3)),
    ],
)
def test_wrong_shapes_in_other_kernels(fn):
    with pytest.raises(ShapeError, match=r"must (have|be square with) shape .*got shape"):
        fn()


# --------------------------------------------------------------------------- values


@pytest.mark.parametrize("arg", ["M", "h", "A", "adot_qd", "f"])
@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_non_finite_input_names_argument(arg, bad):
    args = dict(M=M3.copy(), h=H3.copy(), A=A13.copy(), adot_qd=G1.copy(), f=H3.copy())
    x = args[arg]
    x.flat[0] = bad
    with pytest.raises(NonFiniteError, match=rf"^{arg} must be finite.*1 NaN/inf entries"):
        forward_dynamics(**args)


def test_non_finite_velocity_in_impact_map():
    with pytest.raises(NonFiniteError, match=r"^qd_minus must be finite"):
        impact_map(M3, A13, [0.0, np.nan, 1.0])


def test_non_symmetric_M():
    M = M3.copy()
    M[0, 1] = 0.5
    for fn in (
        lambda: forward_dynamics(M, H3, A13, G1),
        lambda: constraint_force(M, H3, A13, G1),
        lambda: impact_map(M, A13, H3),
        lambda: constraint_inertia(M, np.eye(3), 1.0),
    ):
        with pytest.raises(NotSymmetricError, match=r"^M must be symmetric.*relative asymmetry"):
            fn()


def test_tiny_asymmetry_from_roundoff_is_accepted():
    M = M3 + np.triu(np.full((3, 3), 1e-13), 1)
    assert np.all(np.isfinite(forward_dynamics(M, H3, A13, G1)))


@pytest.mark.parametrize(
    "fn,arg",
    [
        (lambda: forward_dynamics(M3, H3, A13, G1, mu=0.0), "mu"),
        (lambda: forward_dynamics(M3, H3, A13, G1, mu=-1.0), "mu"),
        (lambda: forward_dynamics(M3, H3, A13, G1, rtol=0.0), "rtol"),
        (lambda: forward_dynamics(M3, H3, A13, G1, rtol=2.0), "rtol"),
        (lambda: impact_map(M3, A13, H3, restitution=1.5), "restitution"),
        (lambda: impact_map(M3, A13, H3, restitution=-0.1), "restitution"),
        (lambda: baumgarte_bias(G1, G1, G1, alpha=-1.0), "alpha"),
        (lambda: constraint_inertia(M3, np.eye(3), [1.0, -2.0]), "mu"),
    ],
)
def test_out_of_range_parameters(fn, arg):
    with pytest.raises(InputError, match=rf"^{arg} must"):
        fn()


# --------------------------------------------------------------------------- M not PD on N(A)

M_ZERO = np.diag([1.0, 1.0, 0.0])  # third coordinate has no inertia


@pytest.mark.parametrize(
    "fn",
    [
        lambda A: forward_dynamics(M_ZERO, H3, A, np.zeros(A.shape[0])),
        lambda A: constraint_force(M_ZERO, H3, A, np.zeros(A.shape[0])),
        lambda A: solve_dynamics(M_ZERO, H3, A, np.zeros(A.shape[0])),
        lambda A: impact_map(M_ZERO, A, H3),
        lambda A: position_correction(M_ZERO, A, np.zeros(A.shape[0])),
        lambda A: constraint_force_projector(M_ZERO, nullspace_projector(A)[0], 1.0),
    ],
)
@pytest.mark.parametrize(
    "A",
    [np.zeros((0, 3)), np.array([[1.0, 0.0, 0.0]]), np.array([[0.0, 0.0, 0.0]])],
    ids=["m=0", "fixes-x-only", "all-zero"],
)
def test_zero_inertia_coordinate_not_fixed_raises(fn, A):
    with pytest.raises(NotPositiveDefiniteError, match=r"not positive definite|singular"):
        fn(A)


def test_indefinite_M_on_nullspace_raises():
    M = np.diag([1.0, -1.0, 1.0])
    with pytest.raises(NotPositiveDefiniteError):
        forward_dynamics(M, H3, np.array([[0.0, 0.0, 1.0]]), [0.0])


def test_one_bad_element_in_a_batch_raises():
    M = np.stack([M3, M_ZERO])
    with pytest.raises(NotPositiveDefiniteError):
        forward_dynamics(M, np.zeros((2, 3)), np.zeros((2, 1, 3)), np.zeros((2, 1)))


def test_zero_inertia_coordinate_fixed_by_a_constraint_works():
    """M singular off N(A) is fine: the massless coordinate is fixed (quaternion-like case)."""
    A = np.array([[0.0, 0.0, 1.0]])
    qdd = forward_dynamics(M_ZERO, H3, A, [0.7])
    assert np.allclose(qdd, [0.1, -0.2, -0.7], rtol=0, atol=REF_RTOL)
    fc = constraint_force(M_ZERO, H3, A, [0.7])
    assert np.allclose(fc, [0.0, 0.0, -0.3], rtol=0, atol=REF_RTOL)


def test_infeasible_actuation_message():
    P, _ = nullspace_projector(A13)
    with pytest.raises(InfeasibleActuationError, match=r"rank\(PB\) = 1 < n − rank\(A\) = 2"):
        actuation_projectors(np.array([[0.0], [0.0], [1.0]]), P)


# --------------------------------------------------------------------------- degenerate valid input


def test_no_constraints_all_zero_A_and_zero_rows():
    g = H3 + np.array([1.0, 2.0, 3.0])
    free = np.linalg.solve(M3, g)
    q0 = forward_dynamics(M3, H3, np.zeros((0, 3)), np.zeros(0), f=[1.0, 2.0, 3.0])
    assert rel(q0, free) <= REF_RTOL
    P, r = nullspace_projector(np.zeros((0, 3)))
    assert int(r) == 0 and np.array_equal(P, np.eye(3))
    qz = forward_dynamics(M3, H3, np.zeros((2, 3)), np.zeros(2), f=[1.0, 2.0, 3.0])
    assert rel(qz, free) <= REF_RTOL
    assert np.abs(constraint_force(M3, H3, np.zeros((2, 3)), np.zeros(2))).max() <= REF_RTOL
    # zero rows change nothing
    A = np.array([[1.0, 1.0, 0.0], [0.0, 0.0, 0.0], [0.0, 1.0, -1.0], [0.0, 0.0, 0.0]])
    gam = np.array([0.5, 0.0, -0.2, 0.0])
    qa = forward_dynamics(M3, H3, A, gam)
    qb = forward_dynamics(M3, H3, A[[0, 2]], gam[[0, 2]])
    assert rel(qa, qb) <= REF_RTOL
    assert rel(impact_map(M3, np.zeros((0, 3)), H3), H3) <= REF_RTOL
    assert np.array_equal(position_correction(M3, np.zeros((0, 3)), np.zeros(0)), np.zeros(3))


def test_fully_constrained_and_m_greater_than_n():
    A = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 1.0, 1.0]])
    gam = A @ np.array([0.3, -0.1, 0.2])
    qdd = forward_dynamics(M3, H3, A, gam)
    assert rel(qdd, -np.array([0.3, -0.1, 0.2])) <= REF_RTOL
    P, r = nullspace_projector(A)
    assert int(r) == 3 and np.abs(P).max() <= 1e-15


# ---- real numbers only: NumPy would parse text, count booleans and drop imaginary parts ----
_FD = {"M": np.eye(2), "h": [0.0, -9.81], "A": [[1.0, 0.0]], "adot_qd": [1.0]}


@pytest.mark.parametrize(
    ("arg", "value", "words"),
    [
        ("M", np.eye(2) * (1 + 1j), ["M", "complex"]),
        ("M", [["1", "0"], ["0", "1"]], ["M", "numeric array, got text"]),
        ("h", np.array([True, False]), ["h", "booleans"]),
        ("A", np.array([[1.0, "0"]], dtype=object), ["A", "text"]),
    ],
)
def test_kernels_refuse_text_booleans_and_complex(arg, value, words):
    from nonmin.core import forward_dynamics
    from nonmin.errors import InputError

    with pytest.raises(InputError) as info:
        forward_dynamics(**{**_FD, arg: value})
    for w in words:
        assert w in str(info.value)


def test_kernels_take_complex_with_zero_imaginary_part_without_warning():
    import warnings

    from nonmin.core import forward_dynamics

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        qdd = forward_dynamics(**{**_FD, "M": np.eye(2).astype(complex)})
    np.testing.assert_allclose(qdd, [-1.0, -9.81])
