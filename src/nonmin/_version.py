"""The package version (one place; ``nonmin.__version__`` re-exports it)."""

#: Package version.
__version__ = "0.1.0"
