"""lerobot_blindgrasp: vision-free three-finger grasping with uniaxial fingertip force sensing, for LeRobot.

Importing it registers the plugin's LeRobot types: policy `blindgrasp_transformer`, envs `blindgrasp` and
`blindgrasp_real`, robot `blindgrasp_gripper`, teleoperator `manus_glove`. MuJoCo and rsl-rl load lazily.
"""

from lerobot_blindgrasp import envs, policies, robots, teleoperators  # noqa: F401  (registration)

__version__ = "0.1.0"
