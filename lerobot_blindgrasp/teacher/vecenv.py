"""rsl-rl-lib 5.x `VecEnv` adapter over the batched blind-grasp env, which auto-resets inside `step`.

Observation groups: "policy" (the student's 12-d o_t), "privileged" (the teacher's 92-d vector) and, with
`blind_group`, "privileged_blind" (`blind_approach.py`, the one host round trip). extras["time_outs"] marks
truncations; extras["log"] the ended episodes' reward terms, successes and terminations (`_episode_log`).
"""

from __future__ import annotations

import numpy as np
import torch
from rsl_rl.env import VecEnv
from tensordict import TensorDict

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.sim.batched_env import BatchedGraspEnv
from lerobot_blindgrasp.teacher.blind_approach import GROUP, ActorInput, BlindGroup


class RslRlGraspEnv(VecEnv):
    def __init__(
        self, env: BatchedGraspEnv, device: str = "cpu", on_step=None, blind_group: ActorInput | None = None
    ):
        self.env = env
        self._blind_group = None if blind_group is None else BlindGroup(blind_group)
        self.num_envs = env.num_envs
        self.num_actions = spec.NUM_JOINTS
        self.max_episode_length = env.max_episode_steps
        self.device = device
        self.step_dt = spec.CONTROL_DT  # seconds per env step; rsl-rl's RND scales its weight by it
        self.cfg = {"env": repr(env.cfg)}
        self._on_step = on_step  # e.g. a progress-bar tick
        self._obs = self._to_td(env.reset_tensors())

    @property
    def unwrapped(self) -> RslRlGraspEnv:
        """No wrappers here; rsl-rl's extensions read `env.unwrapped.step_dt`."""
        return self

    @property
    def episode_length_buf(self) -> torch.Tensor:
        return self.env.episode_length

    @episode_length_buf.setter
    def episode_length_buf(self, value: torch.Tensor) -> None:
        # rsl-rl's init_at_random_ep_len spreads time-outs over an iteration
        self.env.episode_length[:] = value.to(self.env.device)

    def _to_td(self, obs: dict[str, torch.Tensor]) -> TensorDict:
        if self._blind_group is not None:
            blind = self._blind_group({"privileged": obs["privileged"].cpu().numpy()})[GROUP]
            obs = {**obs, GROUP: torch.from_numpy(blind)}
        return TensorDict(
            {k: v.to(self.device) for k, v in obs.items()},
            batch_size=[self.num_envs],
            device=self.device,
        )

    def get_observations(self) -> TensorDict:
        return self._obs

    def step(self, actions: torch.Tensor):
        obs, reward, terminated, truncated, info = self.env.step_tensors(actions.detach().to(self.env.device))
        self._obs = self._to_td(obs)
        extras = {"time_outs": truncated.to(self.device), "log": self._episode_log(info)}
        if self._on_step is not None:
            self._on_step()
        return self._obs, reward.to(self.device, torch.float32), (terminated | truncated).to(self.device), extras

    def _episode_log(self, info: dict) -> dict[str, float | torch.Tensor]:
        """Scalars rsl-rl averages over an iteration; tensors stay on the device until rsl-rl writes its log."""
        log: dict = {"Metrics/physics_resets_total": float(self.env.physics_resets)}
        log["Metrics/mean_lift_cm"] = info["lift"].clamp_min(0).mean() * 100.0
        log["Metrics/mean_contacts"] = info["n_contact"].double().mean()
        final = info.get("final")
        if final is None:
            return log
        cfg = self.env.cfg.reward
        seconds = final["episode_length"] / spec.CONTROL_HZ
        for term, sums in final["terms"].items():
            log[f"Episode_Reward/{term}"] = (cfg.weight(term) * sums / seconds).mean()
        log["Episode_Termination/time_out"] = final["truncated"].double().mean()
        log["Episode_Termination/object_out_of_reach"] = final["terminated"].double().mean()
        success = final["success"].double()
        log["Metrics/success"] = success.mean()
        names = self.env.cfg.objects
        index = final["object_index"].cpu().numpy()  # which objects ended: a few ints, to name the log keys
        for k in np.unique(index):
            log[f"Success/{names[k]}"] = success[torch.from_numpy(index == k).to(success.device)].mean()
        return log
