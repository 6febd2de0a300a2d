"""Symbolic source: SymPy expressions (T or M, V, constraints, B) → a numeric model.

The only package of nonmin that imports SymPy (lazily, on first use); without SymPy a
:class:`~nonmin.errors.MissingDependencyError` names the extra ``sympy``.
"""

from ._model import SymbolicConstraint as SymbolicConstraint
from ._model import SymbolicModel as SymbolicModel

__all__ = ["SymbolicConstraint", "SymbolicModel"]
