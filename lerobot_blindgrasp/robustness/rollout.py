"""Student and teacher on the same start states, under one `DomainRandomization`, all objects in one batch.

The student is loaded and run the way `lerobot-eval` does it: `PreTrainedConfig.from_pretrained` + `make_policy`
(with the `blindgrasp` env config), the checkpoint's pre/post-processors from `make_pre_post_processors`, the env's
from `make_env_pre_post_processors`; every step `preprocess_observation` -> env pre -> policy pre ->
`select_action` -> post -> env post, and the absolute targets go to the sim through `delta_for_target`, as the gym
env sends them. The difference from lerobot-eval is the batch: one `BatchedGraspEnv` holds every object's episodes
(env seeds from `spec.eval_env_seed`, so each episode is exactly the start state the gym env gives lerobot-eval for
that `--seed` and object) and the policy sees them as one batch.

The teacher (privileged observation, deterministic mean action) runs in the second half of the same batch on the
same env seeds: the same physics draw, start pose and noise as its student counterpart.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.sim import randomization
from lerobot_blindgrasp.sim.env import BatchedGraspEnv, GraspEnvConfig
from lerobot_blindgrasp.sim.gym_env import start_seed


@dataclass
class Student:
    """A LeRobot policy checkpoint with its processors, as lerobot-eval builds them."""

    policy: object
    preprocessor: object
    postprocessor: object
    env_preprocessor: object
    env_postprocessor: object
    path: Path

    @classmethod
    def load(cls, path: Path, object_names: tuple[str, ...]) -> Student:
        from lerobot.configs.policies import PreTrainedConfig
        from lerobot.envs.factory import make_env_pre_post_processors
        from lerobot.policies import make_policy, make_pre_post_processors

        from lerobot_blindgrasp.envs.sim_env import BlindGraspEnvConfig

        cfg = PreTrainedConfig.from_pretrained(str(path))
        cfg.pretrained_path = Path(path)
        cfg.device = "cpu"
        env_cfg = BlindGraspEnvConfig(task=",".join(object_names))
        policy = make_policy(cfg=cfg, env_cfg=env_cfg)
        policy.eval()
        pre, post = make_pre_post_processors(
            policy_cfg=cfg,
            pretrained_path=cfg.pretrained_path,
            preprocessor_overrides={"device_processor": {"device": "cpu"}},
        )
        env_pre, env_post = make_env_pre_post_processors(env_cfg=env_cfg, policy_cfg=cfg)
        return cls(policy, pre, post, env_pre, env_post, Path(path))

    def reset(self) -> None:
        self.policy.reset()

    def targets(self, state: np.ndarray, tasks: list[str]) -> np.ndarray:
        """(B, 12) observations -> (B, 9) absolute joint targets (rad)."""
        from lerobot.envs.utils import preprocess_observation
        from lerobot.utils.constants import ACTION

        obs = preprocess_observation({"agent_pos": state.astype(np.float32)})
        obs["task"] = tasks
        obs = self.preprocessor(self.env_preprocessor(obs))
        with torch.inference_mode():
            action = self.policy.select_action(obs)
        action = self.env_postprocessor({ACTION: self.postprocessor(action)})[ACTION]
        return action.to("cpu").numpy().astype(np.float64)


def episode_seeds(object_names: tuple[str, ...], episodes: int, seed: int) -> tuple[list[int], list[int]]:
    """(object index, env seed) of each env, round-robin over objects as `BatchedGraspEnv` assigns them: env i is
    evaluation index seed + i // n_objects on object i % n_objects."""
    n_obj = len(object_names)
    obj = [i % n_obj for i in range(n_obj * episodes)]
    seeds = [start_seed(seed + i // n_obj, object_names[i % n_obj]) for i in range(n_obj * episodes)]
    return obj, seeds


def run_point(
    dr: randomization.DomainRandomization,
    student: Student | None,
    teacher,
    object_names: tuple[str, ...],
    episodes: int,
    seed: int,
    nthread: int = 0,
) -> dict[str, dict[str, list[bool]]]:
    """{"student": {object: [success per episode]}, "teacher": {...}} on the same start states (episode k of
    every object is evaluation index seed + k). Either policy may be None (then left out)."""
    from lerobot_blindgrasp.sim import objects as objects_mod

    spec.eval_env_seed(seed + episodes - 1, 0)  # raises if the indices leave the eval block
    obj, seeds = episode_seeds(object_names, episodes, seed)
    roles = [r for r, p in (("student", student), ("teacher", teacher)) if p is not None]
    n = len(seeds)
    env = BatchedGraspEnv(
        GraspEnvConfig(
            num_envs=n * len(roles),
            objects=object_names,
            env_seeds=tuple(seeds * len(roles)),
            dr=dr,
            nthread=nthread,
            autoreset=False,
        )
    )
    tasks = [objects_mod.get_object(object_names[k]).task for k in obj]
    obs = env.reset()
    if student is not None:
        student.reset()
    alive = np.ones(env.num_envs, dtype=bool)
    success = np.zeros(env.num_envs, dtype=bool)
    for _ in range(env.max_episode_steps):
        deltas = []
        for r, role in enumerate(roles):
            rows = slice(r * n, (r + 1) * n)
            if role == "student":
                targets = student.targets(obs["policy"][rows], tasks)
                deltas.append(env.delta_for_target(targets, rows))
            else:
                deltas.append(teacher({k: v[rows] for k, v in obs.items()}, stochastic=False))
        # Episodes whose outcome is final (success latches; ended ones stay ended) are no longer simulated.
        obs, _, term, trunc, info = env.step(np.concatenate(deltas), active=alive & ~success)
        success |= info["success"] & alive
        alive &= ~(term | trunc)
        if not (alive & ~success).any():  # every outcome is final: success latches, ended episodes stay ended
            break
    env.close()
    out = {}
    for r, role in enumerate(roles):
        flags = success[r * n : (r + 1) * n]
        out[role] = {name: [bool(x) for x, o in zip(flags, obj) if o == k] for k, name in enumerate(object_names)}
    return out
