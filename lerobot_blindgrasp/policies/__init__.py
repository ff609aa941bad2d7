"""LeRobot policies of this plugin. Importing registers them with LeRobot (`--policy.type=...`)."""

from lerobot_blindgrasp.policies import blindgrasp_transformer  # noqa: F401  (registration)
