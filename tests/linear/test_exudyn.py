"""IFToMM linearization benchmark "Fourbar linkage with diagonal spring" (B. Minaker).

The problem (iftomm-multibody.org benchmark, solved there with EoM; parameters as in EoM's
input file ``input_ex_four_bar.m``): three uniform thin bars of 1 m and 1 kg (crank, coupler,
rocker; I = mL²/12 about the centre) on ground pivots (0, 0) and (1, 0), so the linkage is a
parallelogram; gravity 9.81 m/s² along −y; a spring–damper (k = 25 N/m, c = 1 N·s/m) from
the crank's ground pivot to the coupler–rocker joint. The benchmark gives the equilibrium
rocker angle φ = 2.23433101898 rad; a free length of √2 m (the diagonal of the unit square)
reproduces it (to 4e-11: the closed form below), and is used here.

Checks:

* ``nonmin.equilibrium`` finds the published angle (to 1e-10);
* the one damped mode equals the exact 1-DOF reduction in φ (every bar turns or translates
  with φ): I φ̈ + c s'² φ̇ + V''(φ) δφ = 0 with I = 1/3 + 1 + 1/3 = 5/3 m·kg,
  V = 2 g sin φ + k (s − √2)²/2, s = 2 cos(φ/2) the spring length (relative 1e-10);
* Exudyn's ``ComputeODE2Eigenvalues`` on the same model built here in Exudyn (RigidBody2D,
  RevoluteJoint2D, SpringDamper): the stiffness Exudyn's routine projects on the null space of
  the constraint Jacobian is the tangent stiffness of the applied forces (spring and gravity)
  without the geometric stiffness of the constraint forces — nonzero here (the joints carry the
  spring's preload and the weight): Exudyn's ω² is 10.35 against the reduction's 4.6125.
  With Exudyn's own static multipliers λ (``SolveStatic``) and constraint Jacobian C
  (``ComputeLinearizedSystem``) that term, −Σ λᵢ ∂²Cᵢ/∂q² in Exudyn's sign (M q̈ = f + C_qᵀλ), is
  added to Exudyn's stiffness on Exudyn's null-space basis, and the undamped ω² and the damped
  eigenvalues (with Exudyn's damping matrix) are compared (1e-8; measured 1e-15); without
  gravity and preload (λ = 0) Exudyn's routine (undamped and ``computeComplexEigenvalues``) is
  compared as it is.
"""

import math

import numpy as np
import pytest

import nonmin
from nonmin.model.planar import PlanarBuilder

G = 9.81
K_SPRING, C_SPRING = 25.0, 1.0
FREE_LENGTH = math.sqrt(2.0)
#: Equilibrium rocker angle given by the benchmark (12 digits).
PHI_PUBLISHED = 2.23433101898
I_BAR = 1.0 / 12.0


def _config(phi):
    """(x, y, θ) of crank, coupler, rocker on the parallelogram at rocker angle φ."""
    c, s = math.cos(phi), math.sin(phi)
    return np.array([0.5 * c, 0.5 * s, phi, c + 0.5, s, 0.0, 1.0 + 0.5 * c, 0.5 * s, phi])


def _nonmin_model(gravity=G, free_length=FREE_LENGTH, damping=C_SPRING):
    b = PlanarBuilder("iftomm_fourbar_spring", gravity=(0.0, -gravity))
    for name in ("crank", "coupler", "rocker"):
        b.body(
            name, mass=1.0, inertia=I_BAR, points={f"{name}0": (-0.5, 0.0), f"{name}1": (0.5, 0.0)}
        )
    b.revolute("O1", ("ground", (0.0, 0.0)), "crank0")
    b.revolute("B", "crank1", "coupler0")
    b.revolute("C", "coupler1", "rocker1")
    b.revolute("O2", ("ground", (1.0, 0.0)), "rocker0")
    b.spring("diagonal", ("ground", (0.0, 0.0)), "coupler1", stiffness=K_SPRING,
             rest_length=free_length, damping=damping)  # fmt: skip
    return b.build()


def _reduced(phi):
    """Exact 1-DOF reduction in φ: (V'(φ), I, c_eff, k_eff)."""
    s = 2 * math.cos(phi / 2)
    s1, s2 = -math.sin(phi / 2), -0.5 * math.cos(phi / 2)
    dV = 2 * G * math.cos(phi) + K_SPRING * (s - FREE_LENGTH) * s1
    k_eff = -2 * G * math.sin(phi) + K_SPRING * (s1 * s1 + (s - FREE_LENGTH) * s2)
    return dV, 5.0 / 3.0, C_SPRING * s1 * s1, k_eff


