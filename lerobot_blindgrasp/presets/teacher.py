"""The teacher (PPO) part of the preset registry: `paper` is exactly Table III; `cpu` and `quick` are sized for a
2-core machine. `blindgrasp-train-teacher --preset=NAME` takes these names.

Every deviation from the paper lives in the `cpu`/`quick` presets only, each stated with its reason in
`deviations` (which the report and the teacher's card print). A training run records the preset it used in `teacher_config.json`, and
resuming refuses a run whose preset values differ, so a preset's numbers change only under a new name.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, replace

from lerobot_blindgrasp.sim import objects, rewards
from lerobot_blindgrasp.teacher.blind_approach import ActorInput
from lerobot_blindgrasp.teacher.scripted_demos import ScriptedDemos


def _ppo_cfg(
    *,
    num_steps_per_env: int,
    hidden_dims: list[int],
    init_std: float,
    obs_normalization: bool,
    save_interval: int,
    learning_rate: float = 1e-3,
    entropy_coef: float = 0.003,
    num_mini_batches: int = 6,
    num_learning_epochs: int = 5,
) -> dict:
    """rsl-rl 5.x OnPolicyRunner config with Table III's PPO values unless overridden."""
    return {
        "num_steps_per_env": num_steps_per_env,
        "save_interval": save_interval,
        "obs_groups": {"actor": ["privileged"], "critic": ["privileged"]},
        "algorithm": {
            "class_name": "PPO",
            "learning_rate": learning_rate,
            "schedule": "adaptive",
            "desired_kl": 0.01,
            "num_learning_epochs": num_learning_epochs,
            "num_mini_batches": num_mini_batches,
            "entropy_coef": entropy_coef,
            "value_loss_coef": 1.0,
            "clip_param": 0.2,
            "gamma": 0.99,
            "lam": 0.95,
            "max_grad_norm": 1.0,
            "use_clipped_value_loss": True,
        },
        "actor": {
            "class_name": "MLPModel",
            "hidden_dims": list(hidden_dims),
            "activation": "elu",
            "obs_normalization": obs_normalization,
            "distribution_cfg": {"class_name": "GaussianDistribution", "init_std": init_std},
        },
        "critic": {
            "class_name": "MLPModel",
            "hidden_dims": list(hidden_dims),
            "activation": "elu",
            "obs_normalization": obs_normalization,
        },
    }


@dataclass(frozen=True)
class TeacherPreset:
    name: str
    num_envs: int
    max_iterations: int
    runner: dict
    reward: rewards.RewardConfig = rewards.PAPER_REWARD
    deviations: tuple[str, ...] = ()
    external_force: bool = True  # Table II random pushes during training
    # Share of training envs per object (order of objects.PAPER_OBJECTS); None: even, as the paper.
    object_weights: tuple[float, ...] | None = None
    # (preset, iterations) this one continues: a fresh run first trains that preset for that many iterations (in
    # <output_dir>/stages/<preset>) and resumes its last checkpoint, so one command trains a staged teacher from
    # scratch. None: this preset starts from scratch itself.
    continues: tuple[str, int] | None = None
    # What a blind-approach actor is denied beyond the object before a touch (teacher/blind_approach.py); only read
    # when its obs_groups read the blind group.
    actor_input: ActorInput = ActorInput()
    # Training envs draw every joint's reading off by +-this (rad, sign per env and joint; beyond Table II).
    joint_calibration_rad: float = 0.0

    def runner_cfg(self) -> dict:
        return copy.deepcopy(self.runner)


PAPER = TeacherPreset(
    name="paper",
    num_envs=9000,  # 18 objects x 500
    max_iterations=4500,
    runner=_ppo_cfg(
        num_steps_per_env=24, hidden_dims=[512, 256, 128], init_std=1.0, obs_normalization=False, save_interval=100
    ),
)

_NO_PUSHES = (
    "no random pushes: 27 % of episodes in which the fingers never move end with a sphere or capsule rolled out of "
    "the workspace, which only adds reward noise on 2 cores (demos and eval run without pushes anyway)"
)

_CPU_DEVIATIONS = (
    "reach term w=0.5, 1 - tanh(20 d) with d from each tip END to the object: r_t is 0 until the object lifts, so "
    "PPO without it learns to keep still",
    "touch term w=0.5 x fraction of tips pressing on the object (> 0.1 N, any direction): with reach alone (scale "
    "10) the policy parked its tips 3 cm from the object for 4 M steps",
    "initial action std 0.5 rad instead of 1.0: with a 0.3 rad clip, std 1.0 makes most actions clipped +-0.3 "
    "bang-bang commands; 0.5 still explores widely and beat 0.3 on reach and contact rate in a "
    "side-by-side 150-iteration run",
    "empirical observation normalization: privileged forces span 0-100 N next to radians",
    "1026 envs x 24 steps, 4 minibatches: what 2 cores step in ~4 s per iteration",
    "actor and critic MLPs [256, 128, 64] instead of [512, 256, 128]: the PPO update on 1 CPU thread took longer "
    "than collection (4.5 s vs 3.5 s per iteration); the smaller MLPs cut it to 1.9 s (blindgrasp-bench --bench.type=teacher)",
    _NO_PUSHES,
)


