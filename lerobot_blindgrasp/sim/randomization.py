"""Domain randomization, Table II of the paper, as one preset plus the functions that draw from it.

Joint offsets and object positions are drawn at every reset; friction, mass and actuator gains once per env at
construction (paper, Sec. III-B). Deviations and readings of the table:
- Mass: the table's "x[0.5, 0.3]" is not an interval (lower > upper). We use x U[0.5, 1.5], symmetric about the
  nominal 3D-printed mass, which spans the infill settings a replica might be printed with (10-40 %).
- Static vs dynamic friction: MuJoCo has one Coulomb coefficient per geom (no static/dynamic split), so we draw one
  coefficient per object and one for the fingertips, each from [0.7, 1.3]. MuJoCo combines a pair with max().
- Random force: each env pushes its object with a force whose components are U[-0.3, 0.3] N for one control step
  (50 ms) "at randomly selected times", U[0, 10] s apart. A force held between pushes rolls spheres and capsules
  off the table (see `BatchedGraspEnv._update_pushes`). Off for demo collection and lerobot-eval.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.sim import rng


@dataclass(frozen=True)
class DomainRandomization:
    joint_offset_rad: float = spec.RESET_JOINT_NOISE_RAD  # + U[-pi/9, pi/9] per joint
    object_xy_m: float = spec.OBJECT_XY_RANGE_M  # U[-3, 3] cm
    object_friction: tuple[float, float] = (0.7, 1.3)
    robot_friction: tuple[float, float] = (0.7, 1.3)
    object_mass_scale: tuple[float, float] = (0.5, 1.5)
    kp_scale: tuple[float, float] = (0.3, 3.0)  # log-uniform
    kv_scale: tuple[float, float] = (0.75, 1.5)  # log-uniform
    push_force_n: float = 0.3
    push_period_s: tuple[float, float] = (0.0, 10.0)
    external_force: bool = True
    joint_noise_rad: float = spec.JOINT_NOISE_STD_RAD
    force_noise_n: float = spec.FORCE_NOISE_STD_N


PAPER_DR = DomainRandomization()
# The paper's randomization and sensor noise without the pushes: the pushes are a training-time robustness aid, and
# evaluation (lerobot-eval, the teacher eval) and demo collection run undisturbed trials.
EVAL_DR = replace(PAPER_DR, external_force=False)
# No randomization at all: for physics tests and scripted checks.
NO_DR = DomainRandomization(
    joint_offset_rad=0.0,
    object_xy_m=0.0,
    object_friction=(1.0, 1.0),
    robot_friction=(1.0, 1.0),
    object_mass_scale=(1.0, 1.0),
    kp_scale=(1.0, 1.0),
    kv_scale=(1.0, 1.0),
    external_force=False,
    joint_noise_rad=0.0,
    force_noise_n=0.0,
)


@dataclass
class PhysicsDraw:
    """Per-env physics parameters, drawn once. Arrays of shape (num_envs,)."""

    object_friction: np.ndarray
    robot_friction: np.ndarray
    object_mass_scale: np.ndarray
    kp_scale: np.ndarray
    kv_scale: np.ndarray

    def row(self, i: int) -> dict[str, float]:
        return {k: float(getattr(self, k)[i]) for k in self.__dataclass_fields__}


def draw_physics(dr: DomainRandomization, seeds: np.ndarray) -> PhysicsDraw:
    u = rng.uniform(seeds, rng.STREAM_DR, 0, 5)
    return PhysicsDraw(
        object_friction=rng.between(u[:, 0], *dr.object_friction),
        robot_friction=rng.between(u[:, 1], *dr.robot_friction),
        object_mass_scale=rng.between(u[:, 2], *dr.object_mass_scale),
        kp_scale=rng.log_uniform(u[:, 3], *dr.kp_scale),
        kv_scale=rng.log_uniform(u[:, 4], *dr.kv_scale),
    )


def draw_reset(dr: DomainRandomization, seeds: np.ndarray, episode: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Initial joint positions (n, 9) and object xy (n, 2) for the given envs' episode counters."""
    u = rng.uniform(seeds, rng.STREAM_RESET, episode, spec.NUM_JOINTS + 2)
    q0 = spec.HOME_POSE[None, :] + rng.between(u[:, : spec.NUM_JOINTS], -dr.joint_offset_rad, dr.joint_offset_rad)
    xy = rng.between(u[:, spec.NUM_JOINTS :], -dr.object_xy_m, dr.object_xy_m)
    return q0, xy


def draw_push(dr: DomainRandomization, seeds: np.ndarray, counter: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A new push force (n, 3) in N and the number of control steps until the next push (n,)."""
    u = rng.uniform(seeds, rng.STREAM_PUSH, counter, 4)
    force = rng.between(u[:, :3], -dr.push_force_n, dr.push_force_n)
    period_s = rng.between(u[:, 3], *dr.push_period_s)
    steps = np.maximum(1, np.ceil(period_s * spec.CONTROL_HZ)).astype(np.int64)
    return force, steps
