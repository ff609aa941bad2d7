"""Domain randomization, Table II of the paper: one preset plus the functions that draw from it. Joint offsets and
object positions are drawn at every reset; friction, mass and actuator gains once per env (Sec. III-B).

Readings of the table:
- Mass: "x[0.5, 0.3]" is not an interval; we use x U[0.5, 1.5], the infill range a replica might be printed with.
- Friction: MuJoCo has one Coulomb coefficient per geom: one draw for the object, one for the tips, each [0.7, 1.3].
- Random force: a push for one control step at random times (`PushSchedule`); off for demos and lerobot-eval.
The fields past Table II (`ROBUSTNESS_FIELDS`) default to the paper's sim; `lab/robustness/` sets them one at a time."""

from __future__ import annotations

import copy
from dataclasses import dataclass, replace

import mujoco
import torch

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
    # --- beyond Table II (robustness); the defaults are the paper's sim exactly -----------------------------------
    # Load cells: reading = clip(gain x true + bias + noise, +-range), then the deadband (force.reading).
    force_gain: float = 1.0  # every load cell's scale error (x true force)
    force_bias_n: float = 0.0  # constant tare error of this size on each load cell, sign drawn per env and cell
    force_range_n: float = 0.0  # saturation: readings clipped to +-range (N); 0 = no saturation
    dead_force_sensor: int = -1  # index into spec.FINGERS of a load cell that reads 0 throughout; -1 = none
    # Joints: a reading is q + calibration offset + noise; the servo holds its target in that same (offset) frame.
    joint_calibration_rad: float = 0.0  # offset of this size on every joint, sign drawn per env and joint
    backlash_rad: float = 0.0  # gearbox play: the servo exerts no torque within +-backlash/2 of its target
    # Servos (the position gains are kp_scale/kv_scale above).
    torque_limit_scale: float = 1.0  # x the 4.1 N m stall torque: a lower current limit caps actuator force
    velocity_limit_rad_s: float = 0.0  # profile velocity: the setpoint moves at most this fast; 0 = no limit
    # Timing, in 20 Hz control steps / seconds.
    obs_latency_steps: int = 0  # the observation returned at step t is the one measured at t - k
    action_latency_steps: int = 0  # the target sent at step t reaches the servos at step t + k
    period_jitter_s: float = 0.0  # each step's target reaches the servos U[0, jitter] late (5 ms substeps)
    # Objects.
    object_size_scale: float = 1.0  # every object's dimensions x this (same density: mass x scale^3)
    hold_push_n: float = 0.0  # one push of this size (random 3-D direction, 50 ms) 0.5 s into each hold

    def __post_init__(self):
        # Every field past Table II is a size, count or scale (>= 0), except the dead load cell's index.
        for name in ("joint_noise_rad", "force_noise_n", *ROBUSTNESS_FIELDS):
            if name != "dead_force_sensor" and getattr(self, name) < 0:
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)}")
        for name in ("force_gain", "torque_limit_scale", "object_size_scale"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)}")
        if not -1 <= self.dead_force_sensor < spec.NUM_FORCES:
            raise ValueError(f"dead_force_sensor must be -1 or a finger index < {spec.NUM_FORCES}")
        if self.period_jitter_s > spec.CONTROL_DT:
            raise ValueError(f"period_jitter_s must be <= one control period ({spec.CONTROL_DT} s)")

    @property
    def substep_servo(self) -> bool:
        """Whether the servo model needs the control period stepped one physics substep at a time."""
        return bool(self.backlash_rad or self.velocity_limit_rad_s or self.period_jitter_s)


# The fields past Table II (from `force_gain` on); a dataset card lists them only where they differ from the default.
_NAMES = list(DomainRandomization.__dataclass_fields__)
ROBUSTNESS_FIELDS: tuple[str, ...] = tuple(_NAMES[_NAMES.index("force_gain") :])

PAPER_DR = DomainRandomization()
# The paper's randomization and sensor noise without the pushes: the pushes are a training-time robustness aid, and
# evaluation (lerobot-eval, the teacher eval) and demo collection run undisturbed trials.
EVAL_DR = replace(PAPER_DR, external_force=False)
CENTRED_EVAL_DR = replace(EVAL_DR, object_xy_m=0.0)  # the object centred: for scripted, centre-assuming motions
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
    """Per-env physics parameters, drawn once. Tensors of shape (num_envs,)."""

    object_friction: torch.Tensor
    robot_friction: torch.Tensor
    object_mass_scale: torch.Tensor
    kp_scale: torch.Tensor
    kv_scale: torch.Tensor

    def row(self, i: int) -> dict[str, float]:
        return {k: float(getattr(self, k)[i]) for k in self.__dataclass_fields__}

    def rows(self, sel, device: torch.device | str | None = None) -> PhysicsDraw:
        """The draws of envs `sel` (a slice or an index tensor), on `device` (default: where they are)."""
        rows = {k: getattr(self, k)[sel] for k in self.__dataclass_fields__}
        return PhysicsDraw(**{k: v if device is None else v.to(device) for k, v in rows.items()})


