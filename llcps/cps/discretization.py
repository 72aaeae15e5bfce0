"""The documented discretization of controller settings that exploration searches.

Units: ``rate`` is end-effector speed during the action's main motion (m/s);
``movement_magnitude`` is the length of that motion (m). See docs/controllers.md.
"""

from __future__ import annotations

from llcps.domain import ORIENTATIONS

#: End-effector speeds tried during exploration, slow to fast (m/s).
RATES: tuple[float, ...] = (0.1, 0.4, 1.0)

#: Motion lengths tried during exploration, short to long (m).
MOVEMENT_MAGNITUDES: tuple[float, ...] = (0.05, 0.15, 0.3)

#: Approach sides tried during exploration.
EXPLORATION_ORIENTATIONS: tuple[str, ...] = ORIENTATIONS
