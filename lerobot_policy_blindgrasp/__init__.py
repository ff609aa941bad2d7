"""Discovery shim: LeRobot imports the module named like the distribution, and importing `lerobot_blindgrasp`
registers every plugin type, so `lerobot-train`, `lerobot-eval`, `lerobot-record`, ... find them with no flags."""

import lerobot_blindgrasp  # noqa: F401  (import for its registration side effects)