_CPU_REWARD = replace(rewards.PAPER_REWARD.with_weights(reach=0.5, touch=0.5), reach_scale=20.0)

# PPO settings the cpu and quick presets share (their deviations list says why each differs from Table III).
_SMALL_PPO = {"num_steps_per_env": 24, "init_std": 0.5, "obs_normalization": True, "num_mini_batches": 4}

CPU = TeacherPreset(
    name="cpu",
    num_envs=1026,  # 18 objects x 57
    max_iterations=3000,
    runner=_ppo_cfg(hidden_dims=[256, 128, 64], save_interval=25, **_SMALL_PPO),
    reward=_CPU_REWARD,
    deviations=_CPU_DEVIATIONS,
    external_force=False,
)

# The scripted cloning the shipped teacher adds to `cpu` (teacher/aux_bc.py): the side-grasp script reads where the
# object stands, as the teacher's privileged observation does, and its grasps of the small objects and the medium
# capsule are cloned into the actor once `cpu` grasps. Iterations 0..1397 are exactly `cpu` (nothing of the cloning
# touches PPO, its random numbers or the normalizer before then); then the cloning loss joins PPO's with weight 0.1,
# decayed to 0 over 300 iterations.
CPU_BC_JOINT = replace(
    CPU,
    name="cpu_bc_joint",
    max_iterations=1798,
    runner=ScriptedDemos(
        pushes=CPU.external_force, start_iteration=1398, decay_iterations=300, coef=0.1
    ).runner_cfg(CPU.runner),
    deviations=_CPU_DEVIATIONS
    + (
        "from iteration 1398, the mean-squared error of the actor's mean against scripted side grasps of the small "
        "objects and the medium capsule joins PPO's loss with weight 0.1, decayed linearly to 0 by iteration 1698 "
        "(teacher/aux_bc.py): `cpu` alone presses the small capsule into the table from above, and no reward or "
        "exploration change tried moved it off that grasp",
    ),
)

# The shipped teacher (models/teacher_cpu_bc). `cpu_bc_joint` lifted every object but the small capsule (0/20 held
# out at 1700 and 1745). A second cloning stage aimed at it alone, continuing `cpu_bc_joint`'s iteration 1745: the
# script's small-capsule grasps only (256 start states), weight 0.5 decayed to 0 over 300 iterations, and 4x the
# small capsule's share of training envs so that PPO sees its rare lifts often enough to keep them. Held out at
# 2099: 97.8 % over the 18 objects, small capsule 90 %, run from scratch by one command in 2.8 h on 2 idle cores:
# the shipped teacher.
_CAPSULE_WEIGHTS = tuple(4.0 if name == "capsule_small" else 1.0 for name in objects.PAPER_OBJECTS)
_CAPSULE_DEMOS = ScriptedDemos(
    objects=("capsule_small",),
    episodes_per_object=256,
    pushes=CPU.external_force,
    start_iteration=1746,
    decay_iterations=300,
    coef=0.5,
)
CPU_BC_CAPSULE = replace(
    CPU_BC_JOINT,
    name="cpu_bc_capsule",
    max_iterations=2100,
    continues=("cpu_bc_joint", 1746),
    object_weights=_CAPSULE_WEIGHTS,
    runner=_CAPSULE_DEMOS.runner_cfg(CPU.runner),
    deviations=CPU_BC_JOINT.deviations
    + (
        "from iteration 1746 (resumed from cpu_bc_joint), a second cloning stage on the small capsule's scripted "
        "grasps alone, weight 0.5 decayed to 0 by 2046, and 4x its share of training envs: cpu_bc_joint still "
        "pressed it from above (0/20 held out)",
    ),
)

# Beyond the paper: the shipped teacher fine-tuned to approach blind (teacher/blind_approach.py). Its actor reads the
# object's state as 0 until a fingertip load cell reads a touch; the critic reads everything. It continues
# cpu_bc_capsule's iteration 2099 (the shipped teacher) for 250 PPO iterations with the `cpu` PPO settings and the
# capsule stage's object weights. Held out: 95.8 % over the 18 objects (shipped: 97.8 %), and its students gain
# 5.6-6.4 pp over the shipped teacher's on the same recipe. Shipped as models/teacher_cpu_bc_blind until 2026-12-03 (in git history).
_BLIND_RUNNER = CPU.runner_cfg()
_BLIND_RUNNER["obs_groups"] = {"actor": ["privileged_blind"], "critic": ["privileged"]}
CPU_BC_BLIND_APPROACH = replace(
    CPU_BC_CAPSULE,
    name="cpu_bc_blind_approach",
    max_iterations=2350,
    continues=("cpu_bc_capsule", 2100),
    runner=_BLIND_RUNNER,
    deviations=CPU_BC_CAPSULE.deviations
    + (
        "from iteration 2100 (resumed from cpu_bc_capsule, the shipped teacher), 250 PPO iterations in which the "
        "actor reads the object's pose, velocities and planar distance as 0 until a fingertip load cell reads "
        "above 2 N; the critic sees everything: the student cannot see the object before a touch, and a teacher "
        "that does asks it for actions it cannot infer",
    ),
)

