"""Side-by-side simulation benchmark: nonmin against Exudyn, MuJoCo and Pinocchio.

Mechanisms (planar chains of uniform bars joined by revolute joints, closed loops):

* ``crossed_four_bar``: crank 1 m, coupler 2 m, rocker 1 m, ground 2 m (Grashof change point),
  started on the anti-parallelogram branch; its two branches cross at every collinear
  configuration.
* ``A02_N2`` / ``A02_N40``: IFToMM A02 N four-bar (N = 2, 10 s; N = 40, 20 s); the motion must
  stay in the parallelogram mode through every horizontal (singular) configuration.

Every engine builds its *own* model of the same mechanism from one neutral description
(:class:`BarMechanism`): bar lengths, masses, inertias, which end of which bar hangs on which
ground pivot or bar end, the loop closures, and the consistent initial state. Each run returns
the bar poses and rates (centre of mass, angle) sampled every ``SAMPLE_DT``; closure error,
energy drift and the branch test are then computed by the same code for every engine:

* closure error: the largest distance between two bar ends that a joint should keep together,
* energy drift: ``max_t |E(t) − E(0)|`` with ``E = Σ ½ m |v_c|² + ½ I ω² + m g y_c``,
* branch: the largest distance (rad) of the sampled configuration from the intended assembly
  branch (anti-parallelogram / parallelogram mode); "stays on branch" means < ``BRANCH_TOL``
  at every sample and no non-finite value,
* wall time per simulated second: median over ``--repeat`` timed runs, setup (model building,
  compilation) and one warm-up run excluded; the timed runs are interleaved (every setting
  once, then every setting again, …), so a drifting machine load weighs on all engines alike;
  after the first pass a short run is timed several times back to back (``SHORT_RUN_S``).

Peers and their settings:

* Exudyn: its own maximal-coordinate model (``NodeRigidBody2D`` + ``RevoluteJoint2D``),
  implicit generalized-α (default spectral radius 0.9) with fixed step ``dt``.
* MuJoCo: a kinematic tree of hinges, loops closed with ``<equality connect>``; ``default`` uses
  MuJoCo's default solver parameters, ``stiff`` sets ``solref = (2 dt, 1)`` and
  ``solimp = (0.99, 0.999, 0.001)``; semi-implicit Euler (MuJoCo's default integrator).
* Pinocchio: the same tree with ``JointModelRZ``, loops closed with ``RigidConstraintModel``
  (``CONTACT_3D``) and Baumgarte correction, proximal ``constraintDynamics``, semi-implicit
  Euler in a Python loop.
* nonmin: ``nonmin.sim.simulate`` on the library mechanism (see ``run_nonmin``).

Run ``python benchmarks/sim_bench.py`` (``--quick`` for a smoke run); results go to
``benchmarks/results/sim_bench.json`` and the table to ``benchmarks/SIM.md``.
"""

from __future__ import annotations

import os

# nonmin's kernels call LAPACK on small matrices: one BLAS thread is fastest and avoids
# oversubscription on a shared machine (MuJoCo, Pinocchio and Exudyn do not use OpenBLAS).
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import json
import math
import platform
import re
import statistics
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

G = 9.81
SAMPLE_DT = 0.01
LONG_RUN_S = 20.0  # nonmin runs longer than this are timed once (no separate warm-up)
SHORT_RUN_S = 0.25  # after the first pass, runs shorter than this are repeated up to this total
BRANCH_TOL = 0.05  # rad
HERE = Path(__file__).resolve().parent


# ---------------------------------------------------------------------------------------------
# neutral mechanism description
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class BarMechanism:
    """A planar mechanism of uniform bars joined by revolute joints.

    Bar ``i`` runs from its *start* point ``s_i`` to its *end* point ``s_i + L_i u(α_i)``
    (``u(α) = (cos α, sin α)``); its centre of mass is the midpoint. ``parents[i]`` says where
    its start is pinned: ``("ground", k)`` at ``ground[k]`` or ``("bar", j)`` at the end of bar
    ``j < i`` (a spanning tree). ``closures`` lists pairs ``(i, j)`` whose *ends* are pinned
    together (the loop-closing joints).
    """

    name: str
    lengths: np.ndarray
    masses: np.ndarray
    inertias: np.ndarray  # about the centre of mass
    ground: np.ndarray  # (k, 2)
    parents: tuple[tuple[str, int], ...]
    closures: tuple[tuple[int, int], ...]
    angles0: np.ndarray  # (nb,) absolute bar angles at t = 0
    rates0: np.ndarray  # (nb,) absolute angular velocities at t = 0
    t_final: float
    branch_distance: Callable[[np.ndarray], np.ndarray]  # angles (T, nb) -> (T,) [rad]
    notes: str = ""

    @property
    def nb(self) -> int:
        return len(self.lengths)

    def starts(self, angles: np.ndarray) -> np.ndarray:
        """Start points (…, nb, 2) of the bars from their absolute angles along the tree."""
        angles = np.asarray(angles, dtype=float)
        out = np.zeros((*angles.shape, 2))
        for i, (kind, k) in enumerate(self.parents):
            if kind == "ground":
                out[..., i, :] = self.ground[k]
            else:
                out[..., i, :] = out[..., k, :] + self.lengths[k] * _u(angles[..., k])
        return out

    def start_rates(self, angles: np.ndarray, rates: np.ndarray) -> np.ndarray:
        angles = np.asarray(angles, dtype=float)
        rates = np.asarray(rates, dtype=float)
        out = np.zeros((*angles.shape, 2))
        for i, (kind, k) in enumerate(self.parents):
            if kind == "bar":
                out[..., i, :] = out[..., k, :] + self.lengths[k] * rates[..., k, None] * _up(
                    angles[..., k]
                )
        return out

    def com_state(self, angles: np.ndarray, rates: np.ndarray) -> np.ndarray:
        """Per-bar (x_c, y_c, α, vx_c, vy_c, ω), shape (…, nb, 6)."""
        s = self.starts(angles)
        sd = self.start_rates(angles, rates)
        half = 0.5 * self.lengths
        c = s + half[:, None] * _u(angles)
        cd = sd + (half * rates)[..., None] * _up(angles)
        return np.concatenate([c, np.asarray(angles)[..., None], cd, np.asarray(rates)[..., None]],
                              axis=-1)


def _u(a: np.ndarray) -> np.ndarray:
    a = np.asarray(a, dtype=float)
    return np.stack([np.cos(a), np.sin(a)], axis=-1)


def _up(a: np.ndarray) -> np.ndarray:
    a = np.asarray(a, dtype=float)
    return np.stack([-np.sin(a), np.cos(a)], axis=-1)


def _wrap(a: np.ndarray) -> np.ndarray:
    return (np.asarray(a) + np.pi) % (2.0 * np.pi) - np.pi


def _complete_rates(mech_lengths: np.ndarray, parents: Sequence[tuple[str, int]],
                    closures: Sequence[tuple[int, int]], angles: np.ndarray, driver: int,
                    driver_rate: float, ground: np.ndarray) -> np.ndarray:
    """Absolute bar rates satisfying the loop closures' velocity equations with one bar driven."""
    nb = len(mech_lengths)
    # end point of bar i as a linear function of the rates: d e_i / d α̇ (2, nb)
    jac = np.zeros((nb, 2, nb))
    for i, (kind, k) in enumerate(parents):
        if kind == "bar":
            jac[i] += jac[k]
        jac[i][:, i] += mech_lengths[i] * _up(angles[i])
    rows = [jac[i] - jac[j] for i, j in closures]
    a = np.vstack(rows)
    free = [i for i in range(nb) if i != driver]
    rhs = -a[:, driver] * driver_rate
    sol, *_ = np.linalg.lstsq(a[:, free], rhs, rcond=None)
    rates = np.zeros(nb)
    rates[driver] = driver_rate
    rates[free] = sol
    res = a @ rates
    if np.max(np.abs(res)) > 1e-12:
        raise RuntimeError(f"inconsistent initial velocity (residual {np.max(np.abs(res)):.2e})")
    return rates


