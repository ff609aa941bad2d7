"""The actors the episode loop runs: each maps the env's observation dict to the env's step (delta-theta, (n, 9)).
The teacher outputs steps; the student's absolute joint targets (LeRobot's action) become steps through the env's
calibration-aware `BatchedGraspEnv.delta_for_target`, as in the lerobot-eval gym env.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from lerobot_blindgrasp.sim import objects
from lerobot_blindgrasp.sim.batched_env import BatchedGraspEnv


class TeacherActor:
    """A teacher's action: its deterministic mean, or a sample of its Gaussian (`stochastic`)."""

    def __init__(self, teacher, stochastic: bool = False):
        self.teacher, self.stochastic = teacher, stochastic

    def __call__(self, obs: dict[str, np.ndarray], env: BatchedGraspEnv | None = None) -> np.ndarray:
        return self.teacher(obs, stochastic=self.stochastic)

    def target(self, obs: dict[str, np.ndarray], env: BatchedGraspEnv) -> np.ndarray:
        """The absolute targets the env would command for this action (a label in the student's terms)."""
        return env.target_for_delta(self(obs, env))


@dataclass
class StudentActor:
    """A LeRobot policy checkpoint with its processors, loaded and run the way lerobot-eval does:
    `make_policy` with the `blindgrasp` env config, the checkpoint's pre/post-processors and the env's; every step
    `preprocess_observation` -> env pre -> policy pre -> `select_action` -> post -> env post."""

    policy: object
    preprocessor: object
    postprocessor: object
    env_preprocessor: object
    env_postprocessor: object
    path: Path
    tasks: dict[str, str]  # object -> the dataset's task string, which the policy's processors may read

    @classmethod
    def load(cls, path: Path, object_names: tuple[str, ...], device: str = "cpu") -> StudentActor:
        from lerobot.configs.policies import PreTrainedConfig
        from lerobot.envs.factory import make_env_pre_post_processors
        from lerobot.policies import make_policy, make_pre_post_processors

        from lerobot_blindgrasp.envs.sim_env import BlindGraspEnvConfig

        cfg = PreTrainedConfig.from_pretrained(str(path))
        cfg.pretrained_path = Path(path)
        cfg.device = device
        env_cfg = BlindGraspEnvConfig(task=",".join(object_names))
        policy = make_policy(cfg=cfg, env_cfg=env_cfg).eval()
        pre, post = make_pre_post_processors(
            policy_cfg=cfg,
            pretrained_path=cfg.pretrained_path,
            preprocessor_overrides={"device_processor": {"device": device}},
        )
        env_pre, env_post = make_env_pre_post_processors(env_cfg=env_cfg, policy_cfg=cfg)
        tasks = {name: objects.get_object(name).task for name in object_names}
        return cls(policy, pre, post, env_pre, env_post, Path(path), tasks)

    def reset(self) -> None:
        """A new batch of episodes: the policy's context starts empty."""
        self.policy.reset()

    def targets(self, state: np.ndarray, object_names: list[str]) -> np.ndarray:
        """(B, 12) observations of envs holding `object_names` -> (B, 9) absolute joint targets (rad)."""
        from lerobot.envs.utils import preprocess_observation
        from lerobot.utils.constants import ACTION

        obs = preprocess_observation({"agent_pos": state.astype(np.float32)})
        obs["task"] = [self.tasks[name] for name in object_names]
        obs = self.preprocessor(self.env_preprocessor(obs))
        with torch.inference_mode():
            action = self.policy.select_action(obs)
        action = self.env_postprocessor({ACTION: self.postprocessor(action)})[ACTION]
        return action.to("cpu").numpy().astype(np.float64)

    def __call__(self, obs: dict[str, np.ndarray], env: BatchedGraspEnv, rows: slice = slice(None)) -> np.ndarray:
        names = list(env.object_names)[rows]
        return env.delta_for_target(self.targets(obs["policy"][rows], names), rows)


class SideBySide:
    """Several actors on consecutive row blocks of one batch (e.g. student and teacher on the same start states)."""

    def __init__(self, actors: list, rows_each: int):
        self.actors, self.rows_each = actors, rows_each

    def block(self, k: int) -> slice:
        return slice(k * self.rows_each, (k + 1) * self.rows_each)

    def __call__(self, obs: dict[str, np.ndarray], env: BatchedGraspEnv) -> np.ndarray:
        steps = []
        for k, actor in enumerate(self.actors):
            rows = self.block(k)
            if isinstance(actor, StudentActor):
                steps.append(actor(obs, env, rows))
            else:
                steps.append(actor({key: v[rows] for key, v in obs.items()}, env))
        return np.concatenate(steps)