# Beyond the paper: the blind-approach teacher with the object revealed only after 6 control steps (0.3 s) of touch.
# Its student could tell the small capsule from the small sphere only a step after the touch, while the teacher
# acted on the object at once. 200 PPO iterations from cpu_bc_blind_approach's last (2349): held out 95.3 % over the
# 18 objects, small capsule 18/20 (`blindgrasp-eval-teacher`, 20 start states per object).
CPU_BC_BLIND_REVEAL6 = replace(
    CPU_BC_BLIND_APPROACH,
    name="cpu_bc_blind_reveal6",
    max_iterations=2550,
    continues=("cpu_bc_blind_approach", 2350),
    actor_input=ActorInput(reveal_delay_steps=6),
    deviations=CPU_BC_BLIND_APPROACH.deviations
    + (
        "from iteration 2350 (resumed from cpu_bc_blind_approach), 200 PPO iterations in which the object is revealed "
        "only once a load cell has read above 2 N for more than 6 consecutive control steps: the student can tell "
        "the objects apart only after a touch, not at it",
    ),
)

# Beyond the paper: the teacher that made models/student_cpu. Its actor reads the fingertip poses as the kinematics
# of the measured joint angles, and PPO fine-tunes it under every joint reading off by +-0.05 rad, so that its
# corrections for a calibration offset are ones the blind student can observe and copy. 400 iterations from
# cpu_bc_blind_reveal6's last (2549). At 150 (2699): 93.3 % nominal, 90.3 % under the offset, training success
# still rising; at 400 (2949): 96.4 % nominal, 91.1 % under the offset, and its student holds 92.2 % under it on
# held-out start states where the blind-approach teacher's held 83.1 % (`blindgrasp-robustness`, seed 2000).
# Shipped as models/teacher_cpu_bc_calib; the teacher's card has the runs.
CPU_BC_CALIB_BLIND = replace(
    CPU_BC_BLIND_REVEAL6,
    name="cpu_bc_calib_blind",
    max_iterations=2950,
    continues=("cpu_bc_blind_reveal6", 2550),
    actor_input=ActorInput(reveal_delay_steps=6, fingertips_from_joints=True),
    joint_calibration_rad=0.05,
    deviations=CPU_BC_BLIND_REVEAL6.deviations
    + (
        "from iteration 2550 (resumed from cpu_bc_blind_reveal6), 400 PPO iterations with the actor's fingertip poses "
        "computed from the measured joint angles and every joint reading off by +-0.05 rad: a teacher that reads the "
        "true fingertips corrects a calibration offset by what the student never observes",
    ),
)

QUICK = TeacherPreset(
    name="quick",
    num_envs=144,  # 18 objects x 8
    max_iterations=30,
    runner=_ppo_cfg(hidden_dims=[128, 64], save_interval=10, **_SMALL_PPO),
    reward=_CPU_REWARD,
    deviations=_CPU_DEVIATIONS[:4]
    + (_NO_PUSHES,)
    + ("144 envs, MLP [128, 64], 30 iterations: minutes, for the pipeline and CI",),
    external_force=False,
)

PRESETS: dict[str, TeacherPreset] = {
    p.name: p
    for p in (
        PAPER,
        CPU,
        CPU_BC_JOINT,
        CPU_BC_CAPSULE,
        CPU_BC_BLIND_APPROACH,
        CPU_BC_BLIND_REVEAL6,
        CPU_BC_CALIB_BLIND,
        QUICK,
    )
}


def get_preset(name: str) -> TeacherPreset:
    try:
        return PRESETS[name]
    except KeyError:
        raise ValueError(f"unknown teacher preset {name!r}; choose from {', '.join(PRESETS)}") from None


# The reward terms a "w/o r_i" teacher loses: every term that pays for fingertip contact. Why these, and why reach
# and r_t stay: the row's doc, ablations.TABLE_V["wo_r_i"].
CONTACT_REWARD_TERMS = ("incentive", "touch")


@dataclass(frozen=True)
class Variant:
    """Teacher switches of the Table V rows (`lerobot_blindgrasp.presets.ablations` names the rows)."""

    no_incentive: bool = False  # teacher for "Student w/o r_i": every CONTACT_REWARD_TERMS term switched off
    student_obs: bool = False  # "RL w/ o_t": actor and critic see only the 12-d student observation

    def apply(self, preset: TeacherPreset) -> TeacherPreset:
        runner = preset.runner_cfg()
        reward = preset.reward
        if self.no_incentive:
            reward = reward.without(*CONTACT_REWARD_TERMS)
        if self.student_obs:
            runner["obs_groups"] = {"actor": ["policy"], "critic": ["policy"]}
        return replace(preset, runner=runner, reward=reward)
