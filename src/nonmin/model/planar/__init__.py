"""Planar multibody models in absolute coordinates ``(x, y, θ)`` per body.

Build a model with :class:`PlanarBuilder` (bodies, point masses, revolute, prismatic, weld,
rod, point-on-line, gear, angle drivers, springs, dampers, actuators, gravity) and get an
immutable :class:`PlanarModel` implementing :class:`nonmin.model.Model` with constant
``M = diag(m, m, I)``, ``C = 0`` and closed-form ``φ``, ``A``, ``Ȧ`` and ``γ``.
"""

from ._builder import PlanarBuilder as PlanarBuilder
from ._builder import PointRef as PointRef
from ._elements import GROUND as GROUND
from ._elements import AngleDriver as AngleDriver
from ._elements import AngleLimit as AngleLimit
from ._elements import Body as Body
from ._elements import ConstantSpeed as ConstantSpeed
from ._elements import ContactTangent as ContactTangent
from ._elements import Gear as Gear
from ._elements import Joint as Joint
from ._elements import JointActuator as JointActuator
from ._elements import Point as Point
from ._elements import PointForce as PointForce
from ._elements import PointOnLine as PointOnLine
from ._elements import Prismatic as Prismatic
from ._elements import Revolute as Revolute
from ._elements import Rod as Rod
from ._elements import RotationalSpring as RotationalSpring
from ._elements import Spring as Spring
from ._elements import Torque as Torque
from ._elements import Weld as Weld
from ._model import PlanarModel as PlanarModel

__all__ = [
    "GROUND",
    "AngleDriver",
    "AngleLimit",
    "Body",
    "ConstantSpeed",
    "ContactTangent",
    "Gear",
    "Joint",
    "JointActuator",
    "PlanarBuilder",
    "PlanarModel",
    "Point",
    "PointForce",
    "PointOnLine",
    "PointRef",
    "Prismatic",
    "Revolute",
    "Rod",
    "RotationalSpring",
    "Spring",
    "Torque",
    "Weld",
]
