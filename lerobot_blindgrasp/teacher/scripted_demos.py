"""The scripted side-grasp demonstrations that `teacher.aux_bc.PPOWithScriptedDemos` clones: their settings and
their collection. Kept apart from the PPO subclass so that the preset registry can name them without importing torch.
"""

from __future__ import annotations

import copy
from dataclasses import asdict, dataclass

import numpy as np

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.sim import objects, randomization

# Script rollouts draw their start states from the teacher-training seed range, far above the env seeds of any
# training run (seed + env index), so that they never share a start state with evaluation or demo collection.
SCRIPT_SEED = 1 << 32
# The rsl-rl algorithm that clones them, as the runner config names it (resolved by rsl-rl when the run starts).
ALGORITHM_CLASS = "lerobot_blindgrasp.teacher.aux_bc:PPOWithScriptedDemos"


# The objects the `cpu` teacher was slowest to lift on its own: every small object and the medium capsule.
HARD_OBJECTS: tuple[str, ...] = (
    *(n for n in objects.PAPER_OBJECTS if n.endswith("_small")),
    "capsule_medium",
)


@dataclass(frozen=True)
class ScriptedDemos:
    """Which script grasps are cloned, and how strongly: the cloning loss, weighted by `coef`, joins PPO's loss in
    every PPO minibatch step (one optimizer, one gradient; DAPG's form), from `start_iteration`, its weight decaying
    linearly to 0 over `decay_iterations`."""

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
        """The cloning loss's weight at a PPO iteration: 0 before `start_iteration`, then decaying linearly to 0
        over `decay_iterations`."""
        if iteration < self.start_iteration:
            return 0.0
        return self.coef * max(0.0, 1.0 - (iteration - self.start_iteration) / self.decay_iterations)


def collect(cfg: ScriptedDemos) -> dict:
    """Roll the side-grasp script out once per env from training start states; keep the successful episodes.

    Returns {"obs": {"privileged": (M, 92), "policy": (M, 12)}, "actions": (M, 9), "success": {object: rate}},
    float32. Both observation groups are kept so that an actor reading either (the teacher's privileged one, or the
    "RL w/ o_t" row's student one) can be cloned."""
    # MuJoCo only when demos are collected, not when a preset names them
    from lerobot_blindgrasp.sim import scripted
    from lerobot_blindgrasp.sim.env import BatchedGraspEnv, GraspEnvConfig

    n = cfg.episodes_per_object * len(cfg.objects)
    dr = randomization.PAPER_DR if cfg.pushes else randomization.EVAL_DR  # as train.build_env_config chooses
    env = BatchedGraspEnv(
        GraspEnvConfig(num_envs=n, objects=cfg.objects, seed=cfg.seed, dr=dr, autoreset=False, nthread=1)
    )
    obs = env.reset()
    script = scripted.SideGraspScript(
        env.joint_positions(), env.object_position(), [objects.get_object(name) for name in env.object_names]
    )
    seen_obs, seen_policy, seen_act = [], [], []
    success = np.zeros(n, dtype=bool)
    for t in range(env.max_episode_steps):
        action = script(env.joint_positions())
        if t < cfg.steps_per_episode:
            seen_obs.append(obs["privileged"].astype(np.float32))
            seen_policy.append(obs["policy"].astype(np.float32))
            seen_act.append(action.astype(np.float32))
        obs, _, terminated, _, info = env.step(action)
        success |= info["success"]
        if terminated.any():  # an object left the workspace: that episode is not a demonstration
            success &= ~terminated
    env.close()
    names = np.array(env.object_names)
    rates = {name: float(success[names == name].mean()) for name in cfg.objects}
    keep = np.flatnonzero(success)
    o = np.stack(seen_obs, axis=1)[keep].reshape(-1, spec.PRIVILEGED_DIM)
    p = np.stack(seen_policy, axis=1)[keep].reshape(-1, spec.STATE_DIM)
    a = np.stack(seen_act, axis=1)[keep].reshape(-1, spec.NUM_JOINTS)
    return {"obs": {"privileged": o, "policy": p}, "actions": a, "success": rates}


@dataclass
class ScriptSuccessConfig:
    """How often the side-grasp script lifts each object from training start states (what cloning can use)."""

    objects: str = "all"  # "all", "medium", or a comma-separated list of catalogue names
    episodes_per_object: int = 30
    pushes: bool = True  # Table II's random pushes (the paper's training randomization)


def main(argv=None) -> None:
    """python -m lerobot_blindgrasp.teacher.scripted_demos [--objects=all] [--episodes_per_object=30]"""
    from lerobot_blindgrasp.cli import parse_config

    cfg = parse_config(ScriptSuccessConfig, argv)
    demos = ScriptedDemos(
        objects=objects.resolve_objects(cfg.objects),
        episodes_per_object=cfg.episodes_per_object,
        steps_per_episode=1,
        pushes=cfg.pushes,
    )
    rates = collect(demos)["success"]
    print(
        f"side-grasp script, {cfg.episodes_per_object} episodes per object from seed {demos.seed}, "
        f"pushes={cfg.pushes}\n\n| object | success |\n|---|---:|"
    )
    for name, rate in rates.items():
        print(f"| {name} | {rate:.0%} ({round(rate * cfg.episodes_per_object)}/{cfg.episodes_per_object}) |")
    print(f"| **all** | **{np.mean(list(rates.values())):.1%}** |")


if __name__ == "__main__":
    main()
