"""Success and termination, over the env axis, with operators only so the twin's numpy state (`twin/physics.py`)
goes through them too.

- Success (Sec. IV-A; sim, teacher eval and the real protocol alike): lifted >= `spec.SUCCESS_LIFT_M` (1.5 cm) for
  `spec.SUCCESS_HOLD_S` (1 s) without a break; it latches.
- Termination (Sec. III-B): the object leaves the 10 cm workspace (`d_xy`, eq. 2), or its physics went unstable."""

from __future__ import annotations

from lerobot_blindgrasp import spec


def held_steps(previous, lift):
    """Consecutive control steps lifted >= SUCCESS_LIFT_M, counting this one (0 once it is no longer lifted)."""
    return (previous + 1) * (lift >= spec.SUCCESS_LIFT_M)


def is_success(held):
    """Held lifted for SUCCESS_HOLD_S (20 control steps)."""
    return held >= spec.SUCCESS_HOLD_STEPS


def out_of_workspace(d_xy, radius_m: float = spec.WORKSPACE_RADIUS_M):
    """The termination condition: the object's planar distance from the gripper centre exceeds the workspace."""
    return d_xy > radius_m


def timed_out(episode_length, max_steps: int, terminated):
    return (episode_length >= max_steps) & ~terminated
