"""Scripted grasps (not baseline policies): a pinch-and-lift for the viewer and physics tests (two-link IK per
finger; it assumes a centred object), and a side grasp whose successes the `cpu_bc*` teachers clone (teacher/aux_bc.py)."""

from __future__ import annotations

import math

import numpy as np

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.sim import gripper, objects

_L1 = gripper.LINK_J11_J12
_L2 = gripper.TIP_CAPSULE_END  # J12 -> centre of the tip capsule's end sphere (0.073 m)
_R0 = gripper.BASE_RADIUS
J11_HEIGHT_M = gripper.PLATE_HEIGHT - gripper.PLATE_TO_J10 - gripper.LINK_J10_J11  # J11 pivot, fingers at J10 = 0


def finger_ik(radius, height):
    """(J11, J12) putting the tip sphere centre at (radius from the claw axis, height above the table), in the
    finger's plane (J10 = 0). Scalars or arrays of the same shape; out-of-reach targets get the straight finger."""
    dx, dz = np.asarray(radius) - _R0, J11_HEIGHT_M - np.asarray(height)
    c2 = (dx * dx + dz * dz - _L1 * _L1 - _L2 * _L2) / (2 * _L1 * _L2)
    t2 = -np.arccos(np.clip(c2, -1.0, 1.0))  # distal curls inward (negative)
    alpha = np.arctan2(_L2 * np.sin(-t2), _L1 + _L2 * np.cos(t2))
    return np.arctan2(dx, dz) + alpha, t2


class WaypointScript:
    """Callable q (n, 9) -> delta-theta (n, 9) that moves the joint targets along `waypoints` in `segments` of
    (steps, from waypoint, to waypoint), reaching each segment's end after 70 % of its steps, then holds the last."""

    waypoints: np.ndarray  # (k, 9) or (k, n, 9)
    segments: tuple[tuple[int, int, int], ...]

    def target(self, t: int) -> np.ndarray:
        start = 0
        for n, a, b in self.segments:
            if t < start + n:
                frac = min(1.0, (t - start + 1) / (0.7 * n))
                return self.waypoints[a] + (self.waypoints[b] - self.waypoints[a]) * frac
            start += n
        return self.waypoints[-1]

    def __call__(self, q: np.ndarray) -> np.ndarray:
        a = np.clip(self.target(self.t) - q, -spec.ACTION_BOUND_RAD, spec.ACTION_BOUND_RAD)
        self.t += 1
        return a


class PinchLiftScript(WaypointScript):
    """Approach (15 steps), pinch 4 mm into the side (20), lift (30), hold; the same targets for every env."""

    def __init__(self, object_radius: float, grasp_height: float, lift_m: float = 0.03):
        r = object_radius + gripper.TIP_CAPSULE_RADIUS  # tip sphere centre touching the side
        targets = ((r + 0.03, grasp_height), (r - 0.004, grasp_height), (r - 0.004, grasp_height + lift_m))
        self.waypoints = np.stack([np.tile([0.0, *finger_ik(x, z)], len(spec.FINGERS)) for x, z in targets])
        self.segments = ((15, 0, 0), (20, 0, 1), (30, 1, 2))
        self.t = 0


def support_distance(o: objects.ObjectSpec, direction_xy: np.ndarray) -> np.ndarray:
    """Horizontal distance from the object's centre to its surface along unit directions (n, 2), spawn pose."""
    ux, uy = np.abs(direction_xy[:, 0]), np.abs(direction_xy[:, 1])
    if o.mjcf_type == "box":
        return o.size[0] * ux + o.size[1] * uy
    if o.mjcf_type == "capsule":
        return o.size[1] * ux + o.size[0]
    return np.full(len(direction_xy), o.size[0])  # cylinder, sphere


def side_pose(object_xy: np.ndarray, clearance: np.ndarray, height: np.ndarray) -> np.ndarray:
    """Joint positions (n, 9) putting each tip centre on its finger's radial line through the object's centre,
    `clearance` (n, 3) from it and `height` (n, 3) above the table; J10 swings to the object's tangential offset."""
    q = np.zeros((object_xy.shape[0], spec.NUM_JOINTS))
    for i, phi in enumerate(spec.FINGER_BASE_ANGLES_RAD):
        c, s = math.cos(phi), math.sin(phi)
        d_r = object_xy[:, 0] * c + object_xy[:, 1] * s  # object centre in the finger's frame
        d_t = -object_xy[:, 0] * s + object_xy[:, 1] * c
        radius = d_r + clearance[:, i]
        depth = np.maximum(J11_HEIGHT_M - height[:, i], 0.0)
        swing = np.arcsin(np.clip(d_t / (gripper.LINK_J10_J11 + depth), -1.0, 1.0))
        j11, j12 = finger_ik(radius, height[:, i])
        q[:, 3 * i : 3 * i + 3] = np.column_stack([swing, j11, j12])
    return np.clip(q, spec.JOINT_LOWER, spec.JOINT_UPPER)


class SideGraspScript(WaypointScript):
    """Per env: hover beside the object (privileged), descend, squeeze as low as the tip reaches, lift, hold."""

    GAP_M = 0.02  # tip surface to the object's surface while hovering and descending
    SQUEEZE_M = 0.006  # tip target this far inside the surface: the servo error that holds the object
    LIFT_M = 0.035
    # (steps, from, to): start -> hover, hover -> beside, beside -> squeeze, squeeze -> lift, then hold
    segments = ((15, 0, 1), (15, 1, 2), (15, 2, 3), (30, 3, 4))

    def __init__(self, q0: np.ndarray, object_pos: np.ndarray, specs: list[objects.ObjectSpec]):
        dirs = np.array([[math.cos(p), math.sin(p)] for p in spec.FINGER_BASE_ANGLES_RAD])
        surface = np.stack([support_distance(o, dirs) for o in specs]) + gripper.TIP_CAPSULE_RADIUS  # (n, 3)
        top = np.array([o.rest_height * 2.0 for o in specs])[:, None].repeat(3, axis=1)
        # Squeeze at the object's centre height, or as low as the tip gets (finger_ik straightens the finger).
        grasp_z = np.maximum(object_pos[:, 2:3].repeat(3, axis=1), gripper.TIP_CAPSULE_RADIUS + 0.004)
        xy = object_pos[:, :2]
        self.waypoints = np.stack(
            [
                np.asarray(q0, dtype=np.float64),
                side_pose(xy, surface + self.GAP_M, top + 0.015),
                side_pose(xy, surface + self.GAP_M, grasp_z),
                side_pose(xy, surface - self.SQUEEZE_M, grasp_z),
                side_pose(xy, surface - self.SQUEEZE_M, grasp_z + self.LIFT_M),
            ]
        )  # (5, n, 9)
        assert self.waypoints.shape[1] == len(specs)
        self.t = 0
