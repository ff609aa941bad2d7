"""The shared contracts of lerobot_blindgrasp, defined once: joint order, limits, servo IDs, control rate, action
bound, observation layouts, the success rule and the seed ranges. Nothing else defines them.

Joint conventions (the sim's zero is the hardware calibration target, see `robots/` for the reference pose):
- Fingers FF, MF, TH (D'Claw naming) sit 120 deg apart on a 6 cm circle; each has J*0 (abduction), J*1 (proximal
  flexion) and J*2 (distal flexion), servo IDs 10,11,12 / 20,21,22 / 30,31,32.
- q = 0 everywhere: every finger hangs straight down from the plate.
- J*1, J*2 > 0 swing the fingertip *away* from the claw axis (opening). With this sign the paper's start pose
  (0, pi/3, 0) is an open claw: proximal link tilted 60 deg outward, distal link straight.
- J*0 > 0 moves the fingertip counter-clockwise about the claw axis, seen from above.
"""

from __future__ import annotations

import itertools
import math

import numpy as np

# --- Joints ------------------------------------------------------------------------------------------------------
FINGERS: tuple[str, ...] = ("ff", "mf", "th")
# Finger base angle about the claw axis (world z, seen from above), D'Claw layout.
FINGER_BASE_ANGLES_RAD: tuple[float, ...] = (math.radians(60.0), math.radians(-60.0), math.radians(180.0))
JOINT_NAMES: tuple[str, ...] = tuple(f"{f}_j{10 * (i + 1) + k}" for i, f in enumerate(FINGERS) for k in range(3))
SERVO_IDS: tuple[int, ...] = tuple(10 * (i + 1) + k for i in range(len(FINGERS)) for k in range(3))
NUM_JOINTS = len(JOINT_NAMES)  # 9

# Allowed joint range (rad), per joint kind (abduction, proximal, distal). Targets are clipped to it (sim and real)
# and r_l (eq. 5) penalizes measured positions outside it.
_KIND_LIMITS = ((-0.48, 0.48), (-1.57, 1.57), (-1.8, 1.8))
JOINT_LOWER = np.array([_KIND_LIMITS[k][0] for _ in FINGERS for k in range(3)], dtype=np.float64)
JOINT_UPPER = np.array([_KIND_LIMITS[k][1] for _ in FINGERS for k in range(3)], dtype=np.float64)
# The hard stops (MJCF joint range) sit a little outside the allowed range, so that r_l can be violated and seen.
HARD_STOP_MARGIN_RAD = 0.2

# Paper, Sec. III-B: start pose (0, pi/3, 0) per finger, plus U(-pi/9, pi/9) per joint at each reset.
HOME_POSE = np.tile(np.array([0.0, math.pi / 3.0, 0.0]), len(FINGERS))
RESET_JOINT_NOISE_RAD = math.pi / 9.0

# --- Control -----------------------------------------------------------------------------------------------------
CONTROL_HZ = 20
CONTROL_DT = 1.0 / CONTROL_HZ
# Paper: a_t = delta-theta in R^9, clipped to +-0.3 rad. LeRobot-native action = absolute target q_now + delta.
ACTION_BOUND_RAD = 0.3
EPISODE_S = 10.0
EPISODE_STEPS = int(round(EPISODE_S * CONTROL_HZ))  # 200
DEMO_EPISODE_S = 5.0

# --- Fingertip force sensing -------------------------------------------------------------------------------------
FORCE_SENSOR_NAMES: tuple[str, ...] = tuple(f"{f}_tip" for f in FINGERS)
NUM_FORCES = len(FORCE_SENSOR_NAMES)
# |f| below this is reported as 0 (sim and real), and f above it counts as a contact (paper: 0.1 N).
FORCE_THRESHOLD_N = 0.1
JOINT_NOISE_STD_RAD = 0.005
FORCE_NOISE_STD_N = 0.5

