"""Analyses of a model at given states: inverse dynamics and reactions by name.

:func:`inverse_dynamics`
    Actuator inputs that produce a given motion of a (closed-chain) constrained system,
    ``u = Γ f_∥`` with ``Γ = (PB)⁺`` (paper eq. (p1_inverse), corrected), the constraint
    forces, and the feasibility diagnosis (is q̈ consistent, is the motion achievable by B).
:func:`reactions`
    The force and torque each named constraint exerts on the two bodies it joins, in the
    bodies' frames, read from the generalized constraint force ``f_c`` (eq. (fc_R)), with
    the components that redundant constraints leave undetermined marked as such.
:func:`impulses`
    The same read-out of an impact's impulse ``M (q̇⁺ − q̇⁻)``: each constraint's force and
    torque impulse on its two bodies (what ``EventRecord.impulses`` holds).

Both build on :mod:`nonmin.core` and a :class:`~nonmin.model.Model`; see ``docs/contact.md``.
"""

from ._inverse import FEASIBILITY_RTOL as FEASIBILITY_RTOL
from ._inverse import InverseDynamics as InverseDynamics
from ._inverse import inverse_dynamics as inverse_dynamics
from ._reactions import DETERMINED_RTOL as DETERMINED_RTOL
from ._reactions import Reaction as Reaction
from ._reactions import impulses as impulses
from ._reactions import reactions as reactions

__all__ = [
    "DETERMINED_RTOL",
    "FEASIBILITY_RTOL",
    "InverseDynamics",
    "Reaction",
    "impulses",
    "inverse_dynamics",
    "reactions",
]
