"""Models: one protocol (:class:`Model`), many sources.

Sources: hand-written functions (:class:`FunctionModel`), planar multibody in absolute
coordinates, spatial multibody with unit quaternions, SymPy expressions, URDF/MJCF robots
(Pinocchio, MuJoCo). All produce :class:`Model` instances.
"""

from ._assembly import AssemblyResidual as AssemblyResidual
from ._assembly import assemble as assemble
from ._assembly import assembly_residual as assembly_residual
from ._assembly import consistent as consistent
from ._function import FunctionConstraint as FunctionConstraint
from ._function import FunctionModel as FunctionModel
from ._protocol import CONSTRAINT_KINDS as CONSTRAINT_KINDS
from ._protocol import ConstraintSpec as ConstraintSpec
from ._protocol import ConstraintTerms as ConstraintTerms
from ._protocol import FrictionContact as FrictionContact
from ._protocol import Geometry as Geometry
from ._protocol import Model as Model
from ._protocol import ModelTerms as ModelTerms
from ._protocol import State as State
from ._timefn import Expression as Expression
from ._timefn import PiecewisePolynomial as PiecewisePolynomial
from ._timefn import Polynomial as Polynomial
from ._timefn import Sampled as Sampled
from ._timefn import Spline as Spline
from ._timefn import TimeFunction as TimeFunction
from .spatial import SpatialBuilder as SpatialBuilder
from .spatial import SpatialModel as SpatialModel
from .symbolic import SymbolicConstraint as SymbolicConstraint
from .symbolic import SymbolicModel as SymbolicModel

__all__ = [
    "CONSTRAINT_KINDS",
    "AssemblyResidual",
    "ConstraintSpec",
    "ConstraintTerms",
    "Expression",
    "FrictionContact",
    "FunctionConstraint",
    "FunctionModel",
    "Geometry",
    "Model",
    "ModelTerms",
    "PiecewisePolynomial",
    "Polynomial",
    "Sampled",
    "SpatialBuilder",
    "SpatialModel",
    "Spline",
    "State",
    "SymbolicConstraint",
    "SymbolicModel",
    "TimeFunction",
    "assemble",
    "assembly_residual",
    "consistent",
]

# Robots (URDF/MJCF via Pinocchio/MuJoCo) are re-exported lazily, so that importing
# nonmin.model never imports pinocchio: nonmin.model.RobotModel imports it on first access.
_LAZY_ROBOTS = ("RobotModel", "FrameConstraint", "JointCoupling", "JointLimit")


def __getattr__(name: str) -> object:
    if name in _LAZY_ROBOTS:
        from . import robots

        return getattr(robots, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