# The draws below are torch over the env axis, on the device of `seeds` (a uint64 array: the CPU; a tensor: its own
# device): the resets and the per-step draws run where the physics does.


def draw_physics(dr: DomainRandomization, seeds) -> PhysicsDraw:
    u = rng.uniform(seeds, rng.STREAM_DR, 0, 5)
    return PhysicsDraw(
        object_friction=rng.between(u[:, 0], *dr.object_friction),
        robot_friction=rng.between(u[:, 1], *dr.robot_friction),
        object_mass_scale=rng.between(u[:, 2], *dr.object_mass_scale),
        kp_scale=rng.log_uniform(u[:, 3], *dr.kp_scale),
        kv_scale=rng.log_uniform(u[:, 4], *dr.kv_scale),
    )


def draw_reset(dr: DomainRandomization, seeds, episode) -> tuple[torch.Tensor, torch.Tensor]:
    """Initial joint positions (n, 9) and object xy (n, 2) for the given envs' episode counters."""
    u = rng.uniform(seeds, rng.STREAM_RESET, episode, spec.NUM_JOINTS + 2)
    home = torch.as_tensor(spec.HOME_POSE, dtype=torch.float64, device=u.device)
    q0 = home[None, :] + rng.between(u[:, : spec.NUM_JOINTS], -dr.joint_offset_rad, dr.joint_offset_rad)
    xy = rng.between(u[:, spec.NUM_JOINTS :], -dr.object_xy_m, dr.object_xy_m)
    return q0, xy


def draw_push(dr: DomainRandomization, seeds, counter, key=None) -> tuple[torch.Tensor, torch.Tensor]:
    """A new push force (n, 3) in N and the number of control steps until the next push (n,)."""
    u = rng.uniform(seeds, rng.STREAM_PUSH, counter, 4, key)
    force = rng.between(u[:, :3], -dr.push_force_n, dr.push_force_n)
    period_s = rng.between(u[:, 3], *dr.push_period_s)
    steps = torch.ceil(period_s * spec.CONTROL_HZ).clamp_min(1).to(torch.int64)
    return force, steps


@dataclass
class SensorDraw:
    """Per-env sensor errors, drawn once: (num_envs, 3) force bias (N) and (num_envs, 9) joint offsets (rad)."""

    force_bias: torch.Tensor
    joint_offset: torch.Tensor

    def rows(self, sel: slice | torch.Tensor) -> SensorDraw:
        return SensorDraw(self.force_bias[sel], self.joint_offset[sel])

    def measured(self, q: torch.Tensor, sel: slice | torch.Tensor = slice(None)) -> torch.Tensor:
        """Joint positions of envs `sel` in the joints' measured frame: q + their calibration offset (a copy)."""
        return q + self.joint_offset[sel]


def _signs(u: torch.Tensor) -> torch.Tensor:
    return torch.where(u < 0.5, -1.0, 1.0).to(torch.float64)


def draw_sensors(dr: DomainRandomization, seeds) -> SensorDraw:
    """Each load cell's bias and each joint's calibration offset: the configured size, a random sign per env."""
    u = rng.uniform(seeds, rng.STREAM_SENSOR, 0, spec.NUM_FORCES + spec.NUM_JOINTS)
    return SensorDraw(
        force_bias=dr.force_bias_n * _signs(u[:, : spec.NUM_FORCES]),
        joint_offset=dr.joint_calibration_rad * _signs(u[:, spec.NUM_FORCES :]),
    )


def draw_hold_push(dr: DomainRandomization, seeds, episode) -> torch.Tensor:
    """(n, 3) the hold push of each env's episode: `hold_push_n` in a uniformly random 3-D direction."""
    g = rng.normal(seeds, rng.STREAM_HOLD_PUSH, episode, 3)
    return dr.hold_push_n * g / g.square().sum(1, keepdim=True).sqrt().clamp_min(1e-12)


def draw_jitter_substeps(dr: DomainRandomization, seeds, counter, substeps: int) -> torch.Tensor:
    """(n,) substeps by which this control step's target arrives late: U[0, jitter], quantized to the timestep."""
    dt = spec.CONTROL_DT / substeps
    u = rng.uniform(seeds, rng.STREAM_JITTER, counter, 1)[:, 0]
    return torch.floor(u * (dr.period_jitter_s / dt + 1)).clamp_max(substeps - 1).to(torch.int64)


