"""URDF/MJCF joint position limits as unilateral constraints (issue 19, "respect what the model says").

References: the limit rows are ``±eᵢ`` with gap ``q − lower`` / ``upper − q`` and γ = 0 (closed
form); the engine's TreeProgram rows are compared with the Python/Pinocchio path; the impact
law at the stop is Newton's (post-impact joint velocity = −e × pre-impact for a 1-dof arm).
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

pin = pytest.importorskip("pinocchio")

from nonmin.errors import InputError, JointLimitWarning, UnknownNameError  # noqa: E402
from nonmin.model.robots import JointLimit, RobotModel  # noqa: E402
from nonmin.sim import simulate  # noqa: E402

# One link about a horizontal (y) axis, COM 0.5 m along x: released horizontal from rest,
# gravity (−z) turns it towards +q, so it reaches the upper limit 0.5 rad at ~0.4 s.
ARM = """<?xml version="1.0"?>
<robot name="arm">
  <link name="base"/>
  <link name="arm">
    <inertial><origin xyz="0.5 0 0"/><mass value="1.0"/>
      <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial>
  </link>
  <joint name="shoulder" type="revolute">
    <parent link="base"/><child link="arm"/><axis xyz="0 1 0"/>
    <limit lower="-0.5" upper="0.5" effort="10" velocity="1"/>
  </joint>
  {extra}
</robot>
"""

ELBOW = """
  <link name="fore">
    <inertial><origin xyz="0.3 0 0"/><mass value="0.5"/>
      <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.05" iyz="0" izz="0.05"/></inertial>
  </link>
  <joint name="elbow" type="revolute">
    <parent link="arm"/><child link="fore"/><origin xyz="1 0 0"/><axis xyz="0 1 0"/>
    <limit lower="-1.0" upper="0.25" effort="10" velocity="1"/>
  </joint>
  <link name="slider">
    <inertial><mass value="0.2"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial>
  </link>
  <joint name="slide" type="prismatic">
    <parent link="fore"/><child link="slider"/><origin xyz="0.6 0 0"/><axis xyz="1 0 0"/>
    <limit lower="-0.1" upper="0.2" effort="10" velocity="1"/>
  </joint>
