"""Gymnasium environments over the simulator (the ``gymnasium`` extra).

Importing this package registers ``avrisk/Highway-v0``::

    import gymnasium
    import avrisk.gym  # noqa: F401  (registers the id)

    env = gymnasium.make("avrisk/Highway-v0", scenario="highway_idm")
    envs = gymnasium.make_vec("avrisk/Highway-v0", num_envs=64)  # one batch,
    # each row a Highway-v0 of its own (seed + i; next-step autoreset)

(``gymnasium.make("avrisk.gym:avrisk/Highway-v0")`` imports it itself.) See
:mod:`avrisk.gym.env` for the spaces, reward and ``info``. Without the extra,
importing it is an ImportError that says ``pip install 'avrisk[gymnasium]'``.
"""

from avrisk.extras import needs_extra

with needs_extra("gymnasium", "avrisk.gym"):
    import gymnasium

from avrisk.gym.env import (
    OBSERVATION_FIELDS,
    HeldAction,
    HighwayEnv,
    HighwayVectorEnv,
    flat_observation,
    observation_fields,
)

__all__ = [
    "ENV_ID",
    "OBSERVATION_FIELDS",
    "HeldAction",
    "HighwayEnv",
    "HighwayVectorEnv",
    "flat_observation",
    "observation_fields",
]

#: The registered environment id.
ENV_ID = "avrisk/Highway-v0"

if ENV_ID not in gymnasium.registry:
    gymnasium.register(
        id=ENV_ID,
        entry_point="avrisk.gym.env:HighwayEnv",
        vector_entry_point="avrisk.gym.env:HighwayVectorEnv",
    )