def test_iftomm_fourbar_equilibrium_and_mode_match_the_exact_reduction():
    model = _nonmin_model()
    eq = nonmin.equilibrium(model, _config(2.2))
    assert eq.converged
    phi = float(eq.q[8])
    assert np.allclose(eq.q, _config(phi), atol=1e-12)
    assert abs(phi - PHI_PUBLISHED) <= 1e-10
    dV, I, c_eff, k_eff = _reduced(phi)
    assert abs(dV) <= 1e-12
    m = nonmin.modes(model, eq.q)
    assert m.frequencies.shape == (1,) and m.stable
    lam_ref = np.roots([I, c_eff, k_eff])
    lam = np.sort_complex(m.eigenvalues)
    assert np.allclose(lam, np.sort_complex(lam_ref), rtol=1e-10, atol=0)
    assert abs(m.frequencies[0] - math.sqrt(k_eff / I)) <= 1e-10 * math.sqrt(k_eff / I)
    assert abs(m.damping_ratios[0] - c_eff / (2 * math.sqrt(k_eff * I))) <= 1e-10


# ------------------------------------------------------------------ Exudyn
def _exudyn(q, gravity, free_length, damping):
    exu = pytest.importorskip("exudyn")
    import inspect

    from exudyn.itemInterface import (
        LoadForceVector,
        MarkerBodyPosition,
        NodeRigidBody2D,
        ObjectGround,
        ObjectRigidBody2D,
        RevoluteJoint2D,
        SpringDamper,
    )  # fmt: skip

    # Exudyn ≥ 1.12.258 names them mass/inertia (physicsMass/physicsInertia deprecated)
    new_names = "mass" in inspect.signature(ObjectRigidBody2D.__init__).parameters
    body_kw = (
        {"mass": 1.0, "inertia": I_BAR}
        if new_names
        else {"physicsMass": 1.0, "physicsInertia": I_BAR}
    )
    SC = exu.SystemContainer()
    mbs = SC.AddSystem()
    ground = mbs.AddObject(ObjectGround())
    bodies = []
    for i in range(3):
        n = mbs.AddNode(NodeRigidBody2D(referenceCoordinates=list(q[3 * i : 3 * i + 3])))
        o = mbs.AddObject(ObjectRigidBody2D(nodeNumber=n, **body_kw))
        bodies.append(o)
        if gravity:
            mc = mbs.AddMarker(MarkerBodyPosition(bodyNumber=o, localPosition=[0.0, 0.0, 0.0]))
            mbs.AddLoad(LoadForceVector(markerNumber=mc, loadVector=[0.0, -gravity, 0.0]))

    def marker(body, x):
        return mbs.AddMarker(MarkerBodyPosition(bodyNumber=body, localPosition=[x, 0.0, 0.0]))

    crank, coupler, rocker = bodies
    g0 = mbs.AddMarker(MarkerBodyPosition(bodyNumber=ground, localPosition=[0.0, 0.0, 0.0]))
    g1 = mbs.AddMarker(MarkerBodyPosition(bodyNumber=ground, localPosition=[1.0, 0.0, 0.0]))
    joints = [
        ("O1", g0, marker(crank, -0.5), crank, -0.5, None),
        ("B", marker(crank, 0.5), marker(coupler, -0.5), crank, 0.5, (coupler, -0.5)),
        ("C", marker(coupler, 0.5), marker(rocker, 0.5), coupler, 0.5, (rocker, 0.5)),
        ("O2", g1, marker(rocker, -0.5), rocker, -0.5, None),
    ]
    for _, ma, mb, *_ in joints:
        mbs.AddObject(RevoluteJoint2D(markerNumbers=[ma, mb]))
    mbs.AddObject(SpringDamper(markerNumbers=[g0, marker(coupler, 0.5)], stiffness=K_SPRING,
                               damping=damping, referenceLength=free_length))  # fmt: skip
    mbs.Assemble()
    return exu, mbs, joints


