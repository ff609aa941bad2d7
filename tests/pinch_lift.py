"""The scripted pinch-and-lift as the physics tests run it: a reset `BatchedGraspEnv`, the same targets for every env."""

from __future__ import annotations

import numpy as np

from lerobot_blindgrasp.sim.scripted import PinchLiftScript


def run_pinch_lift(
    env, steps: int, object_radius: float = 0.03, grasp_height: float = 0.045, lift_m: float = 0.03
):
    """Pinch a reset `BatchedGraspEnv` for `steps` steps: lifts (steps, N), clean forces (steps, N, 3), last info."""
    script = PinchLiftScript(object_radius, grasp_height, lift_m)
    lifts, forces = [], []
    for _ in range(steps):
        _, _, _, _, info = env.step(script(env.joint_positions()))
        lifts.append(info["lift"].copy())
        forces.append(info["uniaxial_force"].copy())
    return np.array(lifts), np.array(forces), info
