"""A scripted pinch-and-lift, for physics tests and the sim demo (not a baseline policy).

Each finger moves in its radial-vertical plane. Two-link inverse kinematics (proximal 0.068 m, distal to the tip
sphere 0.073 m) places the tip sphere on the object's side at mid-height, presses 4 mm past the surface, then
raises it by `lift_m` at the same radius. It assumes the object is centred, so use it without the xy offset.
"""

from __future__ import annotations

import numpy as np

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.sim import gripper

_L1 = gripper.LINK_J11_J12
_L2 = gripper.TIP_CAPSULE_END  # J12 -> centre of the tip capsule's end sphere (0.073 m)
_R0 = gripper.BASE_RADIUS
J11_HEIGHT_M = gripper.PLATE_HEIGHT - gripper.PLATE_TO_J10 - gripper.LINK_J10_J11  # J11 pivot, fingers at J10 = 0
FINGER_REACH_M = _L1 + _L2  # J11 pivot to the tip sphere's centre, finger straight


def finger_ik(radius, height):
    """(J11, J12) putting the tip sphere centre at (radius from the claw axis, height above the table), in the
    finger's plane (J10 = 0). Scalars or arrays of the same shape; out-of-reach targets get the straight finger."""
    dx, dz = np.asarray(radius) - _R0, J11_HEIGHT_M - np.asarray(height)
    c2 = (dx * dx + dz * dz - _L1 * _L1 - _L2 * _L2) / (2 * _L1 * _L2)
    t2 = -np.arccos(np.clip(c2, -1.0, 1.0))  # distal curls inward (negative)
    alpha = np.arctan2(_L2 * np.sin(-t2), _L1 + _L2 * np.cos(t2))
    return np.arctan2(dx, dz) + alpha, t2


def pinch_lift_waypoints(object_radius: float, grasp_height: float, lift_m: float = 0.03, squeeze_m: float = 0.004):
    """Joint waypoints (approach, pinch, lift) for all three fingers, shape (3, 9)."""
    tip_r = gripper.TIP_CAPSULE_RADIUS
    out = []
    for r, z in (
        (object_radius + tip_r + 0.03, grasp_height),
        (object_radius + tip_r - squeeze_m, grasp_height),
        (object_radius + tip_r - squeeze_m, grasp_height + lift_m),
    ):
        j11, j12 = finger_ik(r, z)
        out.append(np.tile([0.0, j11, j12], len(spec.FINGERS)))
    return np.stack(out)


class PinchLiftScript:
    """Callable q (N, 9) -> delta-theta (N, 9) following approach (15 steps), pinch (20), lift (30), hold."""

    def __init__(self, object_radius: float, grasp_height: float, lift_m: float = 0.03):
        self.waypoints = pinch_lift_waypoints(object_radius, grasp_height, lift_m)
        self.segments = ((15, 0, 0), (20, 0, 1), (30, 1, 2))
        self.t = 0

    def target(self, t: int) -> np.ndarray:
        start = 0
        for n, a, b in self.segments:
            if t < start + n:
                frac = min(1.0, (t - start + 1) / (0.7 * n))
                return self.waypoints[a] + (self.waypoints[b] - self.waypoints[a]) * frac
            start += n
        return self.waypoints[-1]

    def __call__(self, q: np.ndarray) -> np.ndarray:
        a = np.clip(self.target(self.t)[None, :] - q, -spec.ACTION_BOUND_RAD, spec.ACTION_BOUND_RAD)
        self.t += 1
        return a


def run_pinch_lift(env, steps: int, object_radius: float = 0.03, grasp_height: float = 0.045, lift_m: float = 0.03):
    """Drive a reset `BatchedGraspEnv` with the pinch for `steps` control steps. Returns the per-step object lift
    (steps, N), the noise-free uniaxial forces (steps, N, 3) and the last step's info."""
    script = PinchLiftScript(object_radius, grasp_height, lift_m)
    lifts, forces = [], []
    for _ in range(steps):
        _, _, _, _, info = env.step(script(env.joint_positions()))
        lifts.append(info["lift"].copy())
        forces.append(info["uniaxial_force"].copy())
    return np.array(lifts), np.array(forces), info
