"""The teacher presets (`blindgrasp-train-teacher --preset=NAME`): `paper` is exactly Table III; `cpu` and `quick`
are sized for 2 cores; the `cpu_bc_*` presets are the shipped teachers' staged recipes. Every deviation from the
paper is stated with its reason in `deviations`. A run records its preset and resuming refuses different values, so
a preset's numbers change only under a new name.
"""

from __future__ import annotations

from dataclasses import replace

from lerobot_blindgrasp.presets.teacher_configs import ActorInput, ScriptedDemos, TeacherPreset, ppo_config
from lerobot_blindgrasp.sim import objects, rewards

PAPER = TeacherPreset(
    name="paper",
    num_envs=9000,  # 18 objects x 500
    max_iterations=4500,
    runner=ppo_config(
        num_steps_per_env=24, hidden_dims=[512, 256, 128], init_std=1.0, obs_normalization=False, save_interval=100
    ),
)

# The reasons of the cpu-sized presets, one constant each, so that a preset sharing one names it.
_REACH = (
    "reach term w=0.5, 1 - tanh(20 d) with d from each tip END to the object: r_t is 0 until the object lifts, so "
    "PPO without it learns to keep still"
)
_TOUCH = (
    "touch term w=0.5 x fraction of tips pressing on the object (> 0.1 N, any direction): with reach alone (scale "
    "10) the policy parked its tips 3 cm from the object for 4 M steps"
)
_INIT_STD = (
    "initial action std 0.5 rad instead of 1.0: with a 0.3 rad clip, std 1.0 makes most actions clipped +-0.3 "
    "bang-bang commands; 0.5 still explores widely and beat 0.3 on reach and contact rate in a "
    "side-by-side 150-iteration run"
)
_OBS_NORM = "empirical observation normalization: privileged forces span 0-100 N next to radians"
_CPU_ENVS = "1026 envs x 24 steps, 4 minibatches: what 2 cores step in ~4 s per iteration"
_CPU_MLP = (
    "actor and critic MLPs [256, 128, 64] instead of [512, 256, 128]: the PPO update on 1 CPU thread took longer "
    "than collection (4.5 s vs 3.5 s per iteration); the smaller MLPs cut it to 1.9 s (blindgrasp-bench --bench.type=teacher)"
)
_NO_PUSHES = (
    "no random pushes: 27 % of episodes in which the fingers never move end with a sphere or capsule rolled out of "
    "the workspace, which only adds reward noise on 2 cores (demos and eval run without pushes anyway)"
)
_SHAPING = (_REACH, _TOUCH, _INIT_STD, _OBS_NORM)
_CPU_REWARD = replace(rewards.PAPER_REWARD.with_weights(reach=0.5, touch=0.5), reach_scale=20.0)
# PPO settings the cpu and quick presets share (their deviations say why each differs from Table III).
_SMALL_PPO = {"num_steps_per_env": 24, "init_std": 0.5, "obs_normalization": True, "num_mini_batches": 4}

CPU = TeacherPreset(
    name="cpu",
    num_envs=1026,  # 18 objects x 57
    max_iterations=3000,
    runner=ppo_config(hidden_dims=[256, 128, 64], save_interval=25, **_SMALL_PPO),
    reward=_CPU_REWARD,
    deviations=(*_SHAPING, _CPU_ENVS, _CPU_MLP, _NO_PUSHES),
    external_force=False,
)

QUICK = TeacherPreset(
    name="quick",
    num_envs=144,  # 18 objects x 8
    max_iterations=30,
    runner=ppo_config(hidden_dims=[128, 64], save_interval=10, **_SMALL_PPO),
    reward=_CPU_REWARD,
    deviations=(*_SHAPING, _NO_PUSHES, "144 envs, MLP [128, 64], 30 iterations: minutes, for the pipeline and CI"),
    external_force=False,
)

# Scripted-grasp cloning into `cpu` (teacher/aux_bc.py) once it grasps; iterations 0..1397 are exactly `cpu`.
CPU_BC_JOINT = replace(
    CPU,
    name="cpu_bc_joint",
    max_iterations=1798,
    runner=ScriptedDemos(
        pushes=CPU.external_force, start_iteration=1398, decay_iterations=300, coef=0.1
    ).runner_cfg(CPU.runner),
    deviations=CPU.deviations
    + (
        "from iteration 1398, the mean-squared error of the actor's mean against scripted side grasps of the small "
        "objects and the medium capsule joins PPO's loss with weight 0.1, decayed linearly to 0 by iteration 1698 "
        "(teacher/aux_bc.py): `cpu` alone presses the small capsule into the table from above, and no reward or "
        "exploration change tried moved it off that grasp",
    ),
)

