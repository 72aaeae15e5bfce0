"""The Gymnasium environment of novelty exploration: ``llcps/Explore-v0``.

Importing this package registers the environment with Gymnasium, so that

    import gymnasium
    import llcps.gym  # noqa: F401  (registers llcps/Explore-v0)
    env = gymnasium.make("llcps/Explore-v0", scenario="scenario2")

gives an :class:`~llcps.gym.env.ExploreEnv` (docs/api.md). Needs the ``rl`` extra
(``pip install 'llcps[rl]'``); ``import llcps`` never loads gymnasium.
"""

from __future__ import annotations

import gymnasium

from llcps.gym.env import ExploreEnv

#: The id the environment is registered under.
ENV_ID = "llcps/Explore-v0"

if ENV_ID not in gymnasium.registry:
    gymnasium.register(id=ENV_ID, entry_point="llcps.gym.env:ExploreEnv")

__all__ = ["ENV_ID", "ExploreEnv"]
