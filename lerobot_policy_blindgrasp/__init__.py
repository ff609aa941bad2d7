"""Discovery shim: LeRobot imports the module named like the distribution (`lerobot_policy_blindgrasp`).

Importing `lerobot_blindgrasp` registers every plugin type this package provides (policy, env, robot,
teleoperator), so `lerobot-train`, `lerobot-eval`, `lerobot-record`, ... find them with no extra flags.
"""

import lerobot_blindgrasp  # noqa: F401  (import for its registration side effects)
