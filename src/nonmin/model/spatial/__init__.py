"""Spatial multibody source: absolute coordinates with unit quaternions (7 per body).

Build models with :class:`SpatialBuilder`; the result is an immutable :class:`SpatialModel`
(one :class:`~nonmin.model.Model`). Quaternion convention and the closed-form ``M``, ``C``:
see :mod:`nonmin.model.spatial._quaternion`.
"""

from ._builder import SpatialBuilder as SpatialBuilder
from ._inertia import check_inertia as check_inertia
from ._model import GROUND as GROUND
from ._model import JOINT_KINDS as JOINT_KINDS
from ._model import Actuator as Actuator
from ._model import Body as Body
from ._model import Joint as Joint
from ._model import OutputPoint as OutputPoint
from ._model import SpatialModel as SpatialModel
from ._model import Spring as Spring
from ._quaternion import E_matrix as E_matrix
from ._quaternion import G_matrix as G_matrix
from ._quaternion import quaternion_from_axis_angle as quaternion_from_axis_angle
from ._quaternion import quaternion_from_rotation_matrix as quaternion_from_rotation_matrix
from ._quaternion import rotation_matrix as rotation_matrix

__all__ = [
    "GROUND",
    "JOINT_KINDS",
    "Actuator",
    "Body",
    "E_matrix",
    "G_matrix",
    "Joint",
    "OutputPoint",
    "SpatialBuilder",
    "SpatialModel",
    "Spring",
    "check_inertia",
    "quaternion_from_axis_angle",
    "quaternion_from_rotation_matrix",
    "rotation_matrix",
]
