"""socnav-wm: predictive world models for social robot navigation.

Importing the package registers its Gymnasium environment ``SocNav-v0`` (Gymnasium 1.x's way,
no entry-point plugin): ``gym.make("socnav_wm:SocNav-v0")`` imports it and makes the env in one
call, and after ``import socnav_wm`` (or ``gym.register_envs(socnav_wm)``) ``gym.make("SocNav-v0")``
works too. The registration names the env classes by their import path, so nothing of the
simulator is imported until an env is made.
"""

import gymnasium

__version__ = "0.1.0"

ENV_ID = "SocNav-v0"
"""The Gymnasium id of the single env (and, with ``gym.make_vec``, the batched one)."""

if ENV_ID not in gymnasium.registry:
    # No `max_episode_steps`: the env truncates itself at its own `max_steps` (a TimeLimit
    # registered here would cut an episode whose `max_steps` was raised at `gym.make`).
    gymnasium.register(
        id=ENV_ID,
        entry_point="socnav_wm.env.gym:SocNavEnv",
        vector_entry_point="socnav_wm.env.gym:SocNavVectorEnv",
    )
