"""Pre-grasp start states: a training-time exploration aid for the objects the teacher never learns to lift.

Issue #9 measured why the `cpu` teacher never lifts the small capsule: it closes its tips on the capsule from above
the equator and presses it into the table, and no exploration in 34 M steps found the lower grasp
(docs/results/teacher_cpu_v4.md). That grasp is narrow. The tip sphere's centre can get no lower than ~2.7 cm
next to a 2 cm-radius capsule, and only with the finger almost straight, so a policy that closes from the
paper's start pose (0, pi/3, 0) lands on top.

With `PregraspStarts`, a share of the training resets of the listed objects starts instead with every finger
almost straight and its tip low beside the object, clear of it by a random gap. From there, closing lifts, and the
critic learns that such states are worth a lot. Exploration from the paper's start pose then only has to reach
them (the reference-state-initialization idea of DeepMimic, Peng et al. 2018). Evaluation, demo collection and
the `paper` preset never use it: it is a field of `GraspEnvConfig`, None by default. Switched on at iteration 350
of the shipped run it changed nothing held out; from scratch it trailed the shipped run at iteration 371
(docs/results/teacher_cpu_pregrasp.md).

Geometry, in each finger's frame (x radial from the claw axis, y tangential, z up; `sim/gripper.py`):
- J10 (axis +x) swings the finger's plane sideways; J11 and J12 bend within it.
- The tip goes on the finger's radial line through the object's centre, at horizontal distance
  bounding radius + tip radius + gap from the centre, so that no part of the finger starts inside the object.
- Within the (swung) plane, the finger is extended to `extension` x its full reach (J11 pivot to tip centre).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.sim import gripper, objects, rng, scripted

# The objects whose training success stayed lowest in the shipped `cpu` run (docs/results/teacher_cpu_v3_eval):
# every small object and the medium capsule.
HARD_OBJECTS: tuple[str, ...] = (
    *(n for n in objects.PAPER_OBJECTS if n.endswith("_small")),
    "capsule_medium",
)


@dataclass(frozen=True)
class PregraspStarts:
    fraction: float = 0.5  # share of the listed objects' resets that start in a pre-grasp pose
    objects: tuple[str, ...] = HARD_OBJECTS
    gap_m: tuple[float, float] = (0.005, 0.03)  # tip surface to the object's bounding circle, uniform
    extension: tuple[float, float] = (0.93, 0.995)  # J11-to-tip distance / (L11 + L12), uniform

    def __post_init__(self):
        if not 0.0 <= self.fraction <= 1.0:
            raise ValueError(f"pregrasp fraction must be in [0, 1], got {self.fraction}")
        unknown = sorted(set(self.objects) - set(objects.CATALOGUE))
        if unknown:
            raise ValueError(f"pregrasp objects not in the catalogue: {unknown}")
        if not (0 < self.gap_m[0] <= self.gap_m[1]) or not (0 < self.extension[0] <= self.extension[1] <= 1):
            raise ValueError(f"bad pregrasp ranges: gap {self.gap_m}, extension {self.extension}")


def bounding_radius(o: objects.ObjectSpec) -> float:
    """Horizontal radius of the smallest circle about the object's centre that holds it in its spawn pose."""
    if o.mjcf_type == "box":
        return math.hypot(o.size[0], o.size[1])
    if o.mjcf_type == "capsule":  # lying along x: half-length plus the end cap
        return o.size[0] + o.size[1]
    return o.size[0]  # cylinder (upright) and sphere


def pregrasp_pose(object_xy: np.ndarray, bound_r: np.ndarray, u: np.ndarray, cfg: PregraspStarts) -> np.ndarray:
    """Joint positions (n, 9) for objects at `object_xy` (n, 2) of bounding radius `bound_r` (n,), from uniform
    draws `u` (n, 6): a gap and an extension per finger."""
    clearance = np.empty((object_xy.shape[0], len(spec.FINGERS)))
    height = np.empty_like(clearance)
    for i, phi in enumerate(spec.FINGER_BASE_ANGLES_RAD):
        d_r = object_xy[:, 0] * math.cos(phi) + object_xy[:, 1] * math.sin(phi)  # object centre, finger's radial axis
        clearance[:, i] = bound_r + gripper.TIP_CAPSULE_RADIUS + rng.between(u[:, 2 * i], *cfg.gap_m)
        ext = rng.between(u[:, 2 * i + 1], *cfg.extension)
        dx = d_r + clearance[:, i] - gripper.BASE_RADIUS  # J11 pivot to the tip centre, horizontally
        # the tip hangs as low as `ext` x the finger's full reach allows at that radius
        height[:, i] = scripted.J11_HEIGHT_M - np.sqrt(np.maximum((ext * scripted.FINGER_REACH_M) ** 2 - dx**2, 0.0))
    return scripted.side_pose(object_xy, clearance, height)
