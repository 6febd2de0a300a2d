"""Planar mechanisms with singular, switching or closing constraints (planar builder models)."""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from ..errors import InputError, ModelError
from ..model import assemble
from ..model.planar import PlanarBuilder, PlanarModel
from ..model.planar._model import FloatArray
from ._registry import Mechanism, register

__all__ = [
    "arm2r_wall",
    "crossed_four_bar",
    "crossed_four_bar_reference",
    "dual_arm_grasp",
    "five_bar",
    "slider_crank",
]


def _bar(length: float, mass: float) -> float:
    """Moment of inertia of a uniform slender bar about its centre."""
    return mass * length * length / 12.0


def _circle_intersection(p0: FloatArray, r0: float, p1: FloatArray, r1: float, side: float) -> FloatArray:
    """Intersection of circles (p0, r0), (p1, r1) left (side=+1) or right (−1) of p0 → p1."""
    d = p1 - p0
    L = float(np.hypot(*d))
    if L > r0 + r1 or L < abs(r0 - r1) or L == 0.0:
        raise ModelError(f"unreachable configuration: distance {L:.4g} with link lengths {r0}, {r1}")
    a = (r0 * r0 - r1 * r1 + L * L) / (2 * L)
    h = math.sqrt(max(r0 * r0 - a * a, 0.0))
    e = d / L
    return p0 + a * e + side * h * np.array([-e[1], e[0]])


def _link_coords(p: FloatArray, r: FloatArray) -> list[float]:
    """(x, y, θ) of a bar from point p to point r (COM at the middle)."""
    m = 0.5 * (p + r)
    return [float(m[0]), float(m[1]), math.atan2(r[1] - p[1], r[0] - p[0])]


# ----------------------------------------------------------------------------- crossed four-bar
_CFB_MASS = (1.0, 2.0, 1.0)  # crank, coupler, rocker: uniform bars of 1 kg/m
_CFB_LEN = (1.0, 2.0, 1.0)


def _cfb_branch(theta: ArrayLike) -> dict[str, FloatArray]:
    """Closed-form anti-parallelogram branch of the crossed four-bar as a function of the crank angle.

    Crank A B (A = 0), rocker D C (D = (2, 0)). With ``z = e^{iθ}`` the rocker direction on the
    anti-parallelogram branch is ``e^{iψ} = (z − 2)/(1 − 2z)`` (the reflection of the
    parallelogram solution ``ψ = θ`` across the line B D), so ``ψ' = −3/(5 − 4 cos θ)`` and
    ``ψ'' = 12 sin θ/(5 − 4 cos θ)²``. The angles are continuous functions of θ (no wrapping):
    ``ψ = −θ + arg(c z)`` and the coupler angle stays in [−π/3, π/3]. Returns positions, first and second θ-derivatives of the
    three COMs and angles (arrays with a leading dimension like θ).
    """
    th = np.asarray(theta, dtype=float)
    z = np.exp(1j * th)
    c = (z - 2.0) / (1.0 - 2.0 * z)
    # continuous in θ: ψ + θ = arg(c z) stays in [−π/3, π/3] (ψ winds once backwards per turn)
    psi = -th + np.angle(c * z)
    den = 5.0 - 4.0 * np.cos(th)
    dpsi = -3.0 / den
    ddpsi = 12.0 * np.sin(th) / den**2
    B = np.stack([np.cos(th), np.sin(th)], axis=-1)
    dB = np.stack([-np.sin(th), np.cos(th)], axis=-1)
    ddB = -B
    u = np.stack([np.cos(psi), np.sin(psi)], axis=-1)
    up = np.stack([-np.sin(psi), np.cos(psi)], axis=-1)
    D = np.array([2.0, 0.0])
    C = D + u
    dC = dpsi[..., None] * up
    ddC = ddpsi[..., None] * up - (dpsi**2)[..., None] * u
    w = C - B
    dw = dC - dB
    ddw = ddC - ddB
    chi = np.arctan2(w[..., 1], w[..., 0])  # stays in [−π/3, π/3]: continuous

    def cross(a: FloatArray, b: FloatArray) -> FloatArray:
        return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]

    dchi = cross(w, dw) / 4.0  # |w| = 2
    ddchi = cross(w, ddw) / 4.0
    return {
        "theta": th,
        "psi": psi,
        "chi": chi,
        "dpsi": dpsi,
        "ddpsi": ddpsi,
        "dchi": dchi,
        "ddchi": ddchi,
        "g": np.stack([0.5 * B, 0.5 * (B + C), D + 0.5 * u]),  # (3, ..., 2) COMs
        "dg": np.stack([0.5 * dB, 0.5 * (dB + dC), 0.5 * dC]),
        "ddg": np.stack([0.5 * ddB, 0.5 * (ddB + ddC), 0.5 * ddC]),
        "ang": np.stack([th, chi, psi]),
        "dang": np.stack([np.ones_like(th), dchi, dpsi]),
        "ddang": np.stack([np.zeros_like(th), ddchi, ddpsi]),
    }


