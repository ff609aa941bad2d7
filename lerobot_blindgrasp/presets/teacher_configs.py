"""The teacher's config types, which the presets (`presets/teacher.py`) are made of and `teacher/` reads."""

from __future__ import annotations

import copy
from dataclasses import asdict, dataclass, replace

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.sim import objects, rewards


def ppo_config(
    *,
    num_steps_per_env: int,
    hidden_dims: list[int],
    init_std: float,
    obs_normalization: bool,
    save_interval: int,
    num_mini_batches: int = 6,
) -> dict:
    """rsl-rl 5.x OnPolicyRunner config with Table III's PPO values unless overridden."""
    mlp = {"class_name": "MLPModel", "hidden_dims": list(hidden_dims), "activation": "elu"}
    mlp["obs_normalization"] = obs_normalization
    return {
        "num_steps_per_env": num_steps_per_env,
        "save_interval": save_interval,
        "obs_groups": {"actor": ["privileged"], "critic": ["privileged"]},
        "algorithm": {
            "class_name": "PPO",
            "learning_rate": 1e-3,
            "schedule": "adaptive",
            "desired_kl": 0.01,
            "num_learning_epochs": 5,
            "num_mini_batches": num_mini_batches,
            "entropy_coef": 0.003,
            "value_loss_coef": 1.0,
            "clip_param": 0.2,
            "gamma": 0.99,
            "lam": 0.95,
            "max_grad_norm": 1.0,
            "use_clipped_value_loss": True,
        },
        "actor": {**mlp, "distribution_cfg": {"class_name": "GaussianDistribution", "init_std": init_std}},
        "critic": mlp,
    }


@dataclass(frozen=True)
class ActorInput:
    """What a blind-approach teacher's actor is denied beyond the object before a touch (teacher/blind_approach.py)."""

    reveal_delay_steps: int = 0  # control steps of touch before the object is revealed (0: at the touch)
    fingertips_from_joints: bool = False  # fingertip poses from the measured joints' kinematics, not the true ones

    def __post_init__(self):
        if self.reveal_delay_steps < 0:
            raise ValueError(f"reveal_delay_steps must be >= 0, got {self.reveal_delay_steps}")

    def as_record(self) -> dict:
        return asdict(self)

    @classmethod
    def from_record(cls, record: dict | None) -> ActorInput:
        """From teacher_config.json's "actor_input" (absent in teachers made before it: the first blind teacher)."""
        return cls(**(record or {}))


# The observation group (rsl-rl obs_groups) of the privileged vector with the object hidden until a touch.
BLIND_GROUP = "privileged_blind"


def reads_blind_group(obs_groups: dict[str, list[str]]) -> bool:
    """Whether any model of an rsl-rl `obs_groups` config reads BLIND_GROUP (only then is it worth computing)."""
    return any(BLIND_GROUP in groups for groups in obs_groups.values())


# Script rollouts' start states: in the teacher-training seed range, far above any training run's env seeds.
SCRIPT_SEED = 1 << 32
# The rsl-rl algorithm that clones them, as the runner config names it (resolved by rsl-rl when the run starts).
ALGORITHM_CLASS = "lerobot_blindgrasp.teacher.aux_bc:PPOWithScriptedDemos"
# The objects the `cpu` teacher was slowest to lift on its own: every small object and the medium capsule.
HARD_OBJECTS: tuple[str, ...] = (*(n for n in objects.PAPER_OBJECTS if n.endswith("_small")), "capsule_medium")


