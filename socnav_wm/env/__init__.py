"""The social-navigation simulator: one batched implementation (``core.Simulator``).

Importing this package registers the gymnasium id ``SocNav-v0``.
"""

from socnav_wm.env.core import ACTION_NAMES, NUM_ACTIONS, Simulator, StepResult
from socnav_wm.env.gym import ENV_ID, SocNavEnv, SocNavVectorEnv, register
from socnav_wm.env.params import EnvParams

register()

__all__ = [
    "ACTION_NAMES",
    "ENV_ID",
    "NUM_ACTIONS",
    "EnvParams",
    "Simulator",
    "SocNavEnv",
    "SocNavVectorEnv",
    "StepResult",
]
