"""lerobot_blindgrasp: vision-free three-finger grasping with uniaxial fingertip force sensing, for LeRobot.

Importing this package registers its LeRobot plugin types (LeRobot imports it through the
`lerobot_policy_blindgrasp` discovery shim):
- policy `blindgrasp_transformer` (`policies/`),
- env `blindgrasp` for lerobot-eval (`envs/`),
- robot and teleoperator for the real gripper and the Manus glove (`robots/`, `teleoperators/`).
Heavy modules (MuJoCo, rsl-rl) are imported lazily by the code that needs them.
"""

from lerobot_blindgrasp import envs, policies, robots, teleoperators  # noqa: F401  (registration)

__version__ = "0.1.0"
