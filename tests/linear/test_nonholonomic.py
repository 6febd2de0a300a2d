"""Nonholonomic linearization: the Chaplygin sleigh (SymPy model, TapeProgram on its tape's
forward mode) against its classical reduced equations.

Centre of mass (x, y), heading θ; the knife edge sits a distance a behind the centre of mass
and cannot slide sideways: −sin θ ẋ + cos θ ẏ − a θ̇ = 0. With u the edge's forward speed and ω
the turning rate, ẋ = u cos θ − a ω sin θ, ẏ = u sin θ + a ω cos θ, θ̇ = ω and (Neimark &
Fufaev; Bloch, *Nonholonomic Mechanics and Control*, §1.7) u̇ = a ω², ω̇ = −m a u ω / (I + m a²).
Linearized about straight motion (θ = 0, u = v, ω = 0) in the reduced state (x, y, θ, u, ω),
mapped to nonmin's tangent state x = (δq, Zᵀ δq̇), it must equal nonmin's 5 × 5 system —
whose δẏ = v δθ comes from the curvature term K.
"""

import numpy as np
import pytest

import nonmin


def _sleigh(m=1.3, I=0.4, a=0.35):
    sp = pytest.importorskip("sympy")  # here, not at collection (every xdist worker)
    from nonmin.model.symbolic import SymbolicConstraint, SymbolicModel

    x, y, th = sp.symbols("x y theta")
    M = sp.diag(m, m, I)
    edge = SymbolicConstraint.nonholonomic("edge", [[-sp.sin(th), sp.cos(th), -a]])
    return SymbolicModel.from_mass_matrix(
        "chaplygin_sleigh", q=[x, y, th], M=M, V=sp.Integer(0), constraints=[edge]
    )


def test_chaplygin_sleigh_linearization_equals_the_reduced_equations():
    m, I, a, v = 1.3, 0.4, 0.35, 0.8
    model = _sleigh(m, I, a)
    q0 = np.zeros(3)
    qd0 = np.array([v, 0.0, 0.0])
    lin = nonmin.linearize(model, q0, qd0)
    assert lin.tangent_dim == 3 and lin.velocity_dim == 2  # no holonomic rows: δq is free
    A_red = np.zeros((5, 5))
    A_red[0, 3] = 1.0  # δẋ = δu
    A_red[1, 2], A_red[1, 4] = v, a  # δẏ = v δθ + a δω
    A_red[2, 4] = 1.0  # δθ̇ = δω
    A_red[4, 4] = -m * a * v / (I + m * a * a)  # δω̇
    # reduced -> tangent: δq = (δx, δy, δθ); δq̇ = (δu, v δθ + a δω, δω)
    dqd = np.array([[0, 0, 0, 1, 0], [0, 0, v, 0, a], [0, 0, 0, 0, 1]], float)
    T = np.vstack([np.hstack([np.eye(3), np.zeros((3, 2))]), lin.Zv.T @ dqd])
    assert np.allclose(lin.A @ T, T @ A_red, rtol=1e-10, atol=1e-12)
    # the output map returns the admissible velocity perturbation of a reduced perturbation
    r = np.array([0.1, -0.2, 0.05, 0.3, -0.4])
    dq, dv = lin.to_dependent(T @ r)
    assert np.allclose(dq, r[:3], atol=1e-14) and np.allclose(dv, dqd @ r, atol=1e-12)
