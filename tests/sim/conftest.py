"""Hand-written test mechanisms for the simulator (FunctionModel; independent of the builders)."""

from __future__ import annotations

import numpy as np
import pytest

from nonmin.model import FunctionConstraint, FunctionModel

G = 9.81


def make_pendulum(length: float = 1.0) -> FunctionModel:
    """Point mass 1 kg on a massless rod in Cartesian coordinates (x, y) (benchmark A01)."""
    rod = FunctionConstraint.holonomic(
        "rod",
        phi=lambda q: [0.5 * (q @ q - length**2)],
        jacobian=lambda q: q[None, :],
        adot_qd=lambda q, qd: [qd @ qd],
    )
    return FunctionModel(
        name="pendulum",
        coordinate_names=("x", "y"),
        mass=lambda q: np.eye(2),
        coriolis=lambda q, qd: np.zeros((2, 2)),
        conservative=lambda q: [0.0, -G],
        potential=lambda q: G * q[1],
        constraints=(rod,),
    )



def forced_oscillator(t: float, y: np.ndarray) -> np.ndarray:
    """x'' = −x + cos(2t) written first order (a time-dependent forcing exercises every node of a
    Runge–Kutta tableau; the DOP853 and RK8 order tests)."""
    return np.array([y[1], -y[0] + np.cos(2.0 * t)])


def forced_oscillator_exact(t: float) -> np.ndarray:
    """The solution of :func:`forced_oscillator` from (x, ẋ) = (2/3, 1) at t = 0."""
    x = np.cos(t) + np.sin(t) - np.cos(2.0 * t) / 3.0
    v = -np.sin(t) + np.cos(t) + 2.0 * np.sin(2.0 * t) / 3.0
    return np.array([x, v])


# Crossed four-bar: crank 1 m at O = (0, 0), coupler 2 m, rocker 1 m at D = (2, 0), ground 2 m.
# Coordinates: absolute link angles (θ1, θ2, θ3); uniform rods of 1 kg per metre.
L1, L2, L3, DX = 1.0, 2.0, 1.0, 2.0
M1, M2, M3 = 1.0, 2.0, 1.0
C12 = M2 * L1 * L2 / 2.0


def _fb_mass(q: np.ndarray) -> np.ndarray:
    c = C12 * np.cos(q[0] - q[1])
    return np.array(
        [
            [M1 * L1**2 / 3 + M2 * L1**2, c, 0.0],
            [c, M2 * L2**2 / 3, 0.0],
            [0.0, 0.0, M3 * L3**2 / 3],
        ]
    )


def _fb_coriolis(q: np.ndarray, qd: np.ndarray) -> np.ndarray:
    s = C12 * np.sin(q[0] - q[1])
    return np.array([[0.0, s * qd[1], 0.0], [-s * qd[0], 0.0, 0.0], [0.0, 0.0, 0.0]])


def _fb_potential(q: np.ndarray) -> float:
    return G * (
        M1 * L1 / 2 * np.sin(q[0]) + M2 * (L1 * np.sin(q[0]) + L2 / 2 * np.sin(q[1]))
        + M3 * L3 / 2 * np.sin(q[2])
    )


def _fb_conservative(q: np.ndarray) -> np.ndarray:
    return -G * np.array(
        [
            (M1 * L1 / 2 + M2 * L1) * np.cos(q[0]),
            M2 * L2 / 2 * np.cos(q[1]),
            M3 * L3 / 2 * np.cos(q[2]),
        ]
    )


def _fb_phi(q: np.ndarray) -> np.ndarray:
    return np.array(
        [
            L1 * np.cos(q[0]) + L2 * np.cos(q[1]) - DX - L3 * np.cos(q[2]),
            L1 * np.sin(q[0]) + L2 * np.sin(q[1]) - L3 * np.sin(q[2]),
        ]
    )


def _fb_jac(q: np.ndarray) -> np.ndarray:
    return np.array(
        [
            [-L1 * np.sin(q[0]), -L2 * np.sin(q[1]), L3 * np.sin(q[2])],
            [L1 * np.cos(q[0]), L2 * np.cos(q[1]), -L3 * np.cos(q[2])],
        ]
    )


def _fb_adot(q: np.ndarray, qd: np.ndarray) -> np.ndarray:
    return np.array(
        [
            -L1 * np.cos(q[0]) * qd[0] ** 2 - L2 * np.cos(q[1]) * qd[1] ** 2 + L3 * np.cos(q[2]) * qd[2] ** 2,
            -L1 * np.sin(q[0]) * qd[0] ** 2 - L2 * np.sin(q[1]) * qd[1] ** 2 + L3 * np.sin(q[2]) * qd[2] ** 2,
        ]
    )


def make_crossed_four_bar() -> FunctionModel:
    loop = FunctionConstraint.holonomic("loop", _fb_phi, _fb_jac, _fb_adot, dim=2)
    return FunctionModel(
        name="crossed_four_bar_fn",
        coordinate_names=("th1", "th2", "th3"),
        mass=_fb_mass,
        coriolis=_fb_coriolis,
        conservative=_fb_conservative,
        potential=_fb_potential,
        constraints=(loop,),
    )


