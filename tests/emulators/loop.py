"""Helpers for tests that drive the emulated gripper at 20 Hz (the `rig` and `robot` fixtures are in conftest.py)."""

from __future__ import annotations

import numpy as np

from lerobot_blindgrasp import spec


def settle(robot, target: dict[str, float], steps: int = 20) -> dict[str, float]:
    """Send the same target at 20 Hz until the servos get there (emulated time constant ~30 ms)."""
    import time

    for _ in range(steps):
        robot.send_action(target)
        time.sleep(spec.CONTROL_DT / 2)
    return robot.get_observation()


def as_q(obs: dict[str, float]) -> np.ndarray:
    return np.array([obs[k] for k in spec.JOINT_FEATURE_NAMES])
