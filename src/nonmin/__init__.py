"""nonmin: non-minimal projection dynamics of constrained mechanical systems.

Keeps all n dependent coordinates, eliminates constraint forces with the orthogonal projector
P = I − A⁺A and adds a virtual mass μQ so that M̄ = PMP + μQ stays SPD where A loses rank
(F. Aghili, "Non-Minimal Systems with Switching Topology: Dynamics and Controls", with the
corrections listed in ``docs/theory.md``).

Subpackages
-----------
core        pure NumPy kernels (P, M̄, C̄, forward dynamics, constraint forces, impact map)
model       the model protocol and its sources (functions, planar, spatial, SymPy, robots)
library     named mechanisms with consistent initial states (IFToMM benchmarks and more)
sim         simulation through singular configurations and switching topology
analysis    inverse dynamics and reactions by name
control     controllers in dependent coordinates (regulation, tracking, hybrid force)
linear      derivatives, linearization, equilibria, modes and LQR on the constraint manifold
            (imported on first use: ``nonmin.linearize``, ``nonmin.equilibrium``, ``nonmin.modes``)
viz         plots and animations (extra ``plot``)
io          scenario files
sweeps      parameter sweeps: batched runs, Zarr store, Dask (extra ``sweep``)
errors      the exception tree

The most used names are re-exported here: :func:`simulate`, :class:`Trajectory`,
:func:`load_trajectory`, :class:`Event`, :class:`Activate`, :class:`Deactivate`,
:class:`Reset`, :class:`Model`, :class:`State`, :func:`assemble`, :func:`check_model`,
:func:`forward_dynamics`, :func:`constraint_force`, :func:`impact_map`,
:func:`inverse_dynamics`, :func:`reactions`.
"""

from typing import TYPE_CHECKING, Any

from . import core as core
from . import errors as errors
from . import model as model
from . import sim as sim
from ._version import __version__ as __version__
from .core import constraint_force as constraint_force
from .core import forward_dynamics as forward_dynamics
from .core import impact_map as impact_map
from .model import Model as Model
from .model import State as State
from .model import assemble as assemble
from .sim import Activate as Activate
from .sim import Deactivate as Deactivate
from .sim import Event as Event
from .sim import EventSet as EventSet
from .sim import Output as Output
from .sim import Reset as Reset
from .sim import Solver as Solver
from .sim import Trajectory as Trajectory
from .sim import check_model as check_model
from .sim import load_trajectory as load_trajectory
from .sim import simulate as simulate
from .sim import simulate_batch as simulate_batch

if TYPE_CHECKING:  # the names below are imported on first access (module ``__getattr__``)
    from . import analysis as analysis
    from . import control as control
    from . import library as library
    from . import sweeps as sweeps
    from .analysis import inverse_dynamics as inverse_dynamics
    from .analysis import reactions as reactions
    from .sweeps import sweep as sweep

#: Names imported on first access (module ``__getattr__``), so that ``import nonmin`` loads only
#: what a simulation needs (issue 17, target 1: ``import nonmin`` <= 0.3 s): the mechanism
#: library, the controllers, inverse dynamics and reactions, the sweeps, nonmin.linear.
_LAZY = {
    "analysis": ("nonmin.analysis", None),
    "inverse_dynamics": ("nonmin.analysis", "inverse_dynamics"),
    "reactions": ("nonmin.analysis", "reactions"),
    "control": ("nonmin.control", None),
    "library": ("nonmin.library", None),
    "sweeps": ("nonmin.sweeps", None),
    "sweep": ("nonmin.sweeps", "sweep"),
    "linear": ("nonmin.linear", None),
    "linearize": ("nonmin.linear", "linearize"),
    "equilibrium": ("nonmin.linear", "equilibrium"),
    "modes": ("nonmin.linear", "modes"),
}


if not TYPE_CHECKING:  # (mypy would read every unknown submodule, the compiled _engine too, through it)

    def __getattr__(name: str) -> Any:
        spec = _LAZY.get(name)
        if spec is None:
            raise AttributeError(f"module 'nonmin' has no attribute {name!r}")
        from importlib import import_module

        mod = import_module(spec[0])
        value = mod if spec[1] is None else getattr(mod, spec[1])
        globals()[name] = value
        return value

    def __dir__() -> list[str]:
        return sorted(set(globals()) | set(_LAZY))


__all__ = [
    "Activate",
    "Deactivate",
    "Event",
    "EventSet",
    "Model",
    "Output",
    "Reset",
    "Solver",
    "State",
    "Trajectory",
    "__version__",
    "analysis",
    "assemble",
    "check_model",
    "constraint_force",
    "control",
    "core",
    "equilibrium",
    "errors",
    "forward_dynamics",
    "impact_map",
    "inverse_dynamics",
    "library",
    "linear",
    "linearize",
    "load_trajectory",
    "model",
    "modes",
    "reactions",
    "sim",
    "simulate",
    "simulate_batch",
    "sweep",
    "sweeps",
]