def a02_mechanism(n: int, t_final: float | None = None) -> BarMechanism:
    """IFToMM A02: N+1 cranks (vertical at t = 0) and N couplers (horizontal), 1 m, 1 kg each."""
    nb = 2 * n + 1
    lengths = np.ones(nb)
    masses = np.ones(nb)
    inertias = np.full(nb, 1.0 / 12.0)
    ground = np.array([[float(i), 0.0] for i in range(n + 1)])
    # bars 0..n: cranks (start at A_i); bars n+1..2n: couplers B_{i-1} -> B_i. Spanning tree
    # for the tree-based engines: the couplers form one serial chain hanging from crank 0, and
    # loop i is closed between the tip of coupler i and the tip of crank i.
    parents: list[tuple[str, int]] = [("ground", i) for i in range(n + 1)]
    parents += [("bar", 0)] + [("bar", n + i - 1) for i in range(2, n + 1)]
    closures = tuple((n + i, i) for i in range(1, n + 1))
    angles0 = np.array([np.pi / 2] * (n + 1) + [0.0] * n)
    rates0 = np.array([-1.0] * (n + 1) + [0.0] * n)

    def branch(angles: np.ndarray) -> np.ndarray:
        cr = angles[..., : n + 1]
        co = angles[..., n + 1 :]
        d1 = np.max(np.abs(_wrap(cr - cr[..., :1])), axis=-1)
        d2 = np.max(np.abs(_wrap(co)), axis=-1)
        return np.maximum(d1, d2)

    return BarMechanism(
        name=f"A02_N{n}", lengths=lengths, masses=masses, inertias=inertias, ground=ground,
        parents=tuple(parents), closures=closures, angles0=angles0, rates0=rates0,
        t_final=(10.0 if n == 2 else 20.0) if t_final is None else t_final,
        branch_distance=branch,
        notes="branch distance: max |crank_i − crank_0| and max |coupler angle| (rad)",
    )


def crossed_anti_rocker(theta: np.ndarray, a: float = 1.0, b: float = 2.0, c: float = 1.0,
                        g: float = 2.0) -> np.ndarray:
    """Rocker angle on the anti-parallelogram branch for crank angle θ (a = c, b = g only).

    The two assemblies are mirror images across the line B–D; the parallelogram one has the
    rocker parallel to the crank (ψ = θ), so the other is its reflection.
    """
    if not (math.isclose(a, c) and math.isclose(b, g)):
        raise ValueError("crossed_anti_rocker needs crank = rocker and coupler = ground")
    theta = np.asarray(theta, dtype=float)
    bx, by = a * np.cos(theta), a * np.sin(theta)
    dx, dy = g, 0.0
    cx, cy = dx + c * np.cos(theta), dy + c * np.sin(theta)  # parallelogram C
    ex, ey = dx - bx, dy - by
    nrm2 = ex * ex + ey * ey
    t = ((cx - bx) * ex + (cy - by) * ey) / nrm2
    px, py = bx + t * ex, by + t * ey
    rx, ry = 2 * px - cx, 2 * py - cy
    return np.arctan2(ry - dy, rx - dx)


@dataclass(frozen=True)
class FourBarParams:
    crank: float = 1.0
    coupler: float = 2.0
    rocker: float = 1.0
    ground: float = 2.0
    masses: tuple[float, float, float] = (1.0, 2.0, 1.0)
    inertias: tuple[float, float, float] | None = None  # default: uniform bars m L²/12
    theta0: float = math.pi / 2
    omega0: float = 2.0 * math.pi
    t_final: float = 10.0


def crossed_four_bar_mechanism(p: FourBarParams | None = None) -> BarMechanism:
    """Crossed (anti-parallelogram) four-bar: A = (0, 0), D = (ground, 0); bars crank A→B,
    coupler B→C, rocker D→C."""
    p = FourBarParams() if p is None else p
    lengths = np.array([p.crank, p.coupler, p.rocker])
    masses = np.array(p.masses, dtype=float)
    inertias = (masses * lengths**2 / 12.0 if p.inertias is None
                else np.array(p.inertias, dtype=float))
    ground = np.array([[0.0, 0.0], [p.ground, 0.0]])
    parents = (("ground", 0), ("bar", 0), ("ground", 1))
    closures = ((1, 2),)
    th = p.theta0
    psi = float(crossed_anti_rocker(th, p.crank, p.coupler, p.rocker, p.ground))
    b = np.array([p.crank * math.cos(th), p.crank * math.sin(th)])
    cpt = np.array([p.ground + p.rocker * math.cos(psi), p.rocker * math.sin(psi)])
    beta = math.atan2(cpt[1] - b[1], cpt[0] - b[0])
    angles0 = np.array([th, beta, psi])
    rates0 = _complete_rates(lengths, parents, closures, angles0, 0, p.omega0, ground)

    def branch(angles: np.ndarray) -> np.ndarray:
        return np.abs(_wrap(angles[..., 2] - crossed_anti_rocker(angles[..., 0], p.crank,
                                                                  p.coupler, p.rocker, p.ground)))

    return BarMechanism(
        name="crossed_four_bar", lengths=lengths, masses=masses, inertias=inertias, ground=ground,
        parents=parents, closures=closures, angles0=angles0, rates0=rates0, t_final=p.t_final,
        branch_distance=branch,
        notes="branch distance: |ψ − ψ_anti(θ)| (rad), ψ rocker angle, θ crank angle",
    )


# ---------------------------------------------------------------------------------------------
# common metrics
# ---------------------------------------------------------------------------------------------
def energy(mech: BarMechanism, com: np.ndarray) -> np.ndarray:
    """Total energy of COM states (T, nb, 6)."""
    v2 = com[..., 3] ** 2 + com[..., 4] ** 2
    kin = 0.5 * mech.masses * v2 + 0.5 * mech.inertias * com[..., 5] ** 2
    pot = mech.masses * G * com[..., 1]
    return np.sum(kin + pot, axis=-1)


def joint_errors(mech: BarMechanism, com: np.ndarray) -> np.ndarray:
    """Largest joint separation per sample (T,) from COM states (T, nb, 6)."""
    half = 0.5 * mech.lengths
    c = com[..., 0:2]
    u = _u(com[..., 2])
    start = c - half[:, None] * u
    end = c + half[:, None] * u
    errs = []
    for i, (kind, k) in enumerate(mech.parents):
        target = mech.ground[k] if kind == "ground" else end[..., k, :]
        errs.append(np.linalg.norm(start[..., i, :] - target, axis=-1))
    for i, j in mech.closures:
        errs.append(np.linalg.norm(end[..., i, :] - end[..., j, :], axis=-1))
    return np.max(np.stack(errs, axis=-1), axis=-1)


@dataclass
class RunResult:
    engine: str
    setting: str
    mechanism: str
    dt: float | None
    t: np.ndarray
    com: np.ndarray  # (T, nb, 6)
    wall: list[float] = field(default_factory=list)
    status: str = "ok"
    extra: dict[str, Any] = field(default_factory=dict)


def summarize(mech: BarMechanism, r: RunResult, reference: Callable[[np.ndarray], np.ndarray]
              | None = None) -> dict[str, Any]:
    com = r.com
    finite = bool(np.all(np.isfinite(com)))
    row: dict[str, Any] = {
        "engine": r.engine, "setting": r.setting, "mechanism": mech.name, "dt": r.dt,
        "t_final": float(r.t[-1]) if len(r.t) else 0.0, "status": r.status, "finite": finite,
    }
    if finite and len(r.t):
        e = energy(mech, com)
        br = mech.branch_distance(com[..., 2])
        row["closure_max"] = float(np.max(joint_errors(mech, com)))
        row["energy_drift"] = float(np.max(np.abs(e - e[0])))
        row["branch_distance_max"] = float(np.max(br))
        reached = abs(float(r.t[-1]) - mech.t_final) < 1e-6
        row["on_branch"] = bool(reached and row["branch_distance_max"] < BRANCH_TOL)
        if reference is not None:
            ref = reference(r.t)
            row["error_vs_reference_max"] = float(np.max(np.abs(ref - _output_point(mech, com))))
            row["error_vs_reference_final"] = float(
                np.max(np.abs(ref[-1] - _output_point(mech, com)[-1])))
    else:
        row.update(closure_max=math.inf, energy_drift=math.inf, branch_distance_max=math.inf,
                   on_branch=False)
    if r.wall:
        med = statistics.median(r.wall)
        row["wall_median_s"] = med
        row["wall_runs_s"] = r.wall
        row["wall_per_sim_s"] = med / mech.t_final
        row["wall_min_per_sim_s"] = min(r.wall) / mech.t_final
    row.update(r.extra)
    return row


