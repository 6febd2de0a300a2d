"""nonmin: non-minimal projection dynamics of constrained mechanical systems.

Keeps all n dependent coordinates, eliminates constraint forces with the orthogonal projector
P = I − A⁺A and adds a virtual mass μQ so that M̄ = PMP + μQ stays SPD where A loses rank
(F. Aghili, "Non-Minimal Systems with Switching Topology: Dynamics and Controls").
"""

from . import core as core
from . import errors as errors

#: Version of the installed nonmin package.
__version__ = "0.1.0"

__all__ = ["__version__", "core", "errors"]
