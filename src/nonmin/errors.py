"""Exception tree of nonmin.

Every error nonmin raises on purpose derives from :class:`NonminError` and also from the
built-in exception a Python user would expect, so ``except ValueError`` keeps working::

    NonminError
    ├── InputError (ValueError)                 bad arguments at a public boundary
    │   ├── ShapeError                          wrong shape / dimension
    │   ├── NonFiniteError                      NaN or inf in an input
    │   ├── NotSymmetricError                   M (or another matrix) not symmetric
    │   ├── UnknownNameError (also KeyError)    unknown body, joint, constraint, registry name
    │   └── FileFormatError                     a corrupt, truncated or inconsistent data file
    ├── NotPositiveDefiniteError (ValueError)   M not positive definite on N(A): M̄ not SPD
    ├── InfeasibleActuationError (ValueError)   rank(PB) < n - rank(A)
    ├── ModelError (ValueError)                 a model that is not physical or not consistent
    │   └── AssemblyError                       initial conditions that cannot be assembled
    ├── SimulationError (RuntimeError)          an integration that cannot go on
    │   └── ZenoError                           too many impacts in too short a time
    ├── ScenarioError (ValueError)              malformed scenario file (file, key, expected)
    │   └── UntrustedCodeError                  a data file names code to run without opt-in
    ├── OutputError (OSError)                   a result file that cannot be written
    └── MissingDependencyError (ImportError)    optional extra not installed (names the extra)

Messages name the argument and give what was expected and what came.

Warnings: :class:`JointLimitWarning` (UserWarning) — a robot file declares joint position
limits that the dynamics do not enforce.
"""

from __future__ import annotations

__all__ = [
    "AssemblyError",
    "FileFormatError",
    "InfeasibleActuationError",
    "InputError",
    "JointLimitWarning",
    "MissingDependencyError",
    "ModelError",
    "NonFiniteError",
    "NonminError",
    "NotPositiveDefiniteError",
    "NotSymmetricError",
    "OutputError",
    "PainleveError",
    "ScenarioError",
    "ShapeError",
    "SimulationError",
    "UnknownNameError",
    "UntrustedCodeError",
    "ZenoError",
]


class NonminError(Exception):
    """Base class of every error raised on purpose by nonmin."""


class InputError(NonminError, ValueError):
    """An argument at a public boundary is not what the function accepts."""


class ShapeError(InputError):
    """An array has the wrong number of dimensions or the wrong size."""


class NonFiniteError(InputError):
    """An input contains NaN or infinity."""


class NotSymmetricError(InputError):
    """A matrix that must be symmetric (the inertia matrix M) is not."""


class UnknownNameError(InputError, KeyError):
    """A name (body, joint, constraint, registry entry) that does not exist."""

    def __str__(self) -> str:  # KeyError would otherwise print the repr of the message
        return str(self.args[0]) if self.args else ""


class FileFormatError(InputError):
    """A data file (trajectory, robot description) that is corrupt, truncated or inconsistent.

    The message names the file and the entry (array, key, XML element) at fault.
    """


class NotPositiveDefiniteError(NonminError, ValueError):
    """M̄ = PMP + μQ is not positive definite: M is not positive definite on N(A)."""


class InfeasibleActuationError(NonminError, ValueError):
    """The actuators cannot produce every admissible force: rank(PB) < n - rank(A)."""


class ModelError(NonminError, ValueError):
    """A model description that is not physical or not consistent."""


class AssemblyError(ModelError):
    """Initial conditions that cannot be assembled onto the constraints."""


class SimulationError(NonminError, RuntimeError):
    """A simulation that cannot continue (step size underflow, non-finite state, ...)."""


class ZenoError(SimulationError):
    """An accumulation of impacts (Zeno behaviour) that the simulator refuses to follow."""


class PainleveError(SimulationError):
    """Sliding Coulomb friction is inconsistent at a contact (Painlevé's paradox): the normal
    force sliding needs solves ``(1 + μ s ∂N/∂F) N = N0`` with a non-positive factor (a non-P
    matrix with several slipping contacts). ``contact``, ``t`` and ``factor`` say where, when
    and how much."""

    def __init__(
        self, message: str, *, contact: str = "", t: float = float("nan"), factor: float = float("nan")
    ) -> None:
        super().__init__(message)
        self.contact = contact
        self.t = t
        self.factor = factor


class ScenarioError(NonminError, ValueError):
    """A malformed scenario file: names the file, the key, what was expected and what came."""


class UntrustedCodeError(ScenarioError):
    """A data file names code to import and run (an entry point, a guard function) and the
    caller did not opt in with ``allow_code=True`` / ``--allow-code``.

    Scenario files with entry points are programs: run them only when you trust their author.
    """


class OutputError(NonminError, OSError):
    """A result file that cannot be written (permissions, full disk, file-size limit, a
    folder in the way). The message names the file; the previous file there is unchanged."""


class MissingDependencyError(NonminError, ImportError):
    """An optional dependency is not installed; the message names the extra to install."""


class JointLimitWarning(UserWarning):
    """A robot file (URDF/MJCF) declares joint position limits that nonmin does not enforce."""


def missing_dependency(module: str, extra: str, purpose: str) -> MissingDependencyError:
    """Build the error raised when optional module ``module`` is missing.

    Parameters
    ----------
    module : str
        Import name of the missing package (e.g. ``"pinocchio"``).
    extra : str
        Name of the nonmin extra that installs it (e.g. ``"pin"``).
    purpose : str
        What the user was trying to do.
    """
    return MissingDependencyError(
        f"{purpose} needs the optional package {module!r}, which is not installed; "
        f"install it with: pip install 'nonmin[{extra}]'"
    )
