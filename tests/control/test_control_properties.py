"""Properties of the actuation map u = (PB)⁺ f_∥ and the public surface of nonmin.control."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import nonmin.control as control
from nonmin.control._common import Evaluation, actuate
from nonmin.core import range_basis
from nonmin.errors import InfeasibleActuationError


def _evaluation(A: np.ndarray, B: np.ndarray) -> Evaluation:
    n = A.shape[1]
    basis = range_basis(A)
    z = np.zeros(n)
    return Evaluation(M=np.eye(n), h=z, f_g=z, f_p=z, B=B, A=A, gamma=np.zeros(A.shape[0]),
                      P=basis.nullspace_projector(), rank=int(basis.rank), basis=basis)


@given(
    n=st.integers(2, 6),
    m=st.integers(0, 4),
    k=st.integers(1, 6),
    seed=st.integers(0, 2**31 - 1),
    redundant=st.booleans(),
)
def test_actuation_realizes_any_admissible_force(n: int, m: int, k: int, seed: int, redundant: bool) -> None:
    """If rank(PB) = n − rank A, then P B (PB)⁺ f_∥ = f_∥ for every f_∥ ∈ N (with redundant
    rows in A and redundant actuators too); otherwise the controller's actuation raises."""
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(m, n))
    if redundant and m:
        A = np.vstack([A, 2.0 * A[:1]])  # a duplicated (redundant) constraint row
    B = rng.normal(size=(n, k))
    ev = _evaluation(A, B)
    f_par = ev.P @ rng.normal(size=n)
    rank_pb = np.linalg.matrix_rank(ev.P @ B, tol=1e-9)
    if rank_pb >= ev.dof:
        u, feasible, sigma = actuate(ev, f_par, policy="raise", rtol=None, t=0.0)
        assert feasible
        np.testing.assert_allclose(ev.P @ B @ u, f_par, atol=1e-9 * (1 + np.abs(f_par).max()))
        # minimum norm: u has no component in N(PB)
        null = np.linalg.svd(ev.P @ B)[2][rank_pb:]
        assert np.abs(null @ u).max(initial=0.0) < 1e-8 * (1 + np.abs(u).max())
        assert sigma.size == min(n, k)
    else:
        with pytest.raises(InfeasibleActuationError, match="rank\\(PB\\)"):
            actuate(ev, f_par, policy="raise", rtol=None, t=0.0)
        u, feasible, _ = actuate(ev, f_par, policy="least_squares", rtol=None, t=0.0)
        assert not feasible and np.isfinite(u).all()


def test_redundant_actuation_where_the_paper_formula_fails() -> None:
    """B = I (redundant actuation): BᵀPB is singular, Γ = (PB)⁺ still works (ERRATA 4)."""
    A = np.array([[1.0, 1.0, 0.0]])
    ev = _evaluation(A, np.eye(3))
    assert np.linalg.matrix_rank(ev.B.T @ ev.P @ ev.B) == 2  # (BᵀPB)⁻¹ does not exist
    f_par = ev.P @ np.array([1.0, -2.0, 3.0])
    u, feasible, _ = actuate(ev, f_par, policy="raise", rtol=None, t=0.0)
    assert feasible
    np.testing.assert_allclose(u, f_par, atol=1e-14)  # (PB)⁺ = P for B = I


def test_public_surface() -> None:
    assert sorted(control.__all__) == sorted([
        "CONTROLLERS", "ControlInfo", "ControlState", "Controller", "get", "names", "ForceControl", "LawOutput",
        "ProjectedController", "Reference", "Regulator", "Switched", "Tracker",
        "align_quaternions", "constraint_force_components", "project_acceleration",
        "project_configuration", "project_velocity",
    ])
    for name in control.__all__:
        if name != "CONTROLLERS":
            assert getattr(control, name).__doc__, f"{name} has no docstring"
    assert set(control.names()) >= {"regulator", "tracker", "hybrid_force"}


@given(n=st.integers(3, 6), seed=st.integers(0, 2**31 - 1))
def test_force_control_sets_the_commanded_rows_and_keeps_the_motion(n: int, seed: int) -> None:
    """For random linear constraints, inertia and full actuation: the constraint force carried by
    the commanded row equals λ* and P f equals the motion controller's f_∥ (checked against an
    independent KKT solve)."""
    from nonmin.control import ForceControl, Regulator
    from nonmin.model import FunctionConstraint, FunctionModel

    rng = np.random.default_rng(seed)
    m = int(rng.integers(1, n - 1))
    A = rng.normal(size=(m, n))
    L = rng.normal(size=(n, n))
    M = L @ L.T + n * np.eye(n)
    cons = [
        FunctionConstraint.holonomic(
            f"c{i}", phi=lambda q, a=A[i]: [a @ q], jacobian=lambda q, a=A[i]: a[None, :],
            adot_qd=lambda q, qd: [0.0])
        for i in range(m)
    ]
    model = FunctionModel(
        name="random", coordinate_names=tuple(f"q{i}" for i in range(n)), mass=lambda q: M,
        coriolis=lambda q, qd: np.zeros((n, n)), conservative=lambda q: -q,
        potential=lambda q: 0.5 * q @ q, constraints=cons,
        actuator_names=tuple(f"u{i}" for i in range(n)), input_matrix_fn=lambda q: np.eye(n))
    P = np.eye(n) - np.linalg.pinv(A) @ A
    q = P @ rng.normal(size=n)
    qd = P @ rng.normal(size=n)
    lam_star = float(rng.normal())
    ctl = ForceControl(Regulator(model, target=np.zeros(n), Kp=2.0, Kd=1.0), {"c0": lam_star})
    info = ctl.info(0.0, q, qd)
    f = info.u  # B = I
    # KKT: [M Aᵀ; A 0] [qdd; −λ] = [f + f_g; 0]  (f_c = Aᵀλ)
    K = np.block([[M, -A.T], [A, np.zeros((m, m))]])
    sol = np.linalg.solve(K, np.concatenate([f - q, np.zeros(m)]))
    assert sol[n] == pytest.approx(lam_star, abs=1e-9 * (1 + abs(lam_star)))
    np.testing.assert_allclose(P @ f, info.f_par, atol=1e-9 * (1 + np.abs(f).max()))