def _cfb_coordinates(theta: ArrayLike, omega: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Full (q, qd) of the model (bodies crank, coupler, rocker) on the anti-parallelogram branch."""
    br = _cfb_branch(theta)
    om = np.asarray(omega, dtype=float)
    qs, qds = [], []
    for k in range(3):
        qs.append(np.concatenate([br["g"][k], br["ang"][k][..., None]], axis=-1))
        qds.append(
            np.concatenate([br["dg"][k], br["dang"][k][..., None]], axis=-1) * om[..., None]
        )
    return np.concatenate(qs, axis=-1), np.concatenate(qds, axis=-1)


def _cfb_reduced(
    g: float,
) -> tuple[Callable[[float], tuple[float, float, float]], Callable[[float, float], float]]:
    masses = np.array(_CFB_MASS)
    inert = np.array([_bar(L, m) for L, m in zip(_CFB_LEN, _CFB_MASS)])

    def mass_and_slope(th: float) -> tuple[float, float, float]:
        br = _cfb_branch(th)
        dg, ddg, da, dda = br["dg"], br["ddg"], br["dang"], br["ddang"]
        m = float(np.sum(masses * np.sum(dg * dg, axis=-1)) + np.sum(inert * da * da))
        dm = 2.0 * float(np.sum(masses * np.sum(dg * ddg, axis=-1)) + np.sum(inert * da * dda))
        dV = g * float(np.sum(masses * dg[:, 1]))
        return m, dm, dV

    def energy(th: float, om: float) -> float:
        br = _cfb_branch(th)
        m, _, _ = mass_and_slope(th)
        return 0.5 * m * om * om + g * float(np.sum(masses * br["g"][:, 1]))

    return mass_and_slope, energy


def crossed_four_bar_reference(
    t: ArrayLike,
    *,
    theta0: float = math.pi / 2,
    omega0: float = 2.0 * math.pi,
    g: float = 9.81,
    rtol: float = 1e-12,
    atol: float = 1e-12,
) -> dict[str, FloatArray]:
    """Exact reference of :func:`crossed_four_bar`: the 1-DOF reduction along its branch.

    With the crank angle θ as the coordinate and the closed-form anti-parallelogram branch
    (:func:`_cfb_branch`), ``T = ½ m(θ) θ̇²``, ``V(θ) = g Σ m_k y_k(θ)`` and Lagrange's
    equation ``m θ̈ + ½ m' θ̇² + V' = 0`` is smooth through the change points (m ≥ I_crank > 0).
    Integrated with ``solve_ivp`` (DOP853) at ``rtol = atol = 1e-12``.

    Parameters
    ----------
    t : array_like, shape (k,)
        Increasing output times ≥ 0.

    Returns
    -------
    dict
        ``theta``, ``omega``, ``energy`` shape (k,); ``q``, ``qd`` shape (k, 9).
    """
    ts = np.atleast_1d(np.asarray(t, dtype=float))
    mass_and_slope, energy = _cfb_reduced(g)

    def rhs(_t: float, y: FloatArray) -> list[float]:
        m, dm, dV = mass_and_slope(float(y[0]))
        return [float(y[1]), -(0.5 * dm * y[1] ** 2 + dV) / m]

    from scipy.integrate import solve_ivp

    sol = solve_ivp(rhs, (0.0, max(float(ts.max()), 1e-9)), [theta0, omega0], method="DOP853",
                    t_eval=ts, rtol=rtol, atol=atol)
    if not sol.success:  # pragma: no cover
        raise RuntimeError(f"crossed_four_bar_reference: solve_ivp failed: {sol.message}")
    th, om = sol.y
    q, qd = _cfb_coordinates(th, om)
    return {
        "theta": th,
        "omega": om,
        "energy": np.array([energy(a, b) for a, b in zip(th, om)]),
        "q": q,
        "qd": qd,
    }


def _cfb_outputs(model: PlanarModel, t: float, q: FloatArray, qd: FloatArray) -> dict[str, FloatArray]:
    th, om = float(q[2]), float(qd[2])
    psi, ompsi = float(q[8]), float(qd[8])
    anti = float(np.angle((np.exp(1j * th) - 2.0) / (1.0 - 2.0 * np.exp(1j * th))))
    resid = (psi - anti + math.pi) % (2 * math.pi) - math.pi
    den = om * om + ompsi * ompsi
    return {
        "crank_angle": np.array(th),
        "crank_rate": np.array(om),
        "rocker_angle": np.array(psi),
        "branch_indicator": np.array(-2.0 * om * ompsi / den if den > 0 else 0.0),
        "anti_branch_residual": np.array(resid),
    }


@functools.lru_cache(maxsize=16)
def _cfb_max_potential(g: float) -> float:
    """The crossed four-bar's largest potential energy over a crank turn (721 angles along the
    branch): once per g (it took ~0.2 s of CPU, 100x the rest of :func:`crossed_four_bar`)."""
    _, energy = _cfb_reduced(g)
    return max(energy(float(a), 0.0) for a in np.linspace(0, 2 * math.pi, 721))


@register("crossed_four_bar")
def crossed_four_bar(
    *, theta0: float = math.pi / 2, omega0: float = 2.0 * math.pi, g: float = 9.81, t_final: float = 10.0
) -> Mechanism:
    """Crossed four-bar at a Grashof change point, started on the anti-parallelogram branch.

    Source: the change-point four-bar of ``shared/benchmarks/README.md`` (crank 1 m, coupler
    2 m, rocker 1 m, ground 2 m; cf. the IFToMM A02 singular four-bar and the change-point
    linkages of Müller, Mech. Mach. Theory 2016). Choices made here: uniform bars of 1 kg/m
    (crank 1 kg, coupler 2 kg, rocker 1 kg, I = mL²/12), gravity 9.81 along −y, ground pivots
    A = (0, 0) and D = (2, 0). Initial state: crank angle ``theta0 = π/2`` (crank vertical)
    and crank rate ``omega0 = 2π rad/s`` on the anti-parallelogram branch (rocker turning the
    other way, ``ψ' = −3/(5 − 4 cos θ)``); with this rate the crank makes full turns, passing
    the collinear change points θ = 0 and π (mod 2π) about twice per turn.

    Bodies ``crank``, ``coupler``, ``rocker``; joints ``A`` (ground–crank), ``B``
    (crank–coupler), ``C`` (coupler–rocker), ``D`` (rocker–ground). Outputs: ``crank_angle``,
    ``crank_rate``, ``rocker_angle``, ``branch_indicator`` = ``−2 θ̇ψ̇/(θ̇² + ψ̇²)`` (in
    [0.6, 1] on the anti-parallelogram branch, −1 on the parallelogram branch) and
    ``anti_branch_residual`` (ψ minus its anti-parallelogram value, wrapped; 0 on the branch).
    Exact reference: :func:`crossed_four_bar_reference`.
    """
    b = PlanarBuilder("crossed_four_bar", gravity=(0.0, -float(g)),
                      description="crossed (change-point) four-bar, anti-parallelogram branch")
    b.body("crank", mass=1.0, inertia=_bar(1.0, 1.0), points={"B": (0.5, 0.0)})
    b.body("coupler", mass=2.0, inertia=_bar(2.0, 2.0))
    b.body("rocker", mass=1.0, inertia=_bar(1.0, 1.0), points={"C": (0.5, 0.0)})
    b.ground_point("A", (0.0, 0.0))
    b.ground_point("D", (2.0, 0.0))
    b.revolute("A", "A", ("crank", (-0.5, 0.0)))
    b.revolute("B", "B", ("coupler", (-1.0, 0.0)))
    b.revolute("C", ("coupler", (1.0, 0.0)), "C")
    b.revolute("D", ("rocker", (-0.5, 0.0)), "D")
    b.output("B", "C")
    model = b.build(outputs_fn=_cfb_outputs)
    q0, qd0 = _cfb_coordinates(float(theta0), float(omega0))
    _, energy = _cfb_reduced(float(g))
    e0 = energy(float(theta0), float(omega0))
    vmax = _cfb_max_potential(float(g))
    if e0 <= vmax:
        raise InputError(
            f"crossed_four_bar: omega0 = {omega0} is too small for full crank turns "
            f"(energy {e0:.4g} J ≤ max potential {vmax:.4g} J)"
        )
    return Mechanism(
        model=model,
        state=model.state(q0, qd0),
        t_final=float(t_final),
        description="crossed four-bar (Grashof change point) on the anti-parallelogram branch, full crank turns",
        reference="nonmin benchmarks README (change-point four-bar); exact 1-DOF reduction along the branch",
    )


# ----------------------------------------------------------------------------- 2R arm and wall
@dataclass(frozen=True)
class _ArmOutputs:
    """Outputs of :func:`arm2r_wall` (a value, so models stay picklable)."""

    wall_x: float

    def __call__(self, model: PlanarModel, t: float, q: FloatArray, qd: FloatArray) -> dict[str, FloatArray]:
        tip = model.point_position("tip", q)
        return {
            "gap": np.array(self.wall_x - tip[0]),
            "joint_angles": np.array([q[2], q[5] - q[2]]),
            "joint_rates": np.array([qd[2], qd[5] - qd[2]]),
        }


@register("arm2r_wall")
def arm2r_wall(
    *,
    l1: float = 1.0,
    l2: float = 1.0,
    m1: float = 1.0,
    m2: float = 1.0,
    wall_x: float = 1.5,
    g: float = 9.81,
    joint_angles: tuple[float, float] = (-math.pi / 3, 2 * math.pi / 3),
    t_final: float = 5.0,
) -> Mechanism:
    """2R arm in absolute coordinates with joint torques and a switchable tip contact on a wall.

    Source: textbook planar 2R manipulator (Siciliano et al., *Robotics: Modelling, Planning and
    Control*, §7.3) with a frictionless vertical wall (nonmin issue #3). Links ``link1``,
    ``link2`` are uniform bars; joints ``shoulder`` (ground at the origin – link1) and
    ``elbow`` (link1 – link2); actuators ``shoulder`` and ``elbow`` (joint torques). The
    unilateral constraint ``wall`` is ``gap = wall_x − x_tip ≥ 0`` (inactive by default).
    Initial state: at rest with absolute link angles ``(q1, q1 + q2)`` from
    ``joint_angles = (q1, q2)`` (default: tip at (1, 0)). Outputs: ``tip.position``,
    ``tip.velocity``, ``gap``, ``joint_angles``.
    """
    b = PlanarBuilder("arm2r_wall", gravity=(0.0, -float(g)), description="2R arm with wall contact")
    b.body("link1", mass=m1, inertia=_bar(l1, m1))
    b.body("link2", mass=m2, inertia=_bar(l2, m2), points={"tip": (l2 / 2, 0.0)})
    b.revolute("shoulder", ("ground", (0.0, 0.0)), ("link1", (-l1 / 2, 0.0)))
    b.revolute("elbow", ("link1", (l1 / 2, 0.0)), ("link2", (-l2 / 2, 0.0)))
    b.point_on_line("wall", ("ground", (float(wall_x), 0.0)), "tip", axis=(0.0, 1.0), unilateral=True)
    b.actuator("shoulder", "shoulder")
    b.actuator("elbow", "elbow")
    b.output("tip")

    model = b.build(outputs_fn=_ArmOutputs(float(wall_x)))
    a1, a2 = float(joint_angles[0]), float(joint_angles[0] + joint_angles[1])
    p0 = np.zeros(2)
    p1 = p0 + l1 * np.array([math.cos(a1), math.sin(a1)])
    p2 = p1 + l2 * np.array([math.cos(a2), math.sin(a2)])
    q0 = np.array(_link_coords(p0, p1) + _link_coords(p1, p2))
    state = model.state(q0)
    if p2[0] > wall_x:
        raise ModelError(f"arm2r_wall: initial tip x = {p2[0]:.4g} is behind the wall at x = {wall_x}")
    return Mechanism(
        model=model,
        state=state,
        t_final=float(t_final),
        description="planar 2R arm (absolute coordinates) with joint torques and a unilateral wall contact",
        reference="Siciliano, Sciavicco, Villani, Oriolo, Robotics (Springer 2009), 2R arm; nonmin issue #3",
    )


# ----------------------------------------------------------------------------- five-bar
def _five_bar_outputs(model: PlanarModel, t: float, q: FloatArray, qd: FloatArray) -> dict[str, FloatArray]:
    i1, i2 = model.body_slice("prox1").stop - 1, model.body_slice("prox2").stop - 1
    return {"actuated_angles": np.array([q[i1], q[i2]]), "actuated_rates": np.array([qd[i1], qd[i2]])}


@register("five_bar")
def five_bar(
    *,
    base: float = 1.0,
    l1: float = 1.0,
    l2: float = 1.0,
    mass: float = 1.0,
    end_effector: tuple[float, float] = (0.0, 1.2),
    g: float = 0.0,
    t_final: float = 2.0,
) -> Mechanism:
    """Five-bar parallel robot (2 DOF) with two actuated base joints.

    Source: the planar five-bar (RR-RRR) parallel robot, e.g. DexTAR (Campos, Bourbonnais,
    Bonev, Bigras, ICRA 2010); Merlet, *Parallel Robots* (2006). Base pivots
    ``A1 = (−base/2, 0)``, ``A2 = (base/2, 0)``; proximal links ``prox1``, ``prox2`` (length l1)
    and distal links ``dist1``, ``dist2`` (length l2), uniform bars of ``mass``; joints
    ``base1``, ``elbow1``, ``base2``, ``elbow2``, ``ee`` (the two distal tips); actuators
    ``base1``, ``base2`` (torques). Horizontal plane by default (``g = 0``). Initial state: at
    rest with the end effector at ``end_effector`` and the elbows outward. With the default
    geometry the end effector is at a *parallel (type-2) singularity* at (0, √3/2 ≈ 0.866)
    (distal links collinear) and at a serial singularity at (0, √(4 − 0.25) ≈ 1.936) (arms
    stretched): pass ``end_effector=(0, 0.87)`` to start close to the former.
    Outputs: ``E.position``, ``E.velocity``, ``actuated_angles``.
    """
    b = PlanarBuilder("five_bar", gravity=(0.0, -float(g)), description="five-bar parallel robot")
    for i in (1, 2):
        b.body(f"prox{i}", mass=mass, inertia=_bar(l1, mass))
        b.body(f"dist{i}", mass=mass, inertia=_bar(l2, mass))
    b.point("E", "dist1", (l2 / 2, 0.0))
    A = {1: np.array([-base / 2, 0.0]), 2: np.array([base / 2, 0.0])}
    for i in (1, 2):
        b.revolute(f"base{i}", ("ground", tuple(A[i])), (f"prox{i}", (-l1 / 2, 0.0)))
        b.revolute(f"elbow{i}", (f"prox{i}", (l1 / 2, 0.0)), (f"dist{i}", (-l2 / 2, 0.0)))
    b.revolute("ee", "E", ("dist2", (l2 / 2, 0.0)))
    b.actuator("base1", "base1")
    b.actuator("base2", "base2")
    b.output("E")

    model = b.build(outputs_fn=_five_bar_outputs)
    E = np.asarray(end_effector, dtype=float)
    B1 = _circle_intersection(A[1], l1, E, l2, +1.0)
    B2 = _circle_intersection(A[2], l1, E, l2, -1.0)
    q0 = np.array(
        _link_coords(A[1], B1) + _link_coords(B1, E) + _link_coords(A[2], B2) + _link_coords(B2, E)
    )
    return Mechanism(
        model=model,
        state=model.state(q0),
        t_final=float(t_final),
        description="five-bar parallel robot, two actuated base joints",
        reference="Merlet, Parallel Robots (Springer 2006); Campos et al., ICRA 2010 (DexTAR)",
    )


# ----------------------------------------------------------------------------- slider-crank
def _slider_outputs(model: PlanarModel, t: float, q: FloatArray, qd: FloatArray) -> dict[str, FloatArray]:
    return {
        "crank_angle": np.array(q[2]),
        "slider_position": np.array(q[6]),
        "slider_velocity": np.array(qd[6]),
    }


@register("slider_crank")
def slider_crank(
    *,
    crank: float = 0.5,
    rod: float = 1.5,
    crank_mass: float = 1.0,
    rod_mass: float = 1.0,
    slider_mass: float = 1.0,
    theta0: float = math.pi / 4,
    omega0: float = 2.0 * math.pi,
    g: float = 0.0,
    t_final: float = 3.0,
) -> Mechanism:
    """Slider-crank mechanism turning through its dead centres.

    Source: the classical slider-crank (e.g. Haug, *Computer-Aided Kinematics and Dynamics of
    Mechanical Systems*, 1989, §6; Nikravesh, *Computer-Aided Analysis of Mechanical Systems*,
    1988). Crank ``crank`` pinned to the ground at the origin (joint ``O``), rod ``rod``
    (joints ``crank_pin``, ``wrist_pin``), slider block ``slider`` on the x axis (prismatic
    joint ``slide``). Horizontal by default (``g = 0``); free motion started at crank angle
    ``theta0`` with crank rate ``omega0`` passes the dead centres θ = 0, π where the slider
    velocity vanishes and a slider force cannot move the crank. ``rod == crank`` gives the
    isosceles slider-crank whose dead centre at θ = ±π/2 is a change point (A loses rank).
    Actuators: ``motor`` (crank torque), ``piston`` (force along the slide). A rheonomic driver
    ``drive`` (``θ_crank = theta0 + omega0·t``) is declared but inactive by default.
    Outputs: ``crank_angle``, ``slider_position``, ``slider_velocity``.
    """
    if rod < crank:
        raise ModelError(f"slider_crank: rod ({rod}) must be at least as long as the crank ({crank})")
    b = PlanarBuilder("slider_crank", gravity=(0.0, -float(g)), description="slider-crank")
    b.body("crank", mass=crank_mass, inertia=_bar(crank, crank_mass))
    b.body("rod", mass=rod_mass, inertia=_bar(rod, rod_mass))
    b.body("slider", mass=slider_mass, inertia=slider_mass * 0.1**2 / 6.0, points={"S": (0.0, 0.0)})
    b.revolute("O", ("ground", (0.0, 0.0)), ("crank", (-crank / 2, 0.0)))
    b.revolute("crank_pin", ("crank", (crank / 2, 0.0)), ("rod", (-rod / 2, 0.0)))
    b.revolute("wrist_pin", ("rod", (rod / 2, 0.0)), "S")
    b.prismatic("slide", ("ground", (0.0, 0.0)), "S", axis=(1.0, 0.0))
    b.drive_angle("drive", "crank", start=float(theta0), speed=float(omega0), active=False)
    b.actuator("motor", "O")
    b.actuator("piston", "slide")
    b.output("S")

    model = b.build(outputs_fn=_slider_outputs)
    P = crank * np.array([math.cos(theta0), math.sin(theta0)])
    xs = P[0] + math.sqrt(max(rod * rod - P[1] * P[1], 0.0))
    S = np.array([xs, 0.0])
    q0 = np.array(_link_coords(np.zeros(2), P) + _link_coords(P, S) + [xs, 0.0, 0.0])
    qd_guess = np.zeros(9)
    qd_guess[2] = omega0
    state = assemble(model, q0, qd_guess, fixed=["crank.theta"])
    return Mechanism(
        model=model,
        state=state,
        t_final=float(t_final),
        description="slider-crank through dead centre (free motion with an initial crank rate)",
        reference="Haug, Computer-Aided Kinematics and Dynamics of Mechanical Systems (1989)",
    )


# ----------------------------------------------------------------------------- dual-arm grasp
def _dual_outputs(model: PlanarModel, t: float, q: FloatArray, qd: FloatArray) -> dict[str, FloatArray]:
    return {"object_pose": q[12:15].copy(), "object_velocity": qd[12:15].copy()}


@register("dual_arm_grasp")
def dual_arm_grasp(
    *,
    link: float = 0.8,
    link_mass: float = 1.0,
    object_length: float = 0.6,
    object_mass: float = 0.5,
    base_distance: float = 2.0,
    object_height: float = 0.8,
    grasp: str = "pin",
    grasped: bool = False,
    g: float = 9.81,
    t_final: float = 3.0,
) -> Mechanism:
    """Two planar 2R arms and a free bar; switchable grasp constraints close one loop.

    Source: cooperative dual-arm manipulation of a common object (Uchiyama & Dauchez, 1988;
    Caccavale & Uchiyama, *Springer Handbook of Robotics*, ch. 39), planar version of nonmin
    issue #3. Arms ``L`` and ``R`` with bases at ``(∓base_distance/2, 0)``, links
    ``L1, L2, R1, R2`` (uniform bars), joints ``L_shoulder, L_elbow, R_shoulder, R_elbow``
    (all actuated, actuator names = joint names), object ``object`` (a bar of
    ``object_length``) initially horizontal at height ``object_height``. Grasp constraints
    ``grasp_L``, ``grasp_R`` (``grasp="pin"``: revolute; ``"weld"``: weld) attach each end
    effector to an end of the object; inactive by default (two open chains + a free object,
    7 DOF), active with ``grasped=True`` (one closed loop: 3 DOF with pins, 1 with welds).
    Initial state: at rest, arms (elbows outward) touching the object ends, so switching the
    grasp on is consistent. Outputs: ``object_pose``, ``L_tip.position``, ``R_tip.position``.
    """
    if grasp not in ("pin", "weld"):
        raise InputError(f"dual_arm_grasp: grasp must be 'pin' or 'weld', got {grasp!r}")
    b = PlanarBuilder("dual_arm_grasp", gravity=(0.0, -float(g)), description="dual-arm grasp")
    Ib = _bar(link, link_mass)
    for s in ("L", "R"):
        b.body(f"{s}1", mass=link_mass, inertia=Ib)
        b.body(f"{s}2", mass=link_mass, inertia=Ib, points={f"{s}_tip": (link / 2, 0.0)})
    b.body("object", mass=object_mass, inertia=_bar(object_length, object_mass),
           points={"O_left": (-object_length / 2, 0.0), "O_right": (object_length / 2, 0.0)})
    bases = {"L": np.array([-base_distance / 2, 0.0]), "R": np.array([base_distance / 2, 0.0])}
    for s in ("L", "R"):
        b.revolute(f"{s}_shoulder", ("ground", tuple(bases[s])), (f"{s}1", (-link / 2, 0.0)))
        b.revolute(f"{s}_elbow", (f"{s}1", (link / 2, 0.0)), (f"{s}2", (-link / 2, 0.0)))
    targets = {
        "L": np.array([-object_length / 2, object_height]),
        "R": np.array([object_length / 2, object_height]),
    }
    elbows = {
        "L": _circle_intersection(bases["L"], link, targets["L"], link, +1.0),
        "R": _circle_intersection(bases["R"], link, targets["R"], link, -1.0),
    }
    q0: list[float] = []
    for s in ("L", "R"):
        q0 += _link_coords(bases[s], elbows[s]) + _link_coords(elbows[s], targets[s])
    q0 += [0.0, float(object_height), 0.0]
    for s, op in (("L", "O_left"), ("R", "O_right")):
        if grasp == "pin":
            b.revolute(f"grasp_{s}", f"{s}_tip", op, active=grasped)
        else:
            th2 = q0[5] if s == "L" else q0[11]
            b.weld(f"grasp_{s}", f"{s}_tip", op, angle=-th2, active=grasped)
    for s in ("L", "R"):
        b.actuator(f"{s}_shoulder", f"{s}_shoulder")
        b.actuator(f"{s}_elbow", f"{s}_elbow")
    b.output("L_tip", "R_tip")

    model = b.build(outputs_fn=_dual_outputs)
    return Mechanism(
        model=model,
        state=model.state(np.array(q0)),
        t_final=float(t_final),
        description="two planar 2R arms and a free object with switchable grasp constraints",
        reference="Caccavale & Uchiyama, Cooperative manipulators, Springer Handbook of Robotics (2008)",
    )
