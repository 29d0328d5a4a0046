"""hazardhunt: find the human behaviours that make a robot's control stack unsafe.

Importing the package registers the environment ``hazardhunt/AGV-v0`` with Gymnasium::

    import gymnasium
    import hazardhunt

    env = gymnasium.make("hazardhunt/AGV-v0", scenario="crossing", field="1.25m", reward="max")
"""

from __future__ import annotations

import gymnasium

__version__ = "0.1.0"

ENV_ID = "hazardhunt/AGV-v0"

if ENV_ID not in gymnasium.registry:
    gymnasium.register(id=ENV_ID, entry_point="hazardhunt.env.agv:AGVEnv")

__all__ = ["ENV_ID", "__version__"]
