"""lerobot-eval's vector env for one object: its gym envs share ONE `BatchedGraspEnv`, stepped once per batch step,
instead of paying the per-step torch work once per sub-env. Each row is seeded as its sub-env alone would be.

What lerobot-eval sees is, step for step, a `SyncVectorEnv` of sub-envs in LeRobot's `FreezeAfterEpisodeEnd`: an
ended sub-env holds its last observation and info with reward 0 (its row is no longer simulated), gymnasium's
next-step autoreset alternates that held observation (not done) with the held result, and the 200-step time limit
truncates at the 200th step. The sub-envs stay reachable (`envs[i].render()`), without gym.make's wrappers.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import gymnasium as gym
import numpy as np
from gymnasium.vector.utils import batch_space, concatenate, create_empty_array

from lerobot_blindgrasp.sim import gym_env


class SharedSimVectorEnv(gym.vector.VectorEnv):
    """`env_fns` build `BlindGraspGymEnv`s of one object (possibly inside gym.make's wrappers). Not a
    `SyncVectorEnv`: the step is this class's, so it relies on no sync env's private state."""

    def __init__(self, env_fns: Sequence[Callable[[], gym.Env]]):
        super().__init__()
        # The sub-envs without gym.make's wrappers: this class enforces the order of calls and owns the time limit.
        self.envs = [fn().unwrapped for fn in env_fns]
        if len({g.object.name for g in self.envs}) != 1 or len({g.dr for g in self.envs}) != 1:
            raise ValueError("the sub-envs of a shared-sim vector env need one object and one randomization")
        self.num_envs = len(self.envs)
        g0 = self.envs[0]
        self.metadata = {**g0.metadata, "autoreset_mode": gym.vector.AutoresetMode.NEXT_STEP}
        self.render_mode = g0.render_mode
        self.single_observation_space, self.single_action_space = g0.observation_space, g0.action_space
        self.observation_space = batch_space(g0.observation_space, self.num_envs)
        self.action_space = batch_space(g0.action_space, self.num_envs)
        self._sim: gym_env.BatchedGraspEnv | None = None
        self._held: list[tuple | None] = [None] * self.num_envs
        self._ended = np.zeros(self.num_envs, dtype=np.bool_)  # ended last step: gymnasium autoresets it now

    def reset(self, *, seed: int | Sequence[int | None] | None = None, options: dict | None = None):
        # `options` is accepted and ignored, as the sub-envs do: every reset starts a new rollout for all of them.
        if seed is None or isinstance(seed, int | np.integer):
            seed = [None if seed is None else int(seed) + i for i in range(self.num_envs)]
        if len(seed) != self.num_envs:
            raise ValueError(f"got {len(seed)} seeds for {self.num_envs} envs")
        for g, s in zip(self.envs, seed, strict=True):
            g.begin(s)
        if self._sim is not None:
            self._sim.close()
        g0 = self.envs[0]
        self._sim = gym_env.make_sim(g0.object.name, [g.env_seed for g in self.envs], g0.dr)
        sim_obs = self._sim.reset()
        self._held = [None] * self.num_envs
        self._ended[:] = False
        observations, infos = [], {}
        for i, g in enumerate(self.envs):
            obs, info = g.attach(self._sim, i, sim_obs)
            observations.append(obs)
            infos = self._add_info(infos, info, i)
        return self._batch(observations), infos

    def step(self, actions):
        if self._sim is None:
            raise RuntimeError("call reset() before step()")
        actions = np.asarray(actions, dtype=np.float64)
        running = np.array([h is None for h in self._held])
        targets = np.zeros((self.num_envs, actions.shape[-1]))
        for i in np.flatnonzero(running):
            targets[i] = self.envs[i].check_action(actions[i])
        out = self._sim.step(self._sim.delta_for_target(targets), active=running) if running.any() else None
        results = [self._row_step(i, out) for i in range(self.num_envs)]
        infos: dict = {}
        for i, result in enumerate(results):
            infos = self._add_info(infos, result[4], i)
        observations, rewards, terminations, truncations, _ = zip(*results, strict=True)
        terminations, truncations = np.array(terminations, dtype=np.bool_), np.array(truncations, dtype=np.bool_)
        self._ended = terminations | truncations
        return self._batch(observations), np.array(rewards, dtype=np.float64), terminations, truncations, infos

    def _row_step(self, i: int, out) -> tuple:
        if self._ended[i]:  # gymnasium resets it; the frozen env replays its last observation
            obs, _, _, _, info = self._held[i]
            return obs, 0.0, False, False, info
        if self._held[i] is not None:
            return self._held[i]
        g = self.envs[i]
        obs, reward, terminated, truncated, info = g.row_result(out)
        truncated = truncated or int(self._sim.episode_length[i]) >= g._max_episode_steps  # TimeLimit
        if terminated or truncated:
            self._held[i] = (obs, 0.0, terminated, truncated, info)
        return obs, reward, terminated, truncated, info

    def _batch(self, observations):
        out = create_empty_array(self.single_observation_space, n=self.num_envs, fn=np.zeros)
        return concatenate(self.single_observation_space, observations, out)

    def render(self) -> tuple:
        return tuple(g.render() for g in self.envs)

    def call(self, name: str, *args, **kwargs) -> tuple:
        attrs = (g.get_wrapper_attr(name) for g in self.envs)
        return tuple(a(*args, **kwargs) if callable(a) else a for a in attrs)

    def get_attr(self, name: str) -> tuple:
        return self.call(name)

    def close_extras(self, **kwargs):
        for g in self.envs:
            g.close()
        self._sim = None
