"""Derivatives, linearization, equilibria, modes and LQR on the constraint manifold.

* :func:`dynamics_derivatives` — ``∂q̈/∂q``, ``∂q̈/∂q̇``, ``∂q̈/∂f``, ``∂q̈/∂u`` and those of the
  constraint force ``f_c``: model terms in forward mode in the engine (dual numbers), the
  kernel's solve differentiated analytically at its rank; :func:`term_tangents` for the
  directional derivatives of the model terms themselves.
* :func:`linearize` — a :class:`LinearSystem` (A, B, C, D) in minimal tangent coordinates of
  the constraint manifold (holonomic and nonholonomic), with the maps back to the dependent
  coordinates, singular configurations reported (and linearized on one branch, chosen by a
  velocity direction or a label: ``branch=``, :func:`branch_tangent`, :func:`branches`); ``to_control()`` for python-control.
* :func:`equilibrium`, :func:`modes` — static equilibria and small-oscillation modes (no
  spurious modes from the virtual mass or the constraint directions).
* :class:`LQR` — a regulator designed on the linearization, run as a nonmin controller,
  re-designed when the active set changes.

Theory: ``docs/linear.md``; derivatives are exact (no finite differences).
"""

from ._derivatives import DynamicsDerivatives as DynamicsDerivatives
from ._derivatives import dynamics_derivatives as dynamics_derivatives
from ._derivatives import term_tangents as term_tangents
from ._linearize import BRANCH_STEP as BRANCH_STEP
from ._linearize import Branches as Branches
from ._linearize import Equilibrium as Equilibrium
from ._linearize import LinearSystem as LinearSystem
from ._linearize import ModeMotion as ModeMotion
from ._linearize import Modes as Modes
from ._linearize import branch_tangent as branch_tangent
from ._linearize import branches as branches
from ._linearize import equilibrium as equilibrium
from ._linearize import linearize as linearize
from ._linearize import modes as modes
from ._lqr import LQR as LQR
from ._lqr import LQRDesign as LQRDesign

__all__ = [
    "BRANCH_STEP",
    "LQR",
    "Branches",
    "DynamicsDerivatives",
    "Equilibrium",
    "LQRDesign",
    "LinearSystem",
    "ModeMotion",
    "Modes",
    "branch_tangent",
    "branches",
    "dynamics_derivatives",
    "equilibrium",
    "linearize",
    "modes",
    "term_tangents",
]