# The shipped teacher (models/teacher_cpu_bc): a second cloning stage aimed at the small capsule alone.
CPU_BC_CAPSULE = replace(
    CPU_BC_JOINT,
    name="cpu_bc_capsule",
    max_iterations=2100,
    stages=(("cpu_bc_joint", 1746),),
    object_weights=tuple(4.0 if name == "capsule_small" else 1.0 for name in objects.PAPER_OBJECTS),
    runner=ScriptedDemos(
        objects=("capsule_small",),
        episodes_per_object=256,
        pushes=CPU.external_force,
        start_iteration=1746,
        decay_iterations=300,
        coef=0.5,
    ).runner_cfg(CPU.runner),
    deviations=CPU_BC_JOINT.deviations
    + (
        "from iteration 1746 (resumed from cpu_bc_joint), a second cloning stage on the small capsule's scripted "
        "grasps alone, weight 0.5 decayed to 0 by 2046, and 4x its share of training envs: cpu_bc_joint still "
        "pressed it from above (0/20 held out)",
    ),
)

# Beyond the paper: the shipped teacher fine-tuned to approach blind (teacher/blind_approach.py).
_BLIND_RUNNER = CPU.runner_cfg()
_BLIND_RUNNER["obs_groups"] = {"actor": ["privileged_blind"], "critic": ["privileged"]}
CPU_BC_BLIND_APPROACH = replace(
    CPU_BC_CAPSULE,
    name="cpu_bc_blind_approach",
    max_iterations=2350,
    stages=(*CPU_BC_CAPSULE.stages, ("cpu_bc_capsule", 2100)),
    runner=_BLIND_RUNNER,
    deviations=CPU_BC_CAPSULE.deviations
    + (
        "from iteration 2100 (resumed from cpu_bc_capsule, the shipped teacher), 250 PPO iterations in which the "
        "actor reads the object's pose, velocities and planar distance as 0 until a fingertip load cell reads "
        "above 2 N; the critic sees everything: the student cannot see the object before a touch, and a teacher "
        "that does asks it for actions it cannot infer",
    ),
)

# Beyond the paper: the object revealed only after 6 control steps (0.3 s) of touch.
CPU_BC_BLIND_REVEAL6 = replace(
    CPU_BC_BLIND_APPROACH,
    name="cpu_bc_blind_reveal6",
    max_iterations=2550,
    stages=(*CPU_BC_BLIND_APPROACH.stages, ("cpu_bc_blind_approach", 2350)),
    actor_input=ActorInput(reveal_delay_steps=6),
    deviations=CPU_BC_BLIND_APPROACH.deviations
    + (
        "from iteration 2350 (resumed from cpu_bc_blind_approach), 200 PPO iterations in which the object is revealed "
        "only once a load cell has read above 2 N for more than 6 consecutive control steps: the student can tell "
        "the objects apart only after a touch, not at it",
    ),
)

# Beyond the paper: the teacher that made models/student_cpu (shipped as models/teacher_cpu_bc_calib), fine-tuned
# to read its fingertips from the measured joints under a +-0.05 rad calibration error.
CPU_BC_CALIB_BLIND = replace(
    CPU_BC_BLIND_REVEAL6,
    name="cpu_bc_calib_blind",
    max_iterations=2950,
    stages=(*CPU_BC_BLIND_REVEAL6.stages, ("cpu_bc_blind_reveal6", 2550)),
    actor_input=ActorInput(reveal_delay_steps=6, fingertips_from_joints=True),
    joint_calibration_rad=0.05,
    deviations=CPU_BC_BLIND_REVEAL6.deviations
    + (
        "from iteration 2550 (resumed from cpu_bc_blind_reveal6), 400 PPO iterations with the actor's fingertip poses "
        "computed from the measured joint angles and every joint reading off by +-0.05 rad: a teacher that reads the "
        "true fingertips corrects a calibration offset by what the student never observes",
    ),
)

TEACHER_PRESETS: dict[str, TeacherPreset] = {
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
