"""Controllers of constrained systems in dependent coordinates (values with explicit state)."""

from ._protocol import Controller as Controller

__all__ = ["Controller"]
