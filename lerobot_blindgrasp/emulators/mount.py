"""How every emulated gripper's servos sit on its fingers: shaft ticks at the sim's q = 0 and each servo's sign,
deliberately messy, so that `lerobot-calibrate` has to find Drive_Mode and Homing_Offset itself."""

from __future__ import annotations

import numpy as np

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.hardware.xm430 import TICKS_PER_REV

TICKS_PER_RAD = TICKS_PER_REV / (2 * np.pi)
MOUNT_ZERO = np.array([1100.0 + 237.0 * k for k in range(spec.NUM_JOINTS)])  # spec.JOINT_NAMES order
MOUNT_SIGN = np.array([1, -1, 1, -1, 1, -1, 1, 1, -1], dtype=np.float64)


def shaft_for_q(q, k=slice(None)):
    """Shaft ticks (before Drive_Mode/Homing_Offset) of joint(s) k at angle q (rad, sim convention)."""
    return MOUNT_ZERO[k] + MOUNT_SIGN[k] * np.asarray(q, dtype=np.float64) * TICKS_PER_RAD


def q_for_shaft(shaft, k=slice(None)):
    """Joint angle(s) (rad, sim convention) of joint(s) k at these shaft ticks."""
    return (np.asarray(shaft, dtype=np.float64) - MOUNT_ZERO[k]) * MOUNT_SIGN[k] / TICKS_PER_RAD