# The model fields Table II writes (`write_physics_draw`); MuJoCo derives constants from the mass and inertia.
PHYSICS_DRAW_FIELDS = ("geom_friction", "body_mass", "body_inertia", "actuator_gainprm", "actuator_biasprm")
TORQUE_LIMIT_FIELD = "actuator_forcerange"


@dataclass(frozen=True)
class DrawTargets:
    """Where Table II lands in the gripper-and-object model (ids shared by every object's model)."""

    object_geom: int
    tip_geoms: tuple[int, ...]
    object_body: int

    @classmethod
    def of(cls, m: mujoco.MjModel) -> DrawTargets:
        tips = tuple(m.geom(f"{f}_tipgeom").id for f in spec.FINGERS)
        return cls(object_geom=m.geom("object_geom").id, tip_geoms=tips, object_body=m.body("object").id)


def write_physics_draw(
    fields: dict[str, torch.Tensor], at: DrawTargets, draw: PhysicsDraw, torque_limit_scale: float = 1.0
) -> None:
    """Table II's draw written in place into per-env rows (n, *MjModel shape) of model fields, for both backends.
    MuJoCo's position actuator: gain kp, bias -kp q - kv qdot."""
    f, scale = fields, draw.object_mass_scale
    f["geom_friction"][:, at.object_geom, 0] = draw.object_friction
    f["geom_friction"][:, list(at.tip_geoms), 0] = draw.robot_friction[:, None]
    f["body_mass"][:, at.object_body] *= scale
    f["body_inertia"][:, at.object_body] *= scale[:, None]
    kp = f["actuator_gainprm"][:, :, 0] * draw.kp_scale[:, None]
    kv = -f["actuator_biasprm"][:, :, 2] * draw.kv_scale[:, None]
    f["actuator_gainprm"][:, :, 0] = kp
    f["actuator_biasprm"][:, :, 1] = -kp
    f["actuator_biasprm"][:, :, 2] = -kv
    if torque_limit_scale != 1.0:
        f[TORQUE_LIMIT_FIELD] *= torque_limit_scale


def apply_physics_draw(
    template: mujoco.MjModel, draw: PhysicsDraw, i: int, torque_limit_scale: float = 1.0
) -> mujoco.MjModel:
    """A copy of an object's model with env i's Table II draw written in and its derived constants recomputed."""
    m = copy.copy(template)
    names = (*PHYSICS_DRAW_FIELDS, TORQUE_LIMIT_FIELD)
    fields = {k: torch.from_numpy(getattr(m, k))[None] for k in names}  # the model's own memory
    write_physics_draw(fields, DrawTargets.of(m), draw.rows(slice(i, i + 1)), torque_limit_scale)
    mujoco.mj_setConst(m, mujoco.MjData(m))  # mass-dependent constants (e.g. constraint scaling)
    return m


class PushSchedule:
    """Table II's random force: U[-0.3, 0.3] N per axis for one control step, U[0, 10] s apart (a held force would
    roll spheres and capsules off the table). It only decides, as masks; the env writes the forces."""

    def __init__(self, dr: DomainRandomization, seeds: torch.Tensor):
        n = len(seeds)
        self.dr, self.seeds = dr, seeds
        self.counter = torch.zeros(n, dtype=torch.int64, device=seeds.device)  # pushes drawn so far, per env
        self.steps_to_push = torch.zeros(n, dtype=torch.int64, device=seeds.device)
        self.pushing = torch.zeros(n, dtype=torch.bool, device=seeds.device)  # a push is under way this step
        self.key = rng.stream_key(seeds, rng.STREAM_PUSH)

    def reset(self, ids: torch.Tensor) -> None:
        """A new episode: no push under way, and the time to the first one drawn."""
        self.pushing[ids] = False
        _, steps = draw_push(self.dr, self.seeds[ids], self.counter[ids])
        self.counter[ids] += 1
        self.steps_to_push[ids] = steps

    def step(self) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Advance one control step. Returns (envs whose push ends now, envs whose push starts now, the forces
        (n, 3) in N of those starting; rows of the others are not used), as masks over the envs."""
        ended = self.pushing
        self.steps_to_push -= 1
        due = self.steps_to_push <= 0
        # every env's next draw, kept where one is due: the same numbers an index list of the due envs would draw
        force, steps = draw_push(self.dr, self.seeds, self.counter, self.key)
        self.counter += due
        self.steps_to_push = torch.where(due, steps, self.steps_to_push)
        self.pushing = due
        return ended, due, force
