"""The compiled controllers on a robot's engine program (TreeProgram), against the Python
controllers in the general driver on the NumPy reference kernels: the regulator's and force
control's f_g = h(q, 0) come from the loop's own evaluation (``NEED_GRAVITY``: the gravity
pass on the same kinematics, ``Program.gravity_in_pass``) instead of an evaluation of their own,
and the program reuses the kinematics of a configuration it evaluated last. Same u, q, qd, f_c
to round-off; the terms bit for bit those of separate evaluations."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

pytest.importorskip("pinocchio")

from nonmin import _engine as eng
from nonmin.control import ForceControl, Regulator
from nonmin.core import use_backend
from nonmin.model.robots._examples import serial_arm, two_arm_grasp
from nonmin.sim import simulate

pytestmark = pytest.mark.filterwarnings("ignore::nonmin.errors.JointLimitWarning")

FIELDS = ("q", "qd", "qdd", "f_c", "u")
NEEDS = ("M", "h", "f_passive", "B", "A", "gamma", "phi", "velocity")
FLAGS = {"M": eng.NEED_M, "h": eng.NEED_H, "f_passive": eng.NEED_H, "B": eng.NEED_B, "A": eng.NEED_A,
         "gamma": eng.NEED_GAMMA, "phi": eng.NEED_PHI, "velocity": eng.NEED_VELOCITY}  # fmt: skip


def _close(a: Any, b: Any, tol: float = 1e-9, tol_acc: float = 1e-7) -> None:
    assert a.metadata["engine"] == "engine" and b.metadata["engine"] == "python"
    assert a.success and b.success, (a.message, b.message)
    assert len(a) == len(b) and a.n_steps == b.n_steps
    for f in FIELDS:
        x, y = getattr(a, f), getattr(b, f)
        err = float(np.max(np.abs(x - y))) / max(1.0, float(np.max(np.abs(y))))
        assert err < (tol_acc if f in ("qdd", "f_c", "u") else tol), (f, err)


@pytest.mark.parametrize("robot", ["serial_arm", "two_arm_grasp"])
def test_gravity_in_pass_and_kinematics_reuse(robot: str) -> None:
    """f_g of NEED_GRAVITY is bitwise h(t, q, 0) of its own evaluation; a workspace evaluated
    again at the same q (any needs, in any order: the inertias added when first needed, a new
    q̇) gives bitwise the terms of a fresh workspace."""
    model = (serial_arm if robot == "serial_arm" else two_arm_grasp)()[0]
    prog = model.engine_program()
    assert prog.gravity_in_pass
    rng = np.random.default_rng(5)
    qs = [model.random_configuration(rng) for _ in range(2)]
    mask = np.ones(len(prog.constraints), dtype=np.uint8)
    T, ws = prog.make_terms(), prog.make_workspace()
    rows_only = eng.NEED_A | eng.NEED_PHI
    seq = [(0, rows_only), (0, eng.NEED_ALL | eng.NEED_GRAVITY), (0, eng.NEED_GAMMA), (1, eng.NEED_PHI),
           (1, eng.NEED_M | eng.NEED_H | eng.NEED_GRAVITY), (1, eng.NEED_ALL), (0, eng.NEED_H | eng.NEED_GRAVITY),
           (0, eng.NEED_GRAVITY)]  # fmt: skip
    for i, need in seq:
        qd = rng.normal(size=model.n)
        prog.evaluate_into(T, ws, 0.0, qs[i], qd, mask, need)
        fresh = prog.evaluate(0.0, qs[i], qd, mask, need)
        for name in NEEDS:
            if need & FLAGS[name]:
                np.testing.assert_array_equal(getattr(T, name), getattr(fresh, name), err_msg=name)
        if need & eng.NEED_GRAVITY:
            h0 = prog.evaluate(0.0, qs[i], np.zeros(model.n), mask, eng.NEED_H).h
            np.testing.assert_array_equal(T.f_g, h0)
            np.testing.assert_array_equal(fresh.f_g, h0)
            assert float(np.max(np.abs(h0))) > 0.1


def _arm_pair(make: Any, **kw: Any) -> tuple[Any, Any]:
    model, state = serial_arm()
    kw = {"t_span": (0.0, 0.1), "q0": state.q, "dt": 2e-3, **kw}
    a = simulate(model, controller=make(model, state), engine="engine", progress=False, **kw)
    with use_backend("numpy"):
        b = simulate(model, controller=make(model, state), engine="python", progress=False, **kw)
    return a, b


def test_regulator_on_a_robot_engine_equals_python() -> None:
    """The regulator on the 4-dof arm (gravity compensated through f_g): the engine's loop =
    the Python controller in the general driver."""

    def make(model: Any, state: Any) -> Regulator:
        return Regulator(model, target=state.q + 0.2, Kp=30.0, Kd=5.0)

    a, b = _arm_pair(make)
    _close(a, b)
    assert float(np.max(np.abs(a.u))) > 1.0


def test_force_control_on_a_robot_engine_equals_python() -> None:
    """Force control over the regulator, the arm's end effector pressed on the ground with
    2 N (the contact held as a bilateral constraint)."""

    def make(model: Any, state: Any) -> ForceControl:
        reg = Regulator(model, target=state.q, Kp=30.0, Kd=5.0)
        return ForceControl(reg, {"ee_contact": 2.0})

    a, b = _arm_pair(make, active={"ee_contact"})
    _close(a, b)
