"""How the twin's servos sit on the fingers: shaft ticks at the sim's q = 0 and the sign of each servo.

Deliberately messy, as after assembly (the same layout as the test rig's), so that `lerobot-calibrate` has to find
Drive_Mode and Homing_Offset itself: the twin never tells the host its mounting.
"""

from __future__ import annotations

import math

import numpy as np

from lerobot_blindgrasp import spec

TICKS_PER_RAD = 4096 / (2 * math.pi)
MOUNT_ZERO = np.array([1100.0 + 237.0 * k for k in range(spec.NUM_JOINTS)])  # spec.JOINT_NAMES order
MOUNT_SIGN = np.array([1, -1, 1, -1, 1, -1, 1, 1, -1], dtype=np.float64)


def shaft_for_q(q, k=slice(None)):
    """Shaft ticks (before Drive_Mode/Homing_Offset) of joint(s) k at angle q (rad, sim convention)."""
    return MOUNT_ZERO[k] + MOUNT_SIGN[k] * np.asarray(q, dtype=np.float64) * TICKS_PER_RAD


def q_for_shaft(shaft, k=slice(None)):
    return (np.asarray(shaft, dtype=np.float64) - MOUNT_ZERO[k]) * MOUNT_SIGN[k] / TICKS_PER_RAD
