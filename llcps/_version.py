"""The package version, in a module of its own so that anything may read it without
importing the package root (which the root's lazy imports would turn into a loop)."""

__version__ = "0.1.0"
