"""Human hand -> gripper joints (docs/hardware.md, "Retargeting"). Flexion maps linearly from the operator's
[open hand, fist] onto [open_pose, closed_pose], clipped to that segment (a hand cannot over-drive the claw);
spread maps relative to the open hand with a gain in rad/rad, since neither pose pins spread.
"""

from __future__ import annotations

import numpy as np

from lerobot_blindgrasp import spec

# Gripper joint (spec.JOINT_NAMES order) -> (kind, glove ergonomics channels averaged): index -> FF, middle -> MF,
# thumb -> TH; spread -> J*0, MCP flexion -> J*1, mean of PIP and DIP flexion -> J*2.
CHANNELS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("spread", ("IndexMCPSpread",)),
    ("flex", ("IndexMCPStretch",)),
    ("flex", ("IndexPIPStretch", "IndexDIPStretch")),
    ("spread", ("MiddleMCPSpread",)),
    ("flex", ("MiddleMCPStretch",)),
    ("flex", ("MiddlePIPStretch", "MiddleDIPStretch")),
    ("spread", ("ThumbMCPSpread",)),
    ("flex", ("ThumbMCPStretch",)),
    ("flex", ("ThumbPIPStretch", "ThumbDIPStretch")),
)
REQUIRED_KEYS: set[str] = {k for _, keys in CHANNELS for k in keys}
IS_FLEX = np.array([kind == "flex" for kind, _ in CHANNELS])


def required_keys(spread_gain) -> set[str]:
    """The channels the retargeting reads with these spread gains (ff, mf, th). A finger whose spread gain is 0 keeps
    its abduction at the open pose, so its spread channel is not read: the way around a publisher that drops it."""
    gains = np.repeat(np.asarray(spread_gain, dtype=np.float64), 3)
    return {k for (kind, keys), g in zip(CHANNELS, gains, strict=True) if kind == "flex" or g != 0 for k in keys}


def glove_features(ergonomics: dict[str, float], required: set[str] = REQUIRED_KEYS) -> np.ndarray:
    """One value (deg) per gripper joint. A channel outside `required` (a spread with gain 0) is not used and reads
    0; a required one that is missing raises KeyError."""
    return np.array([np.mean([ergonomics[k] if k in required else 0.0 for k in keys]) for _, keys in CHANNELS])


def retarget(
    features_deg: np.ndarray,
    open_deg: np.ndarray,
    fist_deg: np.ndarray,
    open_pose: np.ndarray,
    closed_pose: np.ndarray,
    spread_gain: np.ndarray,
) -> np.ndarray:
    """Joint targets (rad) for the gripper, inside spec's joint limits."""
    span = np.where(IS_FLEX, fist_deg - open_deg, 1.0)
    closure = np.clip((features_deg - open_deg) / span, 0.0, 1.0)
    flex_q = open_pose + closure * (closed_pose - open_pose)
    gain = np.repeat(np.asarray(spread_gain, dtype=np.float64), 3)
    spread_q = open_pose + gain * np.radians(features_deg - open_deg)
    return np.clip(np.where(IS_FLEX, flex_q, spread_q), spec.JOINT_LOWER, spec.JOINT_UPPER)


DEFAULT_OPEN_POSE = spec.HOME_POSE.tolist()  # the paper's start pose (0, pi/3, 0): open claw
DEFAULT_CLOSED_POSE = np.tile([0.0, -0.35, -0.6], spec.NUM_FORCES).tolist()  # tips meet low near the claw axis
