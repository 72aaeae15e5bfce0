"""The physics engine, PyBullet, imported once and quietly.

Importing it prints a banner from native code, and stdout carries ``--json`` data, so
every module that drives the engine imports it from here. Modules that only describe
scenes (``specs``) do not, so reading a scenario file or a results table never loads it.
"""

from __future__ import annotations

from llcps.sim.native import native_output_silenced

with native_output_silenced():
    import pybullet

__all__ = ["pybullet"]
