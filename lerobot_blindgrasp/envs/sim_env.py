"""`--env.type=blindgrasp`: the MuJoCo grasping sim as a lerobot-eval env, one task per object.

    lerobot-eval --policy.path=<checkpoint> --env.type=blindgrasp --env.task=all --eval.n_episodes=10

A task_id is the object's index in the catalogue (`objects.task_id`), whichever objects are evaluated. lerobot-eval's
`--seed` + episode number is mapped per object into the evaluation seed range (`sim/gym_env.start_seed`), so
`blindgrasp-eval-teacher --seed S` runs the same start states. Imported at plugin discovery: MuJoCo loads lazily.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import partial

import gymnasium as gym
from lerobot.configs import PolicyFeature
from lerobot.envs.configs import EnvConfig

from lerobot_blindgrasp import spaces, spec
from lerobot_blindgrasp.sim import objects
from lerobot_blindgrasp.sim.objects import task_id

TASK_GROUP = "blindgrasp"
RENDER_STRIDE_REST = spec.CONTROL_HZ  # one video frame a second for the episodes past `render_episodes`


@EnvConfig.register_subclass("blindgrasp")
@dataclass
class BlindGraspEnvConfig(EnvConfig):
    # One object name (e.g. "cylinder_a_medium"), a comma list, "medium" (the 6 medium objects) or "all" (18).
    task: str | None = "all"
    fps: int = spec.CONTROL_HZ
    # The paper's randomization and sensor noise (external pushes off); false gives the nominal, noise-free sim.
    domain_randomization: bool = True
    # lerobot-eval renders up to 10 episodes to mp4; small frames without shadows keep that cheap on a CPU.
    render_width: int = 320
    render_height: int = 240
    render_shadows: bool = False
    # A new video frame every N control steps (repeated in between): N x cheaper videos, motion at 20/N Hz.
    render_stride: int = 1
    # lerobot-eval records the first 10 episodes of each object; only the first N get `render_stride`, the others
    # a frame a second (RENDER_STRIDE_REST): with a software renderer, video dominates a CPU evaluation.
    render_episodes: int = 10
    # End an episode when its success latches (the rates are the same; the batch runs on without it). false: every
    # episode runs its full 10 s, for videos of the whole hold.
    end_on_success: bool = True
    features: dict[str, PolicyFeature] = field(default_factory=spaces.env_features)
    features_map: dict[str, str] = field(default_factory=spaces.env_features_map)

    def __post_init__(self):
        # Fail while parsing the CLI, not after the policy has loaded.
        self.objects = objects.resolve_objects(self.task)
        if self.render_episodes < 0:
            raise ValueError(f"render_episodes must be >= 0, got {self.render_episodes}")

    @property
    def gym_kwargs(self) -> dict:
        from lerobot_blindgrasp.sim import gym_env  # MuJoCo: only when envs are actually built

        dr = gym_env.randomization.EVAL_DR if self.domain_randomization else gym_env.randomization.NO_DR
        return {
            "dr": dr,
            "render_width": self.render_width,
            "render_height": self.render_height,
            "render_shadows": self.render_shadows,
            "render_stride": self.render_stride,
            "end_on_success": self.end_on_success,
            "disable_env_checker": self.disable_env_checker,
        }

    def env_kwargs(self, index: int) -> dict:
        """gym kwargs of the `index`-th env of an object's batch (lerobot-eval renders envs 0..9 of the batch)."""
        kwargs = self.gym_kwargs
        if index >= self.render_episodes:
            kwargs["render_stride"] = max(self.render_stride, RENDER_STRIDE_REST)
        return kwargs

    def create_envs(self, n_envs: int, use_async_envs: bool = False) -> dict[str, dict[int, gym.vector.VectorEnv]]:
        # As LeRobot's multi-task benchmarks: finished sub-envs freeze (sim_vector.py), and only the task being
        # evaluated has async worker processes alive.
        from lerobot.envs.utils import _LazyAsyncVectorEnv

        from lerobot_blindgrasp.envs.sim_vector import SharedSimVectorEnv
        from lerobot_blindgrasp.sim import gym_env

        if n_envs < 1:
            raise ValueError(f"n_envs must be >= 1, got {n_envs}")
        out: dict[int, gym.vector.VectorEnv] = {}
        for name in self.objects:
            # A module-level function plus plain kwargs: async workers unpickle it by reference.
            fns = [partial(gym_env.make_env, name, **self.env_kwargs(i)) for i in range(n_envs)]
            if use_async_envs and n_envs > 1:
                out[task_id(name)] = _LazyAsyncVectorEnv(
                    fns, spaces.observation_space(), spaces.action_space(), dict(gym_env.BlindGraspGymEnv.metadata)
                )
            else:
                out[task_id(name)] = SharedSimVectorEnv(fns)
        return {TASK_GROUP: out}