def _geometric_stiffness(q, lam, C):
    """Σ λᵢ ∂²φᵢ/∂q² of the four revolute joints in Exudyn's own sign: joint j's rows are
    φ = Σ ± (r + R(θ) s) over its bodies, the signs read from Exudyn's constraint Jacobian C
    (n × m, column 2j = ∂φ_x/∂q); ∂²(R(θ) s)/∂θ² = −R(θ) s, so only θθ entries are nonzero."""
    K = np.zeros((9, 9))
    ends = [[(0, -0.5)], [(0, 0.5), (1, -0.5)], [(1, 0.5), (2, 0.5)], [(2, -0.5)]]
    for j, pts in enumerate(ends):
        lj = lam[2 * j : 2 * j + 2]
        for i, sx in pts:
            sign = C[3 * i, 2 * j]
            assert abs(abs(sign) - 1.0) <= 1e-12
            th = q[3 * i + 2]
            K[3 * i + 2, 3 * i + 2] += sign * float(
                lj @ (-sx * np.array([math.cos(th), math.sin(th)]))
            )
    return K


def test_iftomm_fourbar_matches_exudyn_ComputeODE2Eigenvalues():
    model = _nonmin_model()
    q = nonmin.equilibrium(model, _config(PHI_PUBLISHED)).q
    m = nonmin.modes(model, q)
    exu, mbs, _ = _exudyn(q, G, FREE_LENGTH, C_SPRING)
    sims = exu.SimulationSettings()
    sims.staticSolver.newton.relativeTolerance = 1e-14
    sims.staticSolver.newton.absoluteTolerance = 1e-14
    if hasattr(sims, "solution"):  # Exudyn ≥ 1.13 names
        sims.linearSolver.solverType = exu.LinearSolverType.EXUdense
        sims.solution.file.write = False  # no solution/ folder in the cwd
        sims.solution.file.writeInitialValues = False
    else:
        sims.linearSolverType = exu.LinearSolverType.EXUdense
        sims.solutionSettings.writeSolutionToFile = False
        sims.solutionSettings.writeInitialValues = False
    mbs.SolveStatic(sims)
    # at nonmin's equilibrium Exudyn's static solve stays put (ODE2 coordinates are displacements)
    assert np.abs(np.asarray(mbs.systemData.GetODE2Coordinates())).max() <= 1e-10
    lam = np.asarray(mbs.systemData.GetAECoordinates(), dtype=float)
    assert np.abs(lam).max() > 1.0  # the joints carry load: the geometric stiffness matters
    M_, K_, D_, C, N = (np.asarray(x) for x in mbs.ComputeLinearizedSystem(
        returnConstraintJacobian=True, returnConstraintNullspace=True))  # fmt: skip
    assert N.shape == (1, 9)
    ev, _ = mbs.ComputeODE2Eigenvalues()
    Mz, Kz, Dz = ((N @ X @ N.T).item() for X in (M_, K_, D_))
    assert abs(ev[0] - Kz / Mz) <= 1e-10 * abs(ev[0])  # Exudyn's eigenvalue is its projection
    Kg = (N @ _geometric_stiffness(q, lam, C) @ N.T).item()
    # Exudyn's multipliers enter its equations as M q̈ = f + C_qᵀ λ: the tangent stiffness is
    # K − Σ λᵢ ∂²Cᵢ/∂q²
    assert abs(m.frequencies[0] ** 2 - (Kz - Kg) / Mz) <= 1e-8 * (Kz - Kg) / Mz
    assert abs(ev[0] - m.frequencies[0] ** 2) > 0.5 * ev[0]  # without it: off by a factor > 2
    lam_ref = np.sort_complex(np.roots([Mz, Dz, Kz - Kg]))
    assert np.allclose(np.sort_complex(m.eigenvalues), lam_ref, rtol=1e-8)


def test_fourbar_without_preload_matches_exudyn_as_it_is():
    """No gravity, spring at its length at φ = 2.2 rad: zero constraint forces, so Exudyn's
    constrained eigenvalues (undamped and complex, with the damper) apply directly."""
    q = _config(2.2)
    s = float(np.linalg.norm(q[3:5] + np.array([0.5, 0.0])))  # coupler–rocker joint from the origin
    model = _nonmin_model(gravity=0.0, free_length=s)
    m = nonmin.modes(model, q)
    _, mbs, _ = _exudyn(q, 0.0, s, C_SPRING)
    ev, _ = mbs.ComputeODE2Eigenvalues()
    assert ev.shape == (1,)
    assert abs(m.frequencies[0] ** 2 - ev[0]) <= 1e-8 * ev[0]
    evc, _ = mbs.ComputeODE2Eigenvalues(computeComplexEigenvalues=True, useAbsoluteValues=False)
    assert np.allclose(np.sort_complex(m.eigenvalues), np.sort_complex(np.asarray(evc)), rtol=1e-8)
