"""Controllers of constrained systems in dependent coordinates (values with explicit state).

Every controller here computes an admissible generalized force ``f_∥ ∈ N(A)`` and realizes it
with the minimum-norm actuator forces ``u = Γ f_∥``, ``Γ = (PB)⁺`` (ERRATA 4), checking the
actuation condition ``rank(PB) = n − rank(A)`` at every call.

* :class:`Regulator` — the paper's set-point law ``f_∥ = −P(f_g + Kp e + Kd qd)`` (σ = 0 by
  default; σ > 1 makes the loop stick, ERRATA 5) with its Lyapunov function.
* :class:`Tracker` — trajectory tracking on the projected dynamics (passivity-based with M̄, C̄
  and the skew property, or computed torque).
* :class:`ForceControl` — hybrid position/force control: commands the force carried by named
  constraints through the corrected eq. (fc_fp), with a motion controller in N(A).
* :class:`Switched` — picks a controller by the active constraint set.
* :class:`Reference`, :func:`project_configuration` and friends — references on the manifold.
"""

from ._base import LawOutput as LawOutput
from ._base import ProjectedController as ProjectedController
from ._common import ControlInfo as ControlInfo
from ._common import ControlState as ControlState
from ._force import ForceControl as ForceControl
from ._force import constraint_force_components as constraint_force_components
from ._protocol import Controller as Controller
from ._registry import CONTROLLERS as CONTROLLERS
from ._registry import get as get
from ._registry import names as names
from ._regulator import Regulator as Regulator
from ._switched import Switched as Switched
from ._targets import Reference as Reference
from ._targets import align_quaternions as align_quaternions
from ._targets import project_acceleration as project_acceleration
from ._targets import project_configuration as project_configuration
from ._targets import project_velocity as project_velocity
from ._tracking import Tracker as Tracker

__all__ = [
    "CONTROLLERS",
    "ControlInfo",
    "ControlState",
    "Controller",
    "ForceControl",
    "LawOutput",
    "ProjectedController",
    "Reference",
    "Regulator",
    "Switched",
    "Tracker",
    "align_quaternions",
    "constraint_force_components",
    "get",
    "names",
    "project_acceleration",
    "project_configuration",
    "project_velocity",
]
