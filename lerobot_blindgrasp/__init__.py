"""lerobot_blindgrasp: vision-free three-finger grasping with uniaxial fingertip force sensing, for LeRobot.

Importing this package registers its LeRobot plugin types (LeRobot imports it through the
`lerobot_policy_blindgrasp` discovery shim):
- policy `blindgrasp_transformer` (`policies/`),
- env `blindgrasp` for lerobot-eval (`envs/`),
- robot and teleoperator for the real gripper and the Manus glove (`robots/`, `teleoperators/`).
Heavy modules (MuJoCo, rsl-rl) are imported lazily by the code that needs them.
"""

import os

# Before torch loads OpenMP (it reads this once): idle OpenMP threads sleep instead of spinning. On a 2-core machine
# shared with anything else, spinning made the teacher's 2-thread PPO update 4.8x slower (7.3 s against 1.6 s per
# iteration); on an idle machine both policies run it equally fast (docs/results/teacher_cpu_bc.md, section 9).
# Only when this package is imported before torch, and never over the user's own setting.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

from lerobot_blindgrasp import envs, policies, robots, teleoperators  # noqa: E402, F401  (registration)

__version__ = "0.1.0"
