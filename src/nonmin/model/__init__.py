"""Models: one protocol (:class:`Model`), many sources.

Sources: hand-written functions (:class:`FunctionModel`), planar multibody in absolute
coordinates, spatial multibody with unit quaternions, SymPy expressions, URDF/MJCF robots
(Pinocchio, MuJoCo). All produce :class:`Model` instances.
"""

from ._check import ModelReport as ModelReport
from ._check import check_model as check_model
from ._function import FunctionConstraint as FunctionConstraint
from ._function import FunctionModel as FunctionModel
from ._protocol import CONSTRAINT_KINDS as CONSTRAINT_KINDS
from ._protocol import ConstraintSpec as ConstraintSpec
from ._protocol import ConstraintTerms as ConstraintTerms
from ._protocol import Geometry as Geometry
from ._protocol import Model as Model
from ._protocol import ModelTerms as ModelTerms
from ._protocol import State as State

__all__ = [
    "CONSTRAINT_KINDS",
    "ConstraintSpec",
    "ConstraintTerms",
    "FunctionConstraint",
    "FunctionModel",
    "Geometry",
    "Model",
    "ModelReport",
    "ModelTerms",
    "State",
    "check_model",
]
