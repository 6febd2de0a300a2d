"""Robots from URDF and MJCF: Pinocchio and MuJoCo models as nonmin models.

* :class:`RobotModel` — a rigid-body tree evaluated by Pinocchio (extra ``pin``), built with
  ``RobotModel.from_urdf``, ``RobotModel.from_pinocchio`` or ``RobotModel.from_mjcf``
  (MJCF parsed by MuJoCo, extra ``mujoco``; ``<equality>`` connect/weld/joint all imported).
* :class:`FrameConstraint` — named, switchable constraints between frames: ``point`` (3D loop
  closure), ``weld`` (6D), ``hinge`` (5D), ``planar_point``, ``planar_weld``,
  ``point_on_plane`` and unilateral ``contact``; :class:`JointCoupling` — polynomial joint
  coupling; :class:`JointLimit` — one side of a joint's position limit (unilateral; made from
  the file's limits by the constructors unless ``joint_limits=False``); drivers (rheonomic):
  :class:`JointDriver` (a joint coordinate ``q = f(t)``), :class:`PathDriver` (a frame point
  on a path ``(x(t), y(t), z(t))``, any subset of the axes) and :class:`DistanceDriver` (the
  distance of two frame points), with time functions evaluated by the engine.
* :func:`data_path` — path of a robot file shipped with nonmin (``nonmin/data/robots``);
  example robots built from them, each returning ``(model, state)``: :func:`serial_arm`
  (4-dof arm, unilateral end-effector contact), :func:`fourbar` (URDF four-bar + loop-closure
  constraint of a chosen type), :func:`fourbar_mjcf` (MJCF four-bar with ``<equality>``
  connect/weld/joint), :func:`two_arm_grasp` (two arms holding a free-floating box) and
  :func:`ur5_point_closure` (example-robot-data's UR5 with its tool pinned to the world;
  :func:`pinocchio_point_constraint` gives Pinocchio's form of that closure);
  :func:`example_robot_closure` (UR5 or Panda with its tool held by a point or a weld;
  :func:`pinocchio_frame_constraint` gives Pinocchio's form).

The constraint values and :func:`data_path` need no optional dependency; :class:`RobotModel`
is imported lazily, so ``import nonmin.model.robots`` never imports Pinocchio and a missing
Pinocchio raises :class:`~nonmin.errors.MissingDependencyError` naming the extra ``pin`` only
when :class:`RobotModel` is used.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from ._constraints import FRAME_CONSTRAINT_TYPES as FRAME_CONSTRAINT_TYPES
from ._constraints import DistanceDriver as DistanceDriver
from ._constraints import FrameConstraint as FrameConstraint
from ._constraints import JointCoupling as JointCoupling
from ._constraints import JointDriver as JointDriver
from ._constraints import JointLimit as JointLimit
from ._constraints import PathDriver as PathDriver
from ._data import data_path as data_path

if TYPE_CHECKING:
    from ._examples import example_robot_closure as example_robot_closure
    from ._examples import fourbar as fourbar
    from ._examples import fourbar_mjcf as fourbar_mjcf
    from ._examples import pinocchio_frame_constraint as pinocchio_frame_constraint
    from ._examples import pinocchio_point_constraint as pinocchio_point_constraint
    from ._examples import serial_arm as serial_arm
    from ._examples import two_arm_grasp as two_arm_grasp
    from ._examples import ur5_point_closure as ur5_point_closure
    from ._pinocchio import RobotModel as RobotModel

__all__ = [
    "FRAME_CONSTRAINT_TYPES",
    "DistanceDriver",
    "FrameConstraint",
    "JointCoupling",
    "JointDriver",
    "JointLimit",
    "PathDriver",
    "RobotModel",
    "data_path",
    "example_robot_closure",
    "fourbar",
    "fourbar_mjcf",
    "pinocchio_frame_constraint",
    "pinocchio_point_constraint",
    "serial_arm",
    "two_arm_grasp",
    "ur5_point_closure",
]

_EXAMPLES = (
    "example_robot_closure",
    "fourbar",
    "fourbar_mjcf",
    "pinocchio_frame_constraint",
    "pinocchio_point_constraint",
    "serial_arm",
    "two_arm_grasp",
    "ur5_point_closure",
)


def __getattr__(name: str) -> Any:
    if name == "RobotModel":
        from ._pinocchio import RobotModel

        return RobotModel
    if name in _EXAMPLES:
        from . import _examples

        return getattr(_examples, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
