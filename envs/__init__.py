"""Healthcare AI GYM environments.

Importing this package applies the CPU runtime defaults and registers `HealthcareGym-v0`.
"""

from envs import _runtime  # noqa: F401  (must run before torch/ray are imported)

import gymnasium

from envs.env import HealthcareGymEnv

ENV_ID = "HealthcareGym-v0"

if ENV_ID not in gymnasium.registry:
    gymnasium.register(id=ENV_ID, entry_point="envs.env:HealthcareGymEnv", disable_env_checker=False)

__all__ = ["HealthcareGymEnv", "ENV_ID"]