def _output_point(mech: BarMechanism, com: np.ndarray) -> np.ndarray:
    """End point of bar 0 (B0 for A02, B for the four-bar), (T, 2)."""
    return com[..., 0, 0:2] + 0.5 * mech.lengths[0] * _u(com[..., 0, 2])


def sample_times(t_final: float) -> np.ndarray:
    n = round(t_final / SAMPLE_DT)
    return np.linspace(0.0, t_final, n + 1)


# ---------------------------------------------------------------------------------------------
# reference solutions (1-DOF reductions integrated to tight tolerance)
# ---------------------------------------------------------------------------------------------
def a02_reference(n: int) -> Callable[[np.ndarray], np.ndarray]:
    from scipy.integrate import solve_ivp

    inertia = (n + 1) / 3.0 + n
    cg = (n + 1) / 2.0 + n

    def rhs(t: float, y: np.ndarray) -> list[float]:
        return [y[1], -G * cg * math.cos(y[0]) / inertia]

    def ref(t: np.ndarray) -> np.ndarray:
        sol = solve_ivp(rhs, (0.0, float(t[-1])), [math.pi / 2, -1.0], method="DOP853",
                        rtol=1e-13, atol=1e-13, t_eval=t)
        return _u(sol.y[0])

    return ref


def reduced_reference(mech: BarMechanism) -> Callable[[np.ndarray], np.ndarray]:
    """Exact 1-DOF reduction along the crossed four-bar's anti-parallelogram branch.

    Bar angles are a function of the crank angle θ on the branch (rocker by reflection, coupler
    from B and C); with the reduced inertia m(θ) (kinetic energy at unit crank rate, branch
    tangent by a 4th-order central difference of the analytic geometry, error ~1e-13) and the
    potential V(θ), energy conservation ``½ m(θ) θ̇² + V(θ) = E`` gives
    ``θ̇ = ±sqrt(2 (E − V) / m)``, integrated with DOP853 at rtol = atol = 1e-12. Valid while
    the crank rate keeps its sign (full-turn motion), which the integration checks.
    """
    lengths = mech.lengths

    def angles_of(theta: np.ndarray) -> np.ndarray:
        theta = np.asarray(theta, dtype=float)
        psi = crossed_anti_rocker(theta, *lengths, mech.ground[1, 0])
        b = lengths[0] * _u(theta)
        c = mech.ground[1] + lengths[2] * _u(psi)
        beta = np.arctan2(c[..., 1] - b[..., 1], c[..., 0] - b[..., 0])
        return np.stack([theta, beta, psi], axis=-1)

    def reduced(theta: float) -> tuple[float, float]:
        # m(θ) from the branch tangent dα/dθ (unit crank rate)
        ang = angles_of(np.array(theta))
        h = 1e-3  # 4th-order central difference of the (analytic) branch geometry
        d1 = _wrap(angles_of(np.array(theta + h)) - angles_of(np.array(theta - h)))
        d2 = _wrap(angles_of(np.array(theta + 2 * h)) - angles_of(np.array(theta - 2 * h)))
        rates = (8.0 * d1 - d2) / (12.0 * h)
        com = mech.com_state(ang, rates)
        mth = float(np.sum(mech.masses * (com[:, 3] ** 2 + com[:, 4] ** 2)
                           + mech.inertias * rates**2))
        v = float(np.sum(mech.masses * G * com[:, 1]))
        return mth, v

    # The crank rate never vanishes for a full-turn motion (checked below), so θ̇ keeps its
    # sign and θ(t) is the solution of dθ/dt = s sqrt(2 (E − V(θ)) / m(θ)).
    m0, v0 = reduced(mech.angles0[0])
    e_total = 0.5 * m0 * mech.rates0[0] ** 2 + v0
    sgn = math.copysign(1.0, mech.rates0[0])

    def rhs(t: float, y: np.ndarray) -> list[float]:
        m, v = reduced(float(y[0]))
        k = 2.0 * (e_total - v) / m
        if k <= 0.0:
            raise RuntimeError("crossed four-bar reference: crank rate reaches zero")
        return [sgn * math.sqrt(k)]

    def ref(t: np.ndarray) -> np.ndarray:
        from scipy.integrate import solve_ivp

        sol = solve_ivp(rhs, (0.0, float(t[-1])), [mech.angles0[0]], method="DOP853",
                        rtol=1e-12, atol=1e-12, t_eval=t)
        return lengths[0] * _u(sol.y[0])

    return ref


# ---------------------------------------------------------------------------------------------
# peers
# ---------------------------------------------------------------------------------------------
def run_exudyn(mech: BarMechanism, dt: float, *, spectral_radius: float = 0.9,
               sparse: bool | None = None, repeat: int = 3, warmup: bool = True) -> RunResult:
    import exudyn as exu
    from exudyn.itemInterface import (
        LoadMassProportional,
        MarkerBodyMass,
        MarkerBodyPosition,
        NodeRigidBody2D,
        ObjectGround,
        ObjectJointRevolute2D,
        ObjectRigidBody2D,
        SensorNode,
    )

    com0 = mech.com_state(mech.angles0, mech.rates0)

    def build() -> tuple[Any, Any, list[Any], list[Any], Any]:
        sc = exu.SystemContainer()
        mbs = sc.AddSystem()
        nodes, bodies, starts, ends = [], [], [], []
        for i in range(mech.nb):
            x, y, a, vx, vy, w = com0[i]
            nd = mbs.AddNode(NodeRigidBody2D(referenceCoordinates=[x, y, a],
                                             initialVelocities=[vx, vy, w]))
            ob = mbs.AddObject(ObjectRigidBody2D(nodeNumber=nd, mass=float(mech.masses[i]),
                                                 inertia=float(mech.inertias[i])))
            mm = mbs.AddMarker(MarkerBodyMass(bodyNumber=ob))
            mbs.AddLoad(LoadMassProportional(markerNumber=mm, loadVector=[0.0, -G, 0.0]))
            half = 0.5 * mech.lengths[i]
            starts.append(mbs.AddMarker(MarkerBodyPosition(bodyNumber=ob,
                                                           localPosition=[-half, 0.0, 0.0])))
            ends.append(mbs.AddMarker(MarkerBodyPosition(bodyNumber=ob,
                                                         localPosition=[half, 0.0, 0.0])))
            nodes.append(nd)
            bodies.append(ob)
        gnd = mbs.AddObject(ObjectGround())
        gm = [mbs.AddMarker(MarkerBodyPosition(bodyNumber=gnd, localPosition=[px, py, 0.0]))
              for px, py in mech.ground]
        for i, (kind, k) in enumerate(mech.parents):
            other = gm[k] if kind == "ground" else ends[k]
            mbs.AddObject(ObjectJointRevolute2D(markerNumbers=[other, starts[i]]))
        for i, j in mech.closures:
            mbs.AddObject(ObjectJointRevolute2D(markerNumbers=[ends[i], ends[j]]))
        sens_q = [mbs.AddSensor(SensorNode(nodeNumber=nd, storeInternal=True,
                                           outputVariableType=exu.OutputVariableType.Coordinates))
                  for nd in nodes]
        sens_v = [mbs.AddSensor(SensorNode(nodeNumber=nd, storeInternal=True,
                                           outputVariableType=exu.OutputVariableType.Coordinates_t))
                  for nd in nodes]
        mbs.Assemble()
        s = exu.SimulationSettings()
        s.timeIntegration.numberOfSteps = round(mech.t_final / dt)
        s.timeIntegration.endTime = mech.t_final
        s.timeIntegration.verboseMode = 0
        s.timeIntegration.generalizedAlpha.spectralRadius = spectral_radius
        s.timeIntegration.generalizedAlpha.computeInitialAccelerations = True
        if hasattr(s, "solution"):  # Exudyn ≥ 1.13 names (the old ones are deprecated)
            s.solution.file.write = False
            s.solution.sensors.writePeriod = SAMPLE_DT
            s.show.statistics = False
            s.show.computationTime = False
        else:
            s.solutionSettings.writeSolutionToFile = False
            s.solutionSettings.sensorsWritePeriod = SAMPLE_DT
            s.displayStatistics = False
            s.displayComputationTime = False
        if sparse if sparse is not None else mech.nb > 10:
            s.linearSolverType = exu.LinearSolverType.EigenSparse
        return sc, mbs, sens_q, sens_v, s

    walls = []
    status = "ok"
    mbs = sens_q = sens_v = None
    w0 = 1 if warmup else 0  # untimed warm-up runs
    for rep in range(repeat + w0):
        _sc, mbs, sens_q, sens_v, s = build()
        t0 = CLOCK[0]()
        try:
            ok = mbs.SolveDynamic(s)
        except Exception as exc:  # Exudyn raises on Newton failure
            ok = False
            status = f"failed: {type(exc).__name__}: {str(exc).splitlines()[0][:80]}"
        t1 = CLOCK[0]()
        if ok is False and status == "ok":
            status = "failed: SolveDynamic returned False"
        if rep >= w0:
            walls.append(t1 - t0)
        if status != "ok":
            break
    assert mbs is not None and sens_q is not None and sens_v is not None
    qs = [np.asarray(mbs.GetSensorStoredData(sq)) for sq in sens_q]
    vs = [np.asarray(mbs.GetSensorStoredData(sv)) for sv in sens_v]
    nt = min(len(x) for x in qs + vs)
    t = qs[0][:nt, 0]
    com = np.zeros((nt, mech.nb, 6))
    for i in range(mech.nb):
        com[:, i, 0:3] = com0[i, 0:3] + qs[i][:nt, 1:4]
        com[:, i, 3:6] = vs[i][:nt, 1:4]
    return RunResult("exudyn", f"gen-alpha rho={spectral_radius}", mech.name, dt, t, com,
                     walls if status == "ok" else [], status)