@dataclass(frozen=True)
class ScriptedDemos:
    """Which script grasps are cloned (`teacher/aux_bc.py`), and how strongly (`weight_at`)."""

    objects: tuple[str, ...] = HARD_OBJECTS
    episodes_per_object: int = 64  # script rollouts per object; the successful ones are kept
    steps_per_episode: int = 120  # approach, squeeze, lift and 2 s of hold: the rest is more of the same hold
    coef: float = 0.1  # weight of the cloning loss next to PPO's at `start_iteration`
    decay_iterations: int = 700  # ... linearly to 0 over this many iterations; afterwards the paper's reward alone
    start_iteration: int = 0  # PPO alone before this iteration (cloning into a policy that already grasps)
    batch_size: int = 2048
    seed: int = SCRIPT_SEED
    pushes: bool = False  # Table II's random pushes, as the training preset has them (`external_force`)

    def __post_init__(self):
        unknown = sorted(set(self.objects) - set(objects.CATALOGUE))
        if unknown:
            raise ValueError(f"scripted-demo objects not in the catalogue: {unknown}")
        if min(self.episodes_per_object, self.steps_per_episode, self.decay_iterations, self.batch_size) < 1 or (
            self.start_iteration < 0
        ):
            raise ValueError(f"scripted demos need positive sizes, got {self}")
        spec.check_seeds("teacher_train", self.seed, self.episodes_per_object * len(self.objects))

    def as_record(self) -> dict:
        """The JSON form that goes into the runner config (lists, not tuples: it must survive a JSON round trip)."""
        d = asdict(self)
        d["objects"] = list(self.objects)
        return d

    def runner_cfg(self, runner: dict) -> dict:
        """`runner` (an rsl-rl OnPolicyRunner config) with PPO replaced by PPO plus cloning of these demos."""
        runner = copy.deepcopy(runner)
        runner["algorithm"]["class_name"] = ALGORITHM_CLASS
        runner["algorithm"]["scripted_demos"] = self.as_record()
        return runner

    def weight_at(self, iteration: int) -> float:
        """The cloning loss's weight at a PPO iteration: 0 before `start_iteration`, then `coef` decaying to 0."""
        if iteration < self.start_iteration:
            return 0.0
        return self.coef * max(0.0, 1.0 - (iteration - self.start_iteration) / self.decay_iterations)


@dataclass(frozen=True)
class TeacherPreset:
    name: str
    num_envs: int
    max_iterations: int
    runner: dict
    reward: rewards.RewardConfig = rewards.PAPER_REWARD
    deviations: tuple[str, ...] = ()  # from Table III and the paper's training, each with its reason
    external_force: bool = True  # Table II random pushes during training
    # Share of training envs per object (order of objects.PAPER_OBJECTS); None: even, as the paper.
    object_weights: tuple[float, ...] | None = None
    # A staged recipe: the presets trained before this one, in order, each with the iteration it stops at, each
    # starting from the previous one's last checkpoint. (): this preset starts from scratch.
    stages: tuple[tuple[str, int], ...] = ()
    # What a blind-approach actor is denied (read only when its obs_groups read the blind group).
    actor_input: ActorInput = ActorInput()
    # Training envs draw every joint's reading off by +-this (rad, sign per env and joint; beyond Table II).
    joint_calibration_rad: float = 0.0

    def runner_cfg(self) -> dict:
        return copy.deepcopy(self.runner)


# The reward terms a "w/o r_i" teacher loses: every term that pays for contact (why: ablations.TABLE_V["wo_r_i"]).
CONTACT_REWARD_TERMS = ("incentive", "touch")


@dataclass(frozen=True)
class Variant:
    """Teacher switches of the Table V rows (`lerobot_blindgrasp.presets.ablations` names the rows)."""

    no_incentive: bool = False  # teacher for "Student w/o r_i": every CONTACT_REWARD_TERMS term switched off
    student_obs: bool = False  # "RL w/ o_t": actor and critic see only the 12-d student observation

    def apply(self, preset: TeacherPreset) -> TeacherPreset:
        runner = preset.runner_cfg()
        reward = preset.reward.without(*CONTACT_REWARD_TERMS) if self.no_incentive else preset.reward
        if self.student_obs:
            runner["obs_groups"] = {"actor": ["policy"], "critic": ["policy"]}
        return replace(preset, runner=runner, reward=reward)
