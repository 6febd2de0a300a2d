"""Library of named mechanisms, each with a consistent initial state and its benchmark data.

>>> import nonmin.library as lib
>>> mech = lib.get("A02_n_four_bar", N=2)
>>> mech.model.n, mech.t_final
(15, 10.0)

``names()`` lists the registered mechanisms; ``get(name, **params)`` builds one; each also
has its own function (``a01_pendulum``, ``a02_n_four_bar``, ...). To add a mechanism, see
:mod:`nonmin.library._registry` (a ``@register(name)`` decorator in a module of this
package, imported below).
"""

from importlib import import_module as _import_module
from importlib.util import find_spec as _find_spec

from ._andrews import AndrewsModel as AndrewsModel
from ._andrews import a03_andrews as a03_andrews
from ._friction import foot_friction as foot_friction
from ._iftomm import a01_pendulum as a01_pendulum
from ._iftomm import a02_n_four_bar as a02_n_four_bar
from ._iftomm import n_four_bar_reference as n_four_bar_reference
from ._planar import arm2r_wall as arm2r_wall
from ._planar import crossed_four_bar as crossed_four_bar
from ._planar import crossed_four_bar_reference as crossed_four_bar_reference
from ._planar import dual_arm_grasp as dual_arm_grasp
from ._planar import five_bar as five_bar
from ._planar import slider_crank as slider_crank
from ._registry import Mechanism as Mechanism
from ._registry import get as get
from ._registry import names as names
from ._registry import register as register

__all__ = [
    "AndrewsModel",
    "Mechanism",
    "a01_pendulum",
    "a02_n_four_bar",
    "a03_andrews",
    "arm2r_wall",
    "crossed_four_bar",
    "crossed_four_bar_reference",
    "dual_arm_grasp",
    "five_bar",
    "foot_friction",
    "get",
    "n_four_bar_reference",
    "names",
    "register",
    "slider_crank",
]

# Spatial mechanisms (A04 Bricard, spinning top) live in their own modules; they register
# themselves on import.
for _mod in ("bricard", "top"):
    if _find_spec(f"{__name__}.{_mod}") is not None:
        _import_module(f"{__name__}.{_mod}")