def _tree_to_absolute(mech: BarMechanism, rel: np.ndarray, rel_rate: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray]:
    """Absolute bar angles and rates from hinge values of a tree whose zero is the t = 0 pose.

    Poses follow the tree, so tree joints are exact and the loop-closure error is what
    :func:`joint_errors` measures.
    """
    angles = np.zeros_like(rel)
    rates = np.zeros_like(rel)
    for i, (kind, kk) in enumerate(mech.parents):
        if kind == "bar":
            angles[:, i] = angles[:, kk] + (mech.angles0[i] - mech.angles0[kk]) + rel[:, i]
            rates[:, i] = rates[:, kk] + rel_rate[:, i]
        else:
            angles[:, i] = mech.angles0[i] + rel[:, i]
            rates[:, i] = rel_rate[:, i]
    return angles, rates


def mjcf(mech: BarMechanism, dt: float, setting: str) -> str:
    """MJCF of the mechanism as a hinge tree with <equality connect> loop closures."""
    children: dict[int, list[int]] = {}
    roots = []
    for i, (kind, k) in enumerate(mech.parents):
        if kind == "ground":
            roots.append(i)
        else:
            children.setdefault(k, []).append(i)

    def body(i: int, pos: np.ndarray, rel_angle: float) -> str:
        m, inertia, length = mech.masses[i], mech.inertias[i], mech.lengths[i]
        axial = max(inertia * 1e-3, 1e-9)
        inner = "".join(body(j, np.array([length, 0.0]), mech.angles0[j] - mech.angles0[i])
                        for j in children.get(i, []))
        return (f'<body name="b{i}" pos="{float(pos[0])!r} {float(pos[1])!r} 0" '
                f'euler="0 0 {float(rel_angle)!r}">'
                f'<joint name="j{i}" type="hinge" axis="0 0 1" pos="0 0 0" damping="0"/>'
                f'<inertial pos="{float(0.5 * length)!r} 0 0" mass="{float(m)!r}" '
                f'diaginertia="{float(axial)!r} {float(inertia)!r} {float(inertia)!r}"/>'
                f"{inner}</body>")

    tree = "".join(body(i, mech.ground[mech.parents[i][1]], mech.angles0[i]) for i in roots)
    if setting == "default":
        eq_attr = ""
    elif setting == "stiff":
        eq_attr = f' solref="{float(2 * dt)!r} 1" solimp="0.99 0.999 0.001"'
    else:
        raise ValueError(setting)
    eqs = "".join(
        f'<connect body1="b{i}" body2="b{j}" anchor="{float(mech.lengths[i])!r} 0 0"{eq_attr}/>'
        for i, j in mech.closures)
    return (
        '<mujoco model="bench"><compiler angle="radian" autolimits="true"/>'
        f'<option timestep="{float(dt)!r}" gravity="0 {float(-G)!r} 0" integrator="Euler">'
        '<flag contact="disable"/></option>'
        f"<worldbody>{tree}</worldbody><equality>{eqs}</equality></mujoco>"
    )


def run_mujoco(mech: BarMechanism, dt: float, setting: str, *, repeat: int = 3,
               warmup: bool = True) -> RunResult:
    import mujoco

    model = mujoco.MjModel.from_xml_string(mjcf(mech, dt, setting))
    data = mujoco.MjData(model)
    nsteps = round(mech.t_final / dt)
    every = max(1, round(SAMPLE_DT / dt))
    # initial joint rates = relative angular velocities along the tree
    qvel0 = np.array([mech.rates0[i] - (mech.rates0[k] if kind == "bar" else 0.0)
                      for i, (kind, k) in enumerate(mech.parents)])
    body_ids = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, f"b{i}")
                for i in range(mech.nb)]
    jnt_adr = [model.jnt_qposadr[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, f"j{i}")]
               for i in range(mech.nb)]
    dof_adr = [model.jnt_dofadr[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, f"j{i}")]
               for i in range(mech.nb)]
    qvel_init = np.zeros(model.nv)
    qvel_init[dof_adr] = qvel0
    nsamp = nsteps // every + 1
    qpos_hist = np.zeros((nsamp, model.nq))
    qvel_hist = np.zeros((nsamp, model.nv))
    walls = []
    status = "ok"
    w0 = 1 if warmup else 0  # untimed warm-up runs
    for rep in range(repeat + w0):
        mujoco.mj_resetData(model, data)
        data.qvel[:] = qvel_init
        mujoco.mj_forward(model, data)
        qpos_hist[0] = data.qpos
        qvel_hist[0] = data.qvel
        t0 = CLOCK[0]()
        step = mujoco.mj_step
        k = 0
        for n in range(1, nsteps + 1):
            step(model, data)
            if n % every == 0:
                k += 1
                qpos_hist[k] = data.qpos
                qvel_hist[k] = data.qvel
        t1 = CLOCK[0]()
        if rep >= w0:
            walls.append(t1 - t0)
        if not np.all(np.isfinite(data.qpos)):
            status = "diverged"
            break
    t = np.arange(nsamp) * every * dt
    # absolute angles and rates along the tree from the joint values (planar hinges about z)
    rel = qpos_hist[:, jnt_adr]
    rel_rate = qvel_hist[:, dof_adr]
    angles, rates = _tree_to_absolute(mech, rel, rel_rate)
    del body_ids
    com = mech.com_state(angles, rates)
    return RunResult("mujoco", setting, mech.name, dt, t, com, walls if status == "ok" else [],
                     status)