# --- Student observation o_t in R^12 and action, as LeRobot feature names ----------------------------------------
STATE_KEY = "observation.state"
ACTION_KEY = "action"
JOINT_FEATURE_NAMES: tuple[str, ...] = tuple(f"{j}.pos" for j in JOINT_NAMES)
FORCE_FEATURE_NAMES: tuple[str, ...] = tuple(f"{s}.force" for s in FORCE_SENSOR_NAMES)
STATE_NAMES: tuple[str, ...] = JOINT_FEATURE_NAMES + FORCE_FEATURE_NAMES
ACTION_NAMES: tuple[str, ...] = JOINT_FEATURE_NAMES  # absolute joint targets (rad)
STATE_DIM = len(STATE_NAMES)  # 12
ACTION_DIM = len(ACTION_NAMES)  # 9
STATE_JOINT_SLICE = slice(0, NUM_JOINTS)
STATE_FORCE_SLICE = slice(NUM_JOINTS, NUM_JOINTS + NUM_FORCES)


def dataset_features() -> dict:
    """LeRobotDataset features shared by sim demos and glove demos (state-only, no video)."""
    return {
        STATE_KEY: {"dtype": "float32", "shape": (STATE_DIM,), "names": list(STATE_NAMES)},
        ACTION_KEY: {"dtype": "float32", "shape": (ACTION_DIM,), "names": list(ACTION_NAMES)},
    }


# --- Privileged observation (teacher only) -----------------------------------------------------------------------
# (name, size) in order. `privileged_parts` is the only way the sim builds the vector (`sim/observations.py`),
# and a shipped teacher's checkpoint records this layout, so a change here is refused at load time.
PRIVILEGED_LAYOUT: tuple[tuple[str, int], ...] = (
    ("joint_pos", NUM_JOINTS),  # measured: with joint noise
    ("joint_vel", NUM_JOINTS),
    ("fingertip_pos", 3 * NUM_FORCES),  # world frame, relative to the claw centre on the table
    ("fingertip_quat", 4 * NUM_FORCES),  # wxyz
    ("object_pos", 3),  # relative to the claw centre on the table
    ("object_quat", 4),  # wxyz
    ("object_linvel", 3),  # world frame
    ("object_angvel", 3),  # object frame (MuJoCo's free-joint convention)
    ("fingertip_contact_force", 3 * NUM_FORCES),  # contact force on each tip, tip frame, with noise
    ("object_planar_distance", 1),  # d_xy, eq. 2
    ("uniaxial_force", NUM_FORCES),  # the student's force reading: noise, then the deadband
    ("fingertip_wrench", 6 * NUM_FORCES),  # force + torque at each tip's load cell, tip frame, with noise
    # Meant as a_{t-1}, delta-theta (rad), after the +-0.3 rad clip. The env writes each action into it one
    # observation late (BatchedGraspEnv.step observes before it stores the action), so o_t carries a_{t-2} and an
    # episode's first two observations carry 0. Every shipped teacher was trained on it so; fixing it means
    # retraining them.
    ("previous_action", NUM_JOINTS),
)
PRIVILEGED_DIM = sum(n for _, n in PRIVILEGED_LAYOUT)  # 92 (the paper reports 95 without a breakdown)


PRIVILEGED_SLICES: dict[str, slice] = {
    name: slice(end - n, end)
    for (name, n), end in zip(PRIVILEGED_LAYOUT, itertools.accumulate(n for _, n in PRIVILEGED_LAYOUT))
}


def privileged_parts(parts: dict) -> list:
    """The parts of the privileged vector in layout order (numpy arrays or the sim's tensors), to concatenate.
    Refuses a missing, extra or mis-sized part, so the layout cannot drift from what the sim computes."""
    if set(parts) != set(PRIVILEGED_SLICES):
        missing, extra = set(PRIVILEGED_SLICES) - set(parts), set(parts) - set(PRIVILEGED_SLICES)
        raise ValueError(f"privileged parts differ from spec.PRIVILEGED_LAYOUT: missing {missing}, extra {extra}")
    for name, n in PRIVILEGED_LAYOUT:
        if parts[name].ndim != 2 or parts[name].shape[1] != n:
            raise ValueError(f"privileged part {name!r} must be (n_envs, {n}), got {tuple(parts[name].shape)}")
    return [parts[name] for name, _ in PRIVILEGED_LAYOUT]


