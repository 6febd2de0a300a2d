"""Pure NumPy kernels of the non-minimal projection dynamics (arrays in, arrays out).

Every kernel is batched over leading dimensions (``M: (..., n, n)``, ``A: (..., m, n)``,
vectors ``(..., n)``), accepts ``m = 0`` and rank-deficient A, and imports nothing beyond
NumPy and SciPy. Conventions (paper): ``M qdd + C qd = f_g + f_c + f``, ``h = f_g − C qd``,
``A qd = 0``, ``adot_qd = Ȧ qd``. Pinocchio: ``nle = C qd − f_g = −h``; ``J qdd + γ = 0``, so
``adot_qd = γ``.

:func:`forward_dynamics`, :func:`constraint_force` and :func:`solve_dynamics` run on the C++ engine
(``nonmin._engine``, built with the package) and on these NumPy kernels with the backend
``"numpy"``; :func:`set_backend`, :func:`use_backend` or the environment variable
``NONMIN_BACKEND`` (``auto``/``engine``/``numpy``) choose explicitly. Both agree to round-off.
"""

from ._fast import get_backend as get_backend
from ._fast import set_backend as set_backend
from ._fast import use_backend as use_backend
from .dynamics import DynamicsSolution as DynamicsSolution
from .dynamics import baumgarte_bias as baumgarte_bias
from .dynamics import constraint_force as constraint_force
from .dynamics import constraint_inertia as constraint_inertia
from .dynamics import coriolis_bar as coriolis_bar
from .dynamics import forward_dynamics as forward_dynamics
from .dynamics import optimal_virtual_mass as optimal_virtual_mass
from .dynamics import position_correction as position_correction
from .dynamics import solve_dynamics as solve_dynamics
from .friction import SlipDynamics as SlipDynamics
from .friction import slip_dynamics as slip_dynamics
from .impact import PolyhedralProjection as PolyhedralProjection
from .impact import SimultaneousImpact as SimultaneousImpact
from .impact import impact_map as impact_map
from .impact import polyhedral_projection as polyhedral_projection
from .impact import simultaneous_impact as simultaneous_impact
from .linalg import DEFAULT_RTOL as DEFAULT_RTOL
from .linalg import SPD_RTOL as SPD_RTOL
from .linalg import RangeBasis as RangeBasis
from .linalg import pseudo_inverse as pseudo_inverse
from .linalg import range_basis as range_basis
from .projectors import actuation_projectors as actuation_projectors
from .projectors import constraint_force_projector as constraint_force_projector
from .projectors import lambda_matrix as lambda_matrix
from .projectors import nullspace_projector as nullspace_projector
from .projectors import projector_derivative as projector_derivative

__all__ = [
    "DEFAULT_RTOL",
    "SPD_RTOL",
    "DynamicsSolution",
    "PolyhedralProjection",
    "RangeBasis",
    "SimultaneousImpact",
    "SlipDynamics",
    "actuation_projectors",
    "baumgarte_bias",
    "constraint_force",
    "constraint_force_projector",
    "constraint_inertia",
    "coriolis_bar",
    "forward_dynamics",
    "get_backend",
    "impact_map",
    "lambda_matrix",
    "nullspace_projector",
    "optimal_virtual_mass",
    "polyhedral_projection",
    "position_correction",
    "projector_derivative",
    "pseudo_inverse",
    "range_basis",
    "set_backend",
    "simultaneous_impact",
    "slip_dynamics",
    "solve_dynamics",
    "use_backend",
]