def run_pinocchio(mech: BarMechanism, dt: float, *, kp: float = 100.0, mu: float = 1e-8,
                  repeat: int = 3, warmup: bool = True) -> RunResult:
    import pinocchio as pin
    from pin_loops import point_closures  # beside this script

    model = pin.Model()
    model.gravity.linear = np.array([0.0, -G, 0.0])
    # Pinocchio's algorithms (CRBA, constraintDynamics) assume the joints are numbered depth
    # first (every subtree is a contiguous index range): add the bars in DFS order.
    children: dict[int, list[int]] = {}
    for i, (kind, k) in enumerate(mech.parents):
        if kind == "bar":
            children.setdefault(k, []).append(i)
    order: list[int] = []

    def visit(i: int) -> None:
        order.append(i)
        for c in children.get(i, []):
            visit(c)

    for i, (kind, _) in enumerate(mech.parents):
        if kind == "ground":
            visit(i)
    jid = [0] * mech.nb
    for i in order:
        kind, k = mech.parents[i]
        if kind == "ground":
            px, py = mech.ground[k]
            placement = pin.SE3(pin.utils.rotate("z", mech.angles0[i]), np.array([px, py, 0.0]))
            parent = 0
        else:
            placement = pin.SE3(pin.utils.rotate("z", mech.angles0[i] - mech.angles0[k]),
                                np.array([mech.lengths[k], 0.0, 0.0]))
            parent = jid[k]
        j = model.addJoint(parent, pin.JointModelRZ(), placement, f"j{i}")
        inertia = np.diag([max(mech.inertias[i] * 1e-3, 1e-9), mech.inertias[i],
                           mech.inertias[i]])
        model.appendBodyToJoint(
            j, pin.Inertia(mech.masses[i], np.array([0.5 * mech.lengths[i], 0.0, 0.0]), inertia),
            pin.SE3.Identity())
        jid[i] = j
    qidx = np.array([model.joints[jid[i]].idx_q for i in range(mech.nb)])
    data = model.createData()
    pairs = [(jid[i], [mech.lengths[i], 0.0, 0.0], jid[j], [mech.lengths[j], 0.0, 0.0]) for i, j in mech.closures]
    cms, cdatas, prox = point_closures(model, data, pairs, kp, mu)
    q0 = np.zeros(model.nq)
    v0 = np.zeros(model.nv)
    v0[qidx] = [mech.rates0[i] - (mech.rates0[k] if kind == "bar" else 0.0)
                for i, (kind, k) in enumerate(mech.parents)]
    tau = np.zeros(model.nv)
    nsteps = round(mech.t_final / dt)
    every = max(1, round(SAMPLE_DT / dt))
    nsamp = nsteps // every + 1
    qh = np.zeros((nsamp, model.nq))
    vh = np.zeros((nsamp, model.nv))
    walls = []
    status = "ok"
    w0 = 1 if warmup else 0  # untimed warm-up runs
    for rep in range(repeat + w0):
        q = q0.copy()
        v = v0.copy()
        qh[0] = q
        vh[0] = v
        k = 0
        t0 = CLOCK[0]()
        for n in range(1, nsteps + 1):
            a = pin.constraintDynamics(model, data, q, v, tau, cms, cdatas, prox)
            v = v + dt * a
            q = q + dt * v  # RZ joints: configuration space is R^n
            if n % every == 0:
                k += 1
                qh[k] = q
                vh[k] = v
        t1 = CLOCK[0]()
        if rep >= w0:
            walls.append(t1 - t0)
        if not np.all(np.isfinite(q)):
            status = "diverged"
            break
    t = np.arange(nsamp) * every * dt
    angles, rates = _tree_to_absolute(mech, qh[:, qidx], vh[:, qidx])
    com = mech.com_state(angles, rates)
    return RunResult("pinocchio", f"prox-constraintDynamics Kp={kp:g}", mech.name, dt, t, com,
                     walls if status == "ok" else [], status)


# ---------------------------------------------------------------------------------------------
# machine info
# ---------------------------------------------------------------------------------------------
def machine_info() -> dict[str, Any]:
    cpu = ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    versions = {"python": platform.python_version(), "numpy": np.__version__}
    for mod in ("scipy", "exudyn", "mujoco", "pinocchio"):
        try:
            versions[mod] = __import__(mod).__version__
        except Exception:
            versions[mod] = "not installed"
    try:
        import nonmin

        versions["nonmin"] = nonmin.__version__
    except Exception:
        versions["nonmin"] = "not importable"
    return {"platform": platform.platform(), "cpu": cpu, "cpu_count": os.cpu_count(),
            "OPENBLAS_NUM_THREADS": os.environ.get("OPENBLAS_NUM_THREADS", "(unset)"),
            "versions": versions}


# ---------------------------------------------------------------------------------------------
# nonmin
# ---------------------------------------------------------------------------------------------
def nonmin_mechanism(bar: BarMechanism) -> Any:
    """The library mechanism that is the same physical system as ``bar``."""
    from nonmin import library

    if bar.name == "crossed_four_bar":
        return library.get("crossed_four_bar")
    if bar.name.startswith("A02_N"):
        return library.get("A02_n_four_bar", N=int(bar.name[5:]))
    raise KeyError(bar.name)


