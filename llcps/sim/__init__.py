"""The sub-symbolic knowledge base Psi: a PyBullet world, the Panda arm, entities,
the four action controllers R, perception of the symbolic state, Table-1 features,
and random pretraining interactions. See docs/world.md and docs/controllers.md."""

from __future__ import annotations

import os
import sys


def _import_pybullet_quietly() -> None:
    """Import pybullet with its build-time banner (written to the C stderr) suppressed,
    so every command's stderr carries only llcps's own messages."""
    try:
        sys.stderr.flush()
        saved, devnull = os.dup(2), os.open(os.devnull, os.O_WRONLY)
    except OSError:  # no real stderr (embedded interpreters): import as is
        import pybullet  # noqa: F401
        return
    os.dup2(devnull, 2)
    try:
        import pybullet  # noqa: F401
    finally:
        os.dup2(saved, 2)
        os.close(saved)
        os.close(devnull)


_import_pybullet_quietly()
