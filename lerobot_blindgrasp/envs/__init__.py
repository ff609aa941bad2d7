"""LeRobot env plugins for `lerobot-eval`. Importing a module here registers its `--env.type`."""

from lerobot_blindgrasp.envs.real_env import BlindGraspRealEnvConfig  # noqa: F401  (registers "blindgrasp_real")
from lerobot_blindgrasp.envs.sim_env import BlindGraspEnvConfig  # noqa: F401  (registers "blindgrasp")