def _nonmin_to_com(bar: BarMechanism, model: Any, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
    """Per-bar COM state (T, nb, 6) from nonmin planar-body coordinates (x, y, θ per body)."""
    names = list(model.coordinate_names)
    out = np.zeros((q.shape[0], bar.nb, 6))
    for i, body in enumerate(_nonmin_body_names(bar)):
        for k, suffix in enumerate(("x", "y", "theta")):
            col = names.index(f"{body}.{suffix}")
            out[:, i, k] = q[:, col]
            out[:, i, 3 + k] = qd[:, col]
    return out


def _nonmin_body_names(bar: BarMechanism) -> list[str]:
    if bar.name == "crossed_four_bar":
        return ["crank", "coupler", "rocker"]
    n = (bar.nb - 1) // 2
    return [f"crank{i}" for i in range(n + 1)] + [f"coupler{i}" for i in range(1, n + 1)]


def run_nonmin(bar: BarMechanism, method: str, *, dt: float | None = None,
               rtol: float = 1e-8, atol: float = 1e-10, stabilization: str = "projection",
               engine: str = "auto", samples: str = "grid", passages: bool = True,
               h_max: float | None = None, repeat: int = 3, warmup: bool = True) -> RunResult:
    """``samples="grid"``: samples every ``SAMPLE_DT`` (dense output, projected); ``"steps"``: the
    step ends only (``t_eval=None``, as the peers record theirs), errors at those instants.
    ``passages=False``: the integrator without the singularity-aware step placement;
    ``h_max`` (adaptive methods): the largest step, also the first (with ``rtol = 1`` the error
    control accepts every attempt: fixed steps of ``h_max``)."""
    from nonmin.sim import METHODS, simulate

    mech = nonmin_mechanism(bar)
    # the same physical system: nonmin's initial state must equal the neutral description's
    com0 = _nonmin_to_com(bar, mech.model, mech.state.q[None], mech.state.qd[None])[0]
    mismatch = float(np.max(np.abs(com0 - bar.com_state(bar.angles0, bar.rates0))))
    if mismatch > 1e-12:
        raise RuntimeError(f"{bar.name}: nonmin's initial state differs from the peers' by "
                           f"{mismatch:.2e}")
    t_eval = sample_times(bar.t_final) if samples == "grid" else None
    kw: dict[str, Any] = {"method": method, "stabilization": stabilization, "t_eval": t_eval,
                          "engine": engine}
    if dt is not None:
        kw["dt"] = dt
    adaptive = METHODS[method].adaptive
    if adaptive:
        kw.update(rtol=rtol, atol=atol)
    if not passages or h_max is not None:  # an Integrator value instead of the name
        cls = METHODS[method]
        opts: dict[str, Any] = {"passages": passages}
        if adaptive:
            opts.update(rtol=kw.pop("rtol"), atol=kw.pop("atol"))
            if h_max is not None:
                opts["h_max"] = h_max
                kw["h0"] = h_max
        else:
            opts["dt"] = kw.pop("dt")
        kw["method"] = cls(**opts)
    walls = []
    status = "ok"
    traj = None
    note = ""
    if warmup:  # setup: a short run first (imports, caches, first-use costs), so that a long
        # run timed once (below) is not timed with the compilation
        simulate(mech, (0.0, min(bar.t_final, 20.0 * (dt or 1e-3))), throw=False, progress=False,
                 **{**kw, "t_eval": None})  # fmt: skip
    w0 = 1 if warmup else 0  # untimed warm-up runs
    for rep in range(repeat + w0):
        t0 = CLOCK[0]()
        traj = simulate(mech, (0.0, bar.t_final), throw=False, progress=False, **kw)
        t1 = CLOCK[0]()
        if rep >= w0:
            walls.append(t1 - t0)
        if not traj.success:
            status = f"failed: {traj.message[:80]}"
            break
        if rep == 0 and warmup and t1 - t0 > LONG_RUN_S:
            # a long run: warm-up effects are negligible, time the first run only
            walls.append(t1 - t0)
            note = f"single timed run (> {LONG_RUN_S:g} s)"
            break
    assert traj is not None
    com = _nonmin_to_com(bar, mech.model, np.asarray(traj.q), np.asarray(traj.qd))
    used = str(traj.metadata.get("engine", "python"))
    setting = (f"{method} {stabilization}" + (" step ends" if samples == "steps" else "")
               + (f" rtol={rtol:g}" if adaptive else "")
               + (f" h_max={h_max:g}" if h_max is not None else "")
               + (" passages off" if not passages else "") + f" [{used}]")
    return RunResult("nonmin", setting, bar.name, dt, np.asarray(traj.t), com,
                     walls if status == "ok" else [], status,
                     extra={"n_steps": traj.n_steps, "n_rhs": traj.n_rhs, "nonmin_engine": used,
                            **({"timing_note": note} if note else {})})


# ---------------------------------------------------------------------------------------------
# driver
# ---------------------------------------------------------------------------------------------
PeerSpec = tuple[str, dict[str, Any]]


#: The clock of every timed run: wall time, or the process's CPU time (``--cpu``).
CLOCK: list[Callable[[], float]] = [time.perf_counter]

#: ``--wp``: every peer over its range (issue 18, target 4), coarse steps included.
WP_DTS = (1e-2, 5e-3, 2e-3, 1e-3, 1e-4)

#: ``--wp``: the peers' steps coarser than 1e-2 s — those that still stay on the branch belong
#: to their range (Pinocchio's loop and Exudyn's generalized-α do on A02); those that leave it
#: are drawn as crosses.
WP_COARSE_DTS = (5e-2, 2e-2)


def wp_configs(mech: BarMechanism) -> list[PeerSpec]:
    """The work–precision settings: Exudyn's generalized-α at spectral radius 0.6 / 0.9 / 1.0,
    MuJoCo default and stiff, Pinocchio's loop with Kp = 100 and 0, each at dt 1e-2 … 1e-4
    (1e-2 … 1e-3 on A02 N = 40) and at the coarser :data:`WP_COARSE_DTS`, and nonmin's RK4 steps
    and DOPRI5/DOP853 tolerances."""
    dts = [*WP_COARSE_DTS, *(dt for dt in WP_DTS if mech.nb <= 10 or dt >= 1e-3)]
    cfg: list[PeerSpec] = []
    for rho in (0.6, 0.9, 1.0):
        cfg += [("exudyn", {"dt": dt, "spectral_radius": rho}) for dt in dts]
    for setting in ("default", "stiff"):
        cfg += [("mujoco", {"dt": dt, "setting": setting}) for dt in dts]
    for kp in (100.0, 0.0):
        cfg += [("pinocchio", {"dt": dt, "kp": kp}) for dt in dts]
    return cfg + NONMIN_CONFIGS.get(mech.name, []) + WP_STEP_ENDS.get(mech.name, [])


#: nonmin's coarse end recorded at its step ends (``samples="steps"``): no dense output and no
#: projection per sample, as the peers record theirs (``--wp``).
WP_STEP_ENDS: dict[str, list[PeerSpec]] = {
    name: [*(("nonmin", {"method": "rk4", "dt": dt, "samples": "steps"}) for dt in dts),
           *(("nonmin", {"method": m, "rtol": r, "atol": r * 1e-2, "samples": "steps"})
             for m in ("dopri5", "dop853") for r in rtols)]
    for name, dts, rtols in (
        ("crossed_four_bar", (1e-2, 2e-2, 3e-2, 4e-2, 5e-2), (1e-2, 1e-3, 1e-4, 1e-6)),
        ("A02_N2", (1e-2, 2e-2, 4e-2, 5e-2), (1e-2, 1e-3, 2e-4, 1e-4, 1e-6)),
        # N = 40: RK4 between 2e-2 and 5e-2 and DOP853 below 1e-6 (its loose tolerances cost more
        # on N = 40: the stages of long steps lie far off the manifold)
        ("A02_N40", (2e-2, 3e-2, 4e-2, 5e-2, 1e-1), (1e-2, 1e-3, 1e-4, 1e-6, 1e-7, 1e-8)))
}  # fmt: skip

#: RK8 (DOP853's 8th-order stages at a fixed step, no error estimate; ``nonmin.sim.RK8``) at its
#: step ends over its range (issue 18, target 4), with the singular-passage placement and, at
#: A02 N = 2's coarse end, without it (``passages=False``: there the cheapest setting at
#: Pinocchio's semi-implicit Euler dt 5e-2 accuracy); and the coarse end of RK4 and DOP853
#: without the placement on A02 N = 2.
WP_RK8: dict[str, list[PeerSpec]] = {
    name: [*(("nonmin", {"method": "rk8", "dt": dt, "samples": "steps"}) for dt in dts),
           *(("nonmin", {"method": "rk8", "dt": dt, "samples": "steps", "passages": False}) for dt in off)]
    for name, dts, off in (
        ("crossed_four_bar", (2e-3, 5e-3, 1e-2, 2e-2), ()),
        ("A02_N2", (5e-2, 1e-1, 1.5e-1, 2e-1), (2e-1, 2.5e-1, 2.7e-1)),
        ("A02_N40", (2e-2, 5e-2, 1e-1), ()))
}  # fmt: skip
WP_RK8["A02_N2"] += [
    *(("nonmin", {"method": "rk4", "dt": dt, "samples": "steps", "passages": False}) for dt in (6e-2, 7e-2, 8e-2)),
    *(("nonmin", {"method": "dop853", "rtol": r, "atol": r * 1e-2, "samples": "steps", "passages": False})
      for r in (3e-4, 1e-4)),
]  # fmt: skip
for _name, _cfg in WP_RK8.items():
    WP_STEP_ENDS[_name] = WP_STEP_ENDS[_name] + _cfg


def default_configs(mech: BarMechanism, quick: bool) -> list[PeerSpec]:
    """Which engine settings run on a mechanism."""
    big = mech.nb > 10
    dts = [1e-3] if (quick or big) else [1e-3, 1e-4]
    cfg: list[PeerSpec] = []
    for dt in dts:
        cfg.append(("exudyn", {"dt": dt}))
    for dt in ([*COARSE_DTS, 2e-3, *dts] if not quick else dts):
        cfg.append(("mujoco", {"dt": dt, "setting": "default"}))
        cfg.append(("mujoco", {"dt": dt, "setting": "stiff"}))
    for dt in dts:
        cfg.append(("pinocchio", {"dt": dt}))
    cfg += NONMIN_CONFIGS.get(mech.name, [])
    return cfg


#: MuJoCo's coarse steps (its range, as the SciML work–precision benchmarks cover each
#: method's): it stays on the branch up to ~1e-2 s with the stiff setting.
COARSE_DTS = (1e-2, 5e-3)

#: The adaptive methods over their tolerances (issue 18's work–precision diagrams).
ADAPTIVE = [("nonmin", {"method": m, "rtol": r, "atol": r * 1e-2})
            for m in ("dopri5", "dop853") for r in (1e-6, 1e-8, 1e-10)]  # fmt: skip

#: nonmin settings per mechanism: RK4 + mass-metric projection over a range of steps (the
#: compiled engine runs these), and DOPRI5 (general driver) for comparison. The range spans the
#: peers' accuracies, so every peer can be matched by a nonmin run of equal or better accuracy.
NONMIN_CONFIGS: dict[str, list[PeerSpec]] = {
    "crossed_four_bar": [
        *(("nonmin", {"method": "rk4", "dt": dt})
          for dt in (2.5e-4, 5e-4, 1e-3, 2e-3, 5e-3, 1e-2, 2e-2, 2.5e-2, 3e-2, 4e-2)),
        *ADAPTIVE,
    ],
    "A02_N2": [
        *(("nonmin", {"method": "rk4", "dt": dt}) for dt in (1e-3, 2e-3, 5e-3, 1e-2, 2e-2, 4e-2, 5e-2)),
        *ADAPTIVE,
    ],
    # N = 40 (243 coordinates, 242 rows): the compiled engine with the sparse certified LQ
    "A02_N40": [
        *(("nonmin", {"method": "rk4", "dt": dt}) for dt in (1e-2, 2e-2, 5e-2, 1e-1)),
        *ADAPTIVE,
    ],
}

RUNNERS: dict[str, Callable[..., RunResult]] = {
    "exudyn": run_exudyn,
    "mujoco": run_mujoco,
    "pinocchio": run_pinocchio,
    "nonmin": run_nonmin,
}


def reference_for(mech: BarMechanism) -> Callable[[np.ndarray], np.ndarray]:
    if mech.name.startswith("A02_N"):
        return a02_reference(int(mech.name[5:]))
    return reduced_reference(mech)


def run_mechanism(mech: BarMechanism, configs: Sequence[PeerSpec], repeat: int,
                  log: Callable[[str], None] = print) -> list[dict[str, Any]]:
    ref_fn = reference_for(mech)
    t_ref = sample_times(mech.t_final)
    ref_vals = ref_fn(t_ref)

    def cached_ref(t: np.ndarray) -> np.ndarray:
        if len(t) == len(t_ref) and np.allclose(t, t_ref, atol=1e-9):
            return ref_vals
        return ref_fn(t)

    # Pass 1: every setting once (warm-up + one timed run; its result is the row's). Passes
    # 2 … repeat: one more timed run of every setting in turn, so that the load of the shared
    # machine, which drifts over minutes, weighs on every engine alike.
    results: list[Any] = []
    for engine, kw in configs:
        try:
            results.append(RUNNERS[engine](mech, repeat=1, **kw))
        except Exception as exc:  # an engine that cannot run is a result, not a crash
            results.append(exc)
    for _ in range(repeat - 1):
        for (engine, kw), res in zip(configs, results, strict=True):
            if isinstance(res, Exception) or not res.wall or res.extra.get("timing_note"):
                continue
            # short runs (tens of ms) scatter by ±50 % on the shared machine: time several
            # back to back in each pass (about SHORT_RUN_S of timed runs, at most 10)
            k = int(min(10, max(1, round(SHORT_RUN_S / max(res.wall[0], 1e-9)))))
            try:
                more = RUNNERS[engine](mech, repeat=k, warmup=False, **kw)
            except Exception:  # the first pass decides the row's status
                continue
            res.wall.extend(more.wall)
    rows = []
    for (engine, kw), res in zip(configs, results, strict=True):
        if isinstance(res, Exception):
            row = {"engine": engine, "setting": str(kw), "mechanism": mech.name,
                   "dt": kw.get("dt"), "status": f"error: {type(res).__name__}: {res}"[:200],
                   "on_branch": False}
        else:
            row = summarize(mech, res, cached_ref)
        rows.append(row)
        log(_row_line(row))
    return rows


def _row_line(r: dict[str, Any]) -> str:
    def f(x: Any) -> str:
        return "-" if x is None else (f"{x:.2e}" if isinstance(x, float) else str(x))

    return (f"{r['mechanism']:>16} {r['engine']:>9} {r['setting'][:34]:<34} dt={f(r.get('dt')):>8} "
            f"branch={'yes' if r.get('on_branch') else 'NO ':<3} "
            f"closure={f(r.get('closure_max')):>9} dE={f(r.get('energy_drift')):>9} "
            f"err={f(r.get('error_vs_reference_max')):>9} "
            f"wall/s={f(r.get('wall_per_sim_s')):>9} {r.get('status', '')}")


#: Closures below this (m) are round-off of the closure computation itself (bar ends from the
#: sampled poses, lengths ~1 m): they count as equal in the matched-accuracy comparison.
ROUNDOFF_CLOSURE = 1e-13


def compare(rows: list[dict[str, Any]], closure_target: float = 1e-10,
            energy_target: float = 1e-6) -> dict[str, Any]:
    """The speed target, two ways.

    * *Matched accuracy* (the issue's target): for every peer run that stays on the branch, the
      fastest nonmin run that stays on the branch with closure, energy drift and error against
      the exact reduction all ≤ the peer's; the ratio of wall times per simulated second. The
      target is met when the ratio is ≤ 1 for the fastest peer on the branch.
    * *nonmin's own accuracy* (closure ≤ ``closure_target``, dE ≤ ``energy_target``): the
      fastest such nonmin run against the fastest peer on the branch.
    """
    ok = [r for r in rows if r.get("on_branch") and "wall_per_sim_s" in r]
    peers = [r for r in ok if r["engine"] != "nonmin"]
    mine_all = [r for r in ok if r["engine"] == "nonmin"]
    mine = [r for r in mine_all if r["closure_max"] <= closure_target
            and r["energy_drift"] <= energy_target]
    out: dict[str, Any] = {"closure_target": closure_target, "energy_target": energy_target}
    best_peer = min(peers, key=lambda r: r["wall_per_sim_s"]) if peers else None
    best_mine = min(mine, key=lambda r: r["wall_per_sim_s"]) if mine else None
    out["fastest_peer_on_branch"] = _tag(best_peer)
    out["fastest_nonmin_meeting_targets"] = _tag(best_mine)
    if best_peer and best_mine:
        out["ratio_nonmin_over_fastest_peer"] = (best_mine["wall_per_sim_s"]
                                                 / best_peer["wall_per_sim_s"])
    matched = []
    for pr in sorted(peers, key=lambda r: r["wall_per_sim_s"]):
        cand = [r for r in mine_all
                if r["closure_max"] <= max(pr["closure_max"], ROUNDOFF_CLOSURE)
                and r["energy_drift"] <= pr["energy_drift"]
                and r["error_vs_reference_max"] <= pr["error_vs_reference_max"]]
        best = min(cand, key=lambda r: r["wall_per_sim_s"]) if cand else None
        matched.append({"peer": _tag(pr), "nonmin": _tag(best),
                        "ratio": None if best is None
                        else best["wall_per_sim_s"] / pr["wall_per_sim_s"],
                        "ratio_fastest_runs": None if best is None
                        else _ratio(_fastest(best), _fastest(pr))})
    out["matched_accuracy"] = matched
    if matched:
        out["target_met"] = matched[0]["ratio"] is not None and matched[0]["ratio"] <= 1.0
    return out


def _fastest(r: dict[str, Any]) -> float | None:
    """Wall time per simulated second of the fastest timed run (least disturbed by other jobs
    on a shared machine)."""
    x = r.get("wall_min_per_sim_s")
    return None if x is None else float(x)


def _ratio(a: float | None, b: float | None) -> float | None:
    return None if a is None or b is None or b == 0 else a / b


def _tag(r: dict[str, Any] | None) -> dict[str, Any] | None:
    if r is None:
        return None
    keys = ("engine", "setting", "dt", "closure_max", "energy_drift", "error_vs_reference_max",
            "wall_per_sim_s", "wall_min_per_sim_s")
    return {k: r.get(k) for k in keys}


def write_markdown(path: Path, results: dict[str, Any]) -> None:
    info = results["machine"]
    lines = ["# Simulation benchmark: nonmin vs Exudyn, MuJoCo, Pinocchio", "",
             f"Generated by `{results['command']}` on {results['date_utc']}.", "",
             "Machine: " + ", ".join(f"{k}={v}" for k, v in info.items() if k != "versions"),
             "", "Versions: " + ", ".join(f"{k} {v}" for k, v in info["versions"].items()), "",
             f"Load average (1, 5, 15 min) before: {results['load_before']}, after: "
             f"{results['load_after']}. Wall times: median of the timed runs after one warm-up "
             "run, interleaved across the settings of a mechanism (runs shorter than "
             f"{SHORT_RUN_S:g} s repeated back to back in the later passes; `wall_runs_s` in "
             "the JSON: "
             + ("per row, merged from the separate runs listed above"
                if results.get("combined") else f"at least {results['repeat']} per row")
             + f"; nonmin runs longer than {LONG_RUN_S:g} s are timed once, without warm-up); "
             "setup (model building, compilation) excluded. "
             f"Branch tolerance {BRANCH_TOL} rad; samples every {SAMPLE_DT} s.", "",
             "Definitions: closure = largest separation of two bar ends that a joint keeps "
             "together [m]; dE = max |E(t) − E(0)| [J]; err = max |B(t) − B_ref(t)| of the "
             "first bar's end against the exact 1-DOF reduction [m]; wall/s = wall-clock "
             "seconds per simulated second.", ""]
    for mech_name, block in results["mechanisms"].items():
        lines += [f"## {mech_name}", "", "| engine | setting | dt [s] | on branch | closure [m] "
                  "| dE [J] | err [m] | wall/s | status |", "|---|---|---|---|---|---|---|---|---|"]
        for r in block["rows"]:
            def f(x: Any) -> str:
                if x is None:
                    return "-"
                return f"{x:.2e}" if isinstance(x, float) else str(x)

            lines.append(
                f"| {r['engine']} | {r['setting']} | {f(r.get('dt'))} | "
                f"{'yes' if r.get('on_branch') else '**no**'} | {f(r.get('closure_max'))} | "
                f"{f(r.get('energy_drift'))} | {f(r.get('error_vs_reference_max'))} | "
                f"{f(r.get('wall_per_sim_s'))} | {r.get('status', '')} |")
        c = block["comparison"]

        def g(x: Any) -> str:
            return "-" if x is None else f"{x:.2e}"

        def h(x: Any) -> str:
            return "-" if x is None else f"{x:.2f}"

        lines += ["", "Speed at matched accuracy: for each peer run on the branch (fastest "
                  "first), the fastest nonmin run with closure, dE and err all ≤ the peer's "
                  f"(closures below {ROUNDOFF_CLOSURE:g} m count as equal: round-off).", "",
                  "The ratio is that of the median wall times (the target); `fastest runs` is the "
                  "ratio of the two settings' fastest timed runs, the least disturbed by other "
                  "jobs on a shared machine.", "",
                  "| peer | setting | dt | wall/s | nonmin setting | dt | closure | dE | err | "
                  "wall/s | nonmin / peer | fastest runs |",
                  "|---|---|---|---|---|---|---|---|---|---|---|---|"]
        for mrow in c.get("matched_accuracy", []):
            pr, me = mrow["peer"], mrow["nonmin"]
            if me is None:
                lines.append(f"| {pr['engine']} | {pr['setting']} | {g(pr['dt'])} | "
                             f"{g(pr['wall_per_sim_s'])} | none at this accuracy | | | | | | | |")
                continue
            lines.append(
                f"| {pr['engine']} | {pr['setting']} | {g(pr['dt'])} | {g(pr['wall_per_sim_s'])} | "
                f"{me['setting']} | {g(me['dt'])} | {g(me['closure_max'])} | "
                f"{g(me['energy_drift'])} | {g(me['error_vs_reference_max'])} | "
                f"{g(me['wall_per_sim_s'])} | {mrow['ratio']:.2f} | {h(mrow.get('ratio_fastest_runs'))} |")
        met = c.get("target_met")
        lines += ["", f"Target (ratio ≤ 1 against the fastest peer on the branch): "
                  f"{'met' if met else 'not met' if met is not None else 'no peer on the branch'}.",
                  "", f"At nonmin's own accuracy (closure ≤ {c['closure_target']:g} m, dE ≤ "
                  f"{c['energy_target']:g} J): fastest nonmin run "
                  f"{c['fastest_nonmin_meeting_targets']}; ratio to the fastest peer on the "
                  f"branch: {c.get('ratio_nonmin_over_fastest_peer')}.", ""]
    lines += results.get("discussion", [])
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="short horizons, one repeat")
    ap.add_argument("--repeat", type=int, default=3, help="timed runs per setting (median)")
    ap.add_argument("--mechanisms", default="crossed_four_bar,A02_N2,A02_N40")
    ap.add_argument("--engines", default="exudyn,mujoco,pinocchio,nonmin")
    ap.add_argument("--only", default=None, metavar="REGEX",
                    help="run only the settings whose 'engine {options}' matches (e.g. \"dop853|'dt': 0.01\")")
    ap.add_argument("--json", default=str(HERE / "results" / "sim_bench.json"))
    ap.add_argument("--markdown", default=str(HERE / "SIM.md"))
    ap.add_argument("--combine", nargs="+", default=None, metavar="JSON",
                    help="merge result files of earlier runs (e.g. one per mechanism run in "
                    "parallel) into --json and --markdown, running nothing")
    ap.add_argument("--cpu", action="store_true", help="time with the process's CPU time instead of wall time")
    ap.add_argument("--wp", action="store_true",
                    help="work–precision: every peer over its range (wp_configs), nonmin's steps and tolerances")
    args = ap.parse_args(argv)
    if args.cpu:
        CLOCK[0] = time.process_time
    if args.combine:
        parts = [json.loads(Path(f).read_text(encoding="utf-8")) for f in args.combine]
        merged = dict(parts[0])
        mechs_m: dict[str, Any] = {}
        for part in parts:  # later files replace earlier rows of the same engine
            for name, block in part["mechanisms"].items():
                old_block = mechs_m.get(name)
                if old_block is None:
                    mechs_m[name] = dict(block)
                    continue
                engines_new = {r["engine"] for r in block["rows"]}
                rows = [r for r in old_block["rows"] if r["engine"] not in engines_new]
                old_block["rows"] = rows + block["rows"]
        for block in mechs_m.values():
            for r in block["rows"]:  # result files written before the field existed
                if "wall_min_per_sim_s" not in r and r.get("wall_runs_s"):
                    r["wall_min_per_sim_s"] = min(r["wall_runs_s"]) / block["t_final"]
            block["comparison"] = compare(block["rows"])
        merged["mechanisms"] = mechs_m
        merged["command"] = " ; ".join([*(p["command"] for p in parts),
                                        "python " + " ".join([Path(sys.argv[0]).name,
                                                              *(argv or sys.argv[1:])])])
        merged["combined"] = True
        merged["date_utc"] = ", ".join(p["date_utc"] for p in parts)
        merged["load_before"] = [p["load_before"] for p in parts]
        merged["load_after"] = [p["load_after"] for p in parts]
        merged["discussion"] = _discussion()
        Path(args.json).write_text(json.dumps(merged, indent=1, default=float), encoding="utf-8")
        write_markdown(Path(args.markdown), merged)
        print(f"wrote {args.json} and {args.markdown}")
        return 0
    repeat = 1 if args.quick else args.repeat
    engines = set(args.engines.split(","))
    mechs: list[BarMechanism] = []
    for name in args.mechanisms.split(","):
        if name == "crossed_four_bar":
            mechs.append(crossed_four_bar_mechanism(library_four_bar_params()))
        elif name.startswith("A02_N"):
            mechs.append(a02_mechanism(int(name[5:])))
        else:
            raise SystemExit(f"unknown mechanism {name!r}")
    if args.quick:
        mechs = [BarMechanism(**{**m.__dict__, "t_final": min(m.t_final, 2.0)}) for m in mechs]
    load_before = os.getloadavg()
    results: dict[str, Any] = {
        "command": "python " + " ".join([Path(sys.argv[0]).name, *(argv or sys.argv[1:])]),
        "date_utc": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
        "machine": machine_info(), "repeat": repeat, "quick": args.quick,
        "clock": "process CPU time" if args.cpu else "wall time",
        "mechanisms": {}, "discussion": _discussion(),
    }
    for mech in mechs:
        cfgs = [c for c in (wp_configs(mech) if args.wp else default_configs(mech, args.quick)) if c[0] in engines
                and (args.only is None or re.search(args.only, f"{c[0]} {c[1]}"))]
        rows = run_mechanism(mech, cfgs, repeat)
        results["mechanisms"][mech.name] = {"t_final": mech.t_final, "notes": mech.notes,
                                            "rows": rows, "comparison": compare(rows)}
        print(json.dumps(results["mechanisms"][mech.name]["comparison"], indent=1))
    results["load_before"] = [round(x, 2) for x in load_before]
    results["load_after"] = [round(x, 2) for x in os.getloadavg()]
    Path(args.json).parent.mkdir(parents=True, exist_ok=True)
    Path(args.json).write_text(json.dumps(results, indent=1, default=float), encoding="utf-8")
    write_markdown(Path(args.markdown), results)
    print(f"wrote {args.json} and {args.markdown}")
    return 0


def _discussion() -> list[str]:
    path = HERE / "results" / "sim_bench_discussion.md"
    return path.read_text(encoding="utf-8").splitlines() if path.exists() else []


def library_four_bar_params() -> FourBarParams:
    """Parameters of nonmin's library crossed four-bar (the peers model the same system)."""
    return FourBarParams()


if __name__ == "__main__":
    sys.exit(main())