# --- Task and success --------------------------------------------------------------------------------------------
# Object lift (m) above its resting height at which r_t (eq. 3) saturates. 3 cm is reachable for every object from
# mid-height side contacts with the D'Claw finger lengths, and clears the table with margin.
TARGET_LIFT_M = 0.03
# Success (sim, teacher eval, real protocol): object lifted >= SUCCESS_LIFT_M and held for >= SUCCESS_HOLD_S
# continuously within a 10 s trial. "Completely lifted" = clear of the table; 1.5 cm leaves margin for penetration.
SUCCESS_LIFT_M = 0.015
SUCCESS_HOLD_S = 1.0
SUCCESS_HOLD_STEPS = int(round(SUCCESS_HOLD_S * CONTROL_HZ))
# Paper: an episode terminates when the object leaves a 10 cm planar radius around the claw centre.
WORKSPACE_RADIUS_M = 0.10
OBJECT_XY_RANGE_M = 0.03


# --- Seed ranges (evaluation protocol) ---------------------------------------------------------------------------
# An env's start states are a function of (env seed, episode counter); env i of a batch uses seed base + i. Each
# stage draws env seeds from its own range (far wider than any run needs), so no start state seen in teacher
# training or demos is ever used to measure a policy.
SEED_RANGE_SIZE = 1 << 40
SEED_RANGES: dict[str, range] = {
    "teacher_train": range(SEED_RANGE_SIZE),
    "demos": range(SEED_RANGE_SIZE, 2 * SEED_RANGE_SIZE),
    "eval": range(2 * SEED_RANGE_SIZE, 3 * SEED_RANGE_SIZE),
}
TEACHER_TRAIN_SEED = 1  # blindgrasp-train-teacher's default --seed: env seeds 1..num_envs
DEMO_SEED = SEED_RANGES["demos"].start  # blindgrasp-collect-demos' default --seed
# Evaluation seeds are lerobot-eval's per-episode indices (--seed, +1 per episode). The envs and the teacher eval
# map (index, object) into the eval range, one block of EVAL_TASK_STRIDE per object (task id = catalogue index), so
# no two objects share a draw and both tools evaluate on the same start states for the same --seed.
EVAL_TASK_STRIDE = 1 << 32
EVAL_SEED = 1000  # lerobot-eval's own default --seed


def eval_env_seed(seed: int, task_id: int) -> int:
    """The env seed of evaluation episode index `seed` on object `task_id` (its catalogue index)."""
    seed, task_id = int(seed), int(task_id)
    if not 0 <= seed < EVAL_TASK_STRIDE:
        raise ValueError(f"an evaluation seed must be in [0, 2**32), got {seed}")
    if not 0 <= task_id < len(SEED_RANGES["eval"]) // EVAL_TASK_STRIDE:
        raise ValueError(f"task id {task_id} has no evaluation seed block")
    return SEED_RANGES["eval"].start + task_id * EVAL_TASK_STRIDE + seed


def check_seeds(stage: str, first: int, count: int) -> None:
    """Refuse env seeds [first, first + count) unless they lie inside `stage`'s range (so no other stage's)."""
    r = SEED_RANGES[stage]
    if count < 0 or not (r.start <= first and first + count <= r.stop):
        raise ValueError(
            f"env seeds {first}..{first + count - 1} are outside the {stage} range [{r.start}, {r.stop}) "
            f"(spec.SEED_RANGES keeps teacher training, demos and evaluation apart); use a seed in that range"
        )
