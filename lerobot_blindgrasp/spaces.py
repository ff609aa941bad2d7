"""The spec as a lerobot-eval env sees it (`--env.type=blindgrasp` and `blindgrasp_real`): features and gymnasium
spaces. The envs observe `{"agent_pos": o_t}`, which LeRobot's `preprocess_observation` turns into
`observation.state`, and take absolute joint targets. No MuJoCo here: LeRobot imports the env configs to parse.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
from lerobot.configs import FeatureType, PolicyFeature
from lerobot.utils.constants import ACTION, OBS_STATE

from lerobot_blindgrasp import spec

AGENT_POS = "agent_pos"


def env_features() -> dict[str, PolicyFeature]:
    """`EnvConfig.features`: the 9 joint targets out, the 12-d state in."""
    return {
        ACTION: PolicyFeature(type=FeatureType.ACTION, shape=(spec.ACTION_DIM,)),
        AGENT_POS: PolicyFeature(type=FeatureType.STATE, shape=(spec.STATE_DIM,)),
    }


def env_features_map() -> dict[str, str]:
    """`EnvConfig.features_map`: env keys -> policy keys."""
    return {ACTION: ACTION, AGENT_POS: OBS_STATE}


def observation_space() -> gym.spaces.Dict:
    return gym.spaces.Dict({AGENT_POS: gym.spaces.Box(-np.inf, np.inf, shape=(spec.STATE_DIM,), dtype=np.float32)})


def action_space() -> gym.spaces.Box:
    """Absolute joint targets within the joint limits. A target beyond them is not refused: the sim and the robot
    clip it, as they clip every step to +-0.3 rad."""
    return gym.spaces.Box(
        spec.JOINT_LOWER.astype(np.float32), spec.JOINT_UPPER.astype(np.float32), dtype=np.float32
    )


def observation(state: np.ndarray) -> dict[str, np.ndarray]:
    """One env's observation from its 12-d state (float32, a copy)."""
    return {AGENT_POS: np.array(state, dtype=np.float32)}
