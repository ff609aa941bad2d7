"""Success and termination: when an episode counts as a grasp, and when it ends.

- Success (paper Sec. IV-A, the same test in simulation, teacher evaluation and the real protocol): the object
  lifted at least `spec.SUCCESS_LIFT_M` (1.5 cm) above its resting height and held there for `spec.SUCCESS_HOLD_S`
  (1 s) without a break. It latches: a later drop does not undo it.
- Termination (Sec. III-B): the object leaves the 10 cm workspace around the gripper's centre (`d_xy`, eq. 2), or
  its physics went unstable (the env resets it).
- Truncation: the episode's time runs out (10 s) before it terminated.
"""

from __future__ import annotations

import numpy as np

from lerobot_blindgrasp import spec


def is_lifted(lift: np.ndarray) -> np.ndarray:
    """The object is at least SUCCESS_LIFT_M above its resting height."""
    return lift >= spec.SUCCESS_LIFT_M


def held_steps(previous: np.ndarray, lift: np.ndarray) -> np.ndarray:
    """Consecutive control steps lifted, counting this one (0 once it is no longer lifted)."""
    return np.where(is_lifted(lift), previous + 1, 0)


def is_success(held: np.ndarray) -> np.ndarray:
    """Held lifted for SUCCESS_HOLD_S (20 control steps)."""
    return held >= spec.SUCCESS_HOLD_STEPS


def out_of_workspace(d_xy: np.ndarray, radius_m: float = spec.WORKSPACE_RADIUS_M) -> np.ndarray:
    """The termination condition: the object's planar distance from the gripper centre exceeds the workspace."""
    return d_xy > radius_m


def timed_out(episode_length: np.ndarray, max_steps: int, terminated: np.ndarray) -> np.ndarray:
    """Truncation: the episode reached its length without terminating."""
    return (episode_length >= max_steps) & ~terminated