def crossed_branch_point(th1: float) -> np.ndarray:
    """Joint C on the anti-parallelogram branch: reflection of the parallelogram C across BD."""
    B = L1 * np.array([np.cos(th1), np.sin(th1)])
    D = np.array([DX, 0.0])
    Cp = B + np.array([L2, 0.0])  # parallelogram branch
    u = (D - B) / np.linalg.norm(D - B)
    v = Cp - B
    return B + 2 * (v @ u) * u - v


def crossed_initial_state(th1: float = np.pi / 2, rate: float = 5.0) -> tuple[np.ndarray, np.ndarray]:
    """A configuration on the crossed branch with crank rate ``rate`` (admissible velocity)."""
    B = L1 * np.array([np.cos(th1), np.sin(th1)])
    C = crossed_branch_point(th1)
    th2 = np.arctan2(*(C - B)[::-1])
    th3 = np.arctan2(*(C - np.array([DX, 0.0]))[::-1])
    q = np.array([th1, th2, th3])
    A = _fb_jac(q)
    _, _, Vh = np.linalg.svd(A)
    t = Vh[-1]
    return q, rate * t / t[0]


def joint_C(q: np.ndarray) -> np.ndarray:
    """Position of joint C computed from the rocker (D + L3 e(θ3))."""
    q = np.atleast_2d(q)
    return np.column_stack([DX + L3 * np.cos(q[:, 2]), L3 * np.sin(q[:, 2])])


@pytest.fixture
def pendulum() -> FunctionModel:
    return make_pendulum()


@pytest.fixture
def crossed_four_bar() -> FunctionModel:
    return make_crossed_four_bar()


def make_ball() -> FunctionModel:
    """Point mass 1 kg in the plane (x, y) above a floor ``gap = y ≥ 0`` (unilateral)."""
    floor = FunctionConstraint.unilateral(
        "floor",
        gap=lambda q: [q[1]],
        jacobian=lambda q: np.array([[0.0, 1.0]]),
        adot_qd=lambda q, qd: [0.0],
    )
    return FunctionModel(
        name="ball",
        coordinate_names=("x", "y"),
        mass=lambda q: np.eye(2),
        coriolis=lambda q, qd: np.zeros((2, 2)),
        conservative=lambda q: [0.0, -G],
        potential=lambda q: G * q[1],
        constraints=(floor,),
    )


# 2R arm (uniform rods, 1 m, 1 kg), base at the origin, gravity −y, motor torque on joint 1,
# a frictionless wall x = XW that the tip may not cross: gap = XW − x_tip ≥ 0.
XW = 1.5
_LC, _I = 0.5, 1.0 / 12.0


def _arm_mass(q: np.ndarray) -> np.ndarray:
    c2 = np.cos(q[1])
    m11 = 2 * _I + _LC**2 + (1.0 + _LC**2 + 2 * _LC * c2)
    m12 = _I + _LC**2 + _LC * c2
    return np.array([[m11, m12], [m12, _I + _LC**2]])


def _arm_coriolis(q: np.ndarray, qd: np.ndarray) -> np.ndarray:
    hh = _LC * np.sin(q[1])
    return np.array([[-hh * qd[1], -hh * (qd[0] + qd[1])], [hh * qd[0], 0.0]])


def _arm_potential(q: np.ndarray) -> float:
    return G * (_LC * np.sin(q[0]) + np.sin(q[0]) + _LC * np.sin(q[0] + q[1]))


def _arm_conservative(q: np.ndarray) -> np.ndarray:
    c12 = np.cos(q[0] + q[1])
    return -G * np.array([(_LC + 1.0) * np.cos(q[0]) + _LC * c12, _LC * c12])


def arm_tip_x(q: np.ndarray) -> np.ndarray:
    q = np.asarray(q)
    return np.cos(q[..., 0]) + np.cos(q[..., 0] + q[..., 1])


def make_arm_wall() -> FunctionModel:
    wall = FunctionConstraint.unilateral(
        "wall",
        gap=lambda q: [XW - np.cos(q[0]) - np.cos(q[0] + q[1])],
        jacobian=lambda q: np.array([[np.sin(q[0]) + np.sin(q[0] + q[1]), np.sin(q[0] + q[1])]]),
        adot_qd=lambda q, qd: [
            np.cos(q[0]) * qd[0] ** 2 + np.cos(q[0] + q[1]) * (qd[0] + qd[1]) ** 2
        ],
    )
    return FunctionModel(
        name="arm2r_wall_fn",
        coordinate_names=("q1", "q2"),
        mass=_arm_mass,
        coriolis=_arm_coriolis,
        conservative=_arm_conservative,
        potential=_arm_potential,
        constraints=(wall,),
        actuator_names=("tau1",),
        input_matrix_fn=lambda q: np.array([[1.0], [0.0]]),
    )
