"""lerobot-eval's vector env for one object: its gym envs share ONE `BatchedGraspEnv`, stepped once per batch step,
instead of paying the per-step torch work once per sub-env. Each row is seeded as its sub-env alone would be.

What lerobot-eval sees is, step for step, a `SyncVectorEnv` of sub-envs in LeRobot's `FreezeAfterEpisodeEnd`: an
ended sub-env holds its last observation and info with reward 0 (its row is no longer simulated), gymnasium's
next-step autoreset alternates that held observation (not done) with the held result, and the 200-step time limit
truncates at the 200th step. The sub-envs stay reachable (`envs[i].render()`), without gym.make's wrappers.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from copy import deepcopy

import gymnasium as gym
import numpy as np
from gymnasium.vector.utils import concatenate

from lerobot_blindgrasp.sim import gym_env


class SharedSimVectorEnv(gym.vector.SyncVectorEnv):
    """`env_fns` build `BlindGraspGymEnv`s of one object (possibly inside gym.make's wrappers)."""

    def __init__(self, env_fns: Sequence[Callable[[], gym.Env]]):
        super().__init__(env_fns, autoreset_mode=gym.vector.AutoresetMode.NEXT_STEP)
        # The sub-envs without gym.make's wrappers: this class enforces the order of calls and owns the time limit.
        self.envs = self._gyms = [e.unwrapped for e in self.envs]
        if len({g.object.name for g in self._gyms}) != 1 or len({g.dr for g in self._gyms}) != 1:
            raise ValueError("the sub-envs of a shared-sim vector env need one object and one randomization")
        self._sim: gym_env.BatchedGraspEnv | None = None
        self._held: list[tuple | None] = [None] * self.num_envs

    def reset(self, *, seed: int | Sequence[int | None] | None = None, options: dict | None = None):
        # `options` is accepted and ignored, as the sub-envs do: every reset starts a new rollout for all of them.
        if seed is None or isinstance(seed, int | np.integer):
            seed = [None if seed is None else int(seed) + i for i in range(self.num_envs)]
        if len(seed) != self.num_envs:
            raise ValueError(f"got {len(seed)} seeds for {self.num_envs} envs")
        for g, s in zip(self._gyms, seed, strict=True):
            g.begin(s)
        if self._sim is not None:
            self._sim.close()
        g0 = self._gyms[0]
        self._sim = gym_env.make_sim(g0.object.name, [g.env_seed for g in self._gyms], g0.dr)
        sim_obs = self._sim.reset()
        self._held = [None] * self.num_envs
        self._autoreset_envs = np.zeros(self.num_envs, dtype=np.bool_)
        infos: dict = {}
        for i, g in enumerate(self._gyms):
            self._env_obs[i], info = g.attach(self._sim, i, sim_obs)
            infos = self._add_info(infos, info, i)
        return self._gather(), infos

    def step(self, actions):
        if self._sim is None:
            raise RuntimeError("call reset() before step()")
        actions = np.asarray(actions, dtype=np.float64)
        running = np.array([h is None for h in self._held])
        targets = np.zeros((self.num_envs, actions.shape[-1]))
        for i in np.flatnonzero(running):
            targets[i] = self._gyms[i].check_action(actions[i])
        out = self._sim.step(self._sim.delta_for_target(targets), active=running) if running.any() else None
        infos: dict = {}
        for i, g in enumerate(self._gyms):
            if self._autoreset_envs[i]:  # gymnasium resets it; the frozen env replays its last observation
                obs, _, _, _, info = self._held[i]
                result = (obs, 0.0, False, False, info)
            elif self._held[i] is not None:
                result = self._held[i]
            else:
                obs, reward, terminated, truncated, info = g.row_result(out)
                truncated = truncated or int(self._sim.episode_length[i]) >= g._max_episode_steps  # TimeLimit
                result = (obs, reward, terminated, truncated, info)
                if terminated or truncated:
                    self._held[i] = (obs, 0.0, terminated, truncated, info)
            self._env_obs[i], self._rewards[i], self._terminations[i], self._truncations[i], info = result
            infos = self._add_info(infos, info, i)
        self._autoreset_envs = np.logical_or(self._terminations, self._truncations)
        return (
            self._gather(),
            np.copy(self._rewards),
            np.copy(self._terminations),
            np.copy(self._truncations),
            infos,
        )

    def _gather(self):
        self._observations = concatenate(self.single_observation_space, self._env_obs, self._observations)
        return deepcopy(self._observations) if self.copy else self._observations

    def close_extras(self, **kwargs):
        super().close_extras(**kwargs)
        self._sim = None