"""


def _arm(tmp_path: Path, extra: str = "", **kw: object) -> RobotModel:
    p = tmp_path / "arm.urdf"
    p.write_text(ARM.format(extra=extra))
    return RobotModel.from_urdf(p, **kw)  # type: ignore[arg-type]


def test_limits_are_unilateral_constraints(tmp_path: Path) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error", JointLimitWarning)
        model = _arm(tmp_path)
    names = [c.name for c in model.constraints]
    assert names == ["shoulder.lower", "shoulder.upper"]
    assert all(c.kind == "unilateral" for c in model.constraints)
    assert model.default_active == frozenset()
    lo, hi = (c for c in model.robot_constraints if isinstance(c, JointLimit))
    assert (lo.side, lo.bound, hi.side, hi.bound) == ("lower", -0.5, "upper", 0.5)


@pytest.mark.parametrize("engine", ["engine", "python"])
def test_arm_stops_at_limit_and_bounces(tmp_path: Path, engine: str) -> None:
    """The issue's example: limited to ±0.5 rad, it no longer swings to 3.24 rad (the C++
    loop and the general Python driver)."""
    model = _arm(tmp_path)
    e = 0.5
    tr = simulate(model, (0.0, 2.0), [0.0], [0.0], dt=1e-3, restitution={"shoulder.upper": e}, engine=engine)
    assert tr.status.value == "success", tr.message
    q = tr.q[:, 0]
    assert q.max() <= 0.5 + 1e-9 and q.min() >= -0.5 - 1e-9
    assert q.max() > 0.5 - 1e-9  # it reached the stop
    impacts = [ev for ev in tr.events if ev.name == "impact:shoulder.upper"]
    assert impacts, [ev.name for ev in tr.events]
    ev = impacts[0]
    assert abs(ev.q_before[0] - 0.5) < 1e-9
    assert ev.qd_before[0] > 1.0  # gravity accelerated it into the stop
    assert abs(ev.qd_after[0] - (-e * ev.qd_before[0])) < 1e-6


def test_plastic_limit_holds_the_arm(tmp_path: Path) -> None:
    model = _arm(tmp_path)
    tr = simulate(model, (0.0, 1.5), [0.0], [0.0], dt=1e-3)  # restitution 0: plastic stop
    q = tr.q[:, 0]
    assert q.max() <= 0.5 + 1e-9
    assert abs(q[-1] - 0.5) < 1e-9 and abs(tr.qd[-1, 0]) < 1e-9
    assert "shoulder.upper" in tr.events[0].active_after


def test_joint_limits_false_warns_and_swings_past(tmp_path: Path) -> None:
    with pytest.warns(JointLimitWarning, match=r"shoulder \[-0\.5, 0\.5\]"):
        model = _arm(tmp_path, joint_limits=False)
    assert model.constraints == ()
    tr = simulate(model, (0.0, 2.0), [0.0], [0.0], dt=1e-3)
    assert tr.q[:, 0].max() > 3.0  # the unlimited pendulum swings to ~π (3.24 in the issue)
    with warnings.catch_warnings():
        warnings.simplefilter("error", JointLimitWarning)
        assert _arm(tmp_path, joint_limits="ignore").constraints == ()
    with pytest.raises(InputError, match="joint_limits"):
        _arm(tmp_path, joint_limits="enforce")


def test_limit_rows_engine_equals_python(tmp_path: Path) -> None:
    model = _arm(tmp_path, extra=ELBOW)
    names = [c.name for c in model.constraints]
    assert names == ["shoulder.lower", "shoulder.upper", "elbow.lower", "elbow.upper", "slide.lower", "slide.upper"]
    assert model.engine_program() is not None
    rng = np.random.default_rng(3)
    bounds = {"shoulder": (-0.5, 0.5), "elbow": (-1.0, 0.25), "slide": (-0.1, 0.2)}
    for _ in range(5):
        q = rng.uniform(-1.5, 1.5, 3)
        qd = rng.normal(size=3)
        every = frozenset(names)
        eng = model.evaluate(0.0, q, qd, every)
        py = model._evaluate_pinocchio(0.0, q, qd, every)
        np.testing.assert_allclose(eng.constraints.A, py.constraints.A, atol=0, rtol=0)
        np.testing.assert_allclose(eng.constraints.phi, py.constraints.phi, atol=1e-15)
        np.testing.assert_allclose(eng.constraints.gamma, py.constraints.gamma, atol=0)
        np.testing.assert_allclose(eng.constraints.velocity, py.constraints.velocity, atol=1e-15)
        # closed form: gap q - lower / upper - q, A = ±e_i, γ = 0
        phi, A = [], []
        for i, j in enumerate(("shoulder", "elbow", "slide")):
            lo, hi = bounds[j]
            phi += [q[i] - lo, hi - q[i]]
            A += [np.eye(3)[i], -np.eye(3)[i]]
        np.testing.assert_allclose(py.constraints.phi, phi, atol=1e-15)
        np.testing.assert_array_equal(py.constraints.A, np.array(A))
        np.testing.assert_array_equal(py.constraints.gamma, np.zeros(6))
        # a subset: rows follow the active set
        sub = frozenset({"elbow.upper"})
        e1, p1 = model.evaluate(0.0, q, qd, sub), model._evaluate_pinocchio(0.0, q, qd, sub)
        np.testing.assert_array_equal(e1.constraints.A, p1.constraints.A)
        np.testing.assert_allclose(e1.constraints.phi, [0.25 - q[1]], atol=1e-15)


def test_from_pinocchio_limits_and_bad_joint() -> None:
    pm = pin.Model()
    jid = pm.addJoint(0, pin.JointModelRY(), pin.SE3.Identity(), "j")
    pm.appendBodyToJoint(jid, pin.Inertia(1.0, np.array([0.5, 0.0, 0.0]), np.eye(3) * 0.01), pin.SE3.Identity())
    assert RobotModel.from_pinocchio(pm).constraints == ()  # default limits: none
    pm.lowerPositionLimit = np.array([-0.3])
    pm.upperPositionLimit = np.array([np.inf])  # one-sided
    model = RobotModel.from_pinocchio(pm)
    assert [c.name for c in model.constraints] == ["j.lower"]
    with pytest.warns(JointLimitWarning, match="j"):
        RobotModel.from_pinocchio(pm, joint_limits=False)
    with pytest.raises(UnknownNameError, match="nope"):
        RobotModel.from_pinocchio(pm, constraints=[JointLimit("x", "nope", 0.0, "lower")], joint_limits="ignore")
    with pytest.raises(InputError, match="side"):
        JointLimit("x", "j", 0.0, "middle")  # type: ignore[arg-type]
    with pytest.raises(InputError, match="bound"):
        JointLimit("x", "j", float("nan"), "lower")


def test_mjcf_limits(tmp_path: Path) -> None:
    pytest.importorskip("mujoco")
    p = tmp_path / "m.xml"
    p.write_text(
        '<mujoco><compiler angle="radian"/><worldbody><body name="b"><joint name="h" type="hinge" '
        'axis="0 1 0" limited="true" range="-0.5 0.5"/><geom type="sphere" size="0.1" pos="0.5 0 0"/>'
        "</body></worldbody></mujoco>"
    )
    with warnings.catch_warnings():
        warnings.simplefilter("error", JointLimitWarning)
        model = RobotModel.from_mjcf(p)
    assert [c.name for c in model.constraints] == ["h.lower", "h.upper"]
    tr = simulate(model, (0.0, 1.5), [0.0], [0.0], dt=1e-3, restitution={"h.upper": 0.3, "h.lower": 0.3})
    assert -0.5 - 1e-9 <= tr.q[:, 0].min() and tr.q[:, 0].max() <= 0.5 + 1e-9
    with pytest.warns(JointLimitWarning, match=r"h \[-0\.5, 0\.5\]"):
        free = RobotModel.from_mjcf(p, joint_limits=False)
    assert free.constraints == ()


def test_limit_on_a_floating_base_robot_keeps_the_loop_closed() -> None:
    """The dual-arm grasp (free box: its unit-quaternion row is always active) reaches the left
    wrist's upper stop (π) at t ≈ 0.719 s. The gap and the impact of a limit are read from the
    limit's own row (located by name), not from row 0, which is the quaternion's: the bug made
    every limit "impact" at the first step and the grasp come apart (closure 3.2 m, status
    success)."""
    from nonmin.model.robots import two_arm_grasp

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model, state = two_arm_grasp()
    for engine, t1 in (("engine", 0.8), ("python", 0.01)):
        tr = simulate(model, (0.0, t1), state, method="rk4", dt=1e-3, progress=False, engine=engine)
        assert float(np.max(tr.phi_norm)) < 1e-9, engine
        names = [e.name for e in tr.events]
        assert names == (["impact:left_wrist.upper"] if t1 > 0.72 else []), (engine, names)
