"""Scripted side grasps as auxiliary demonstrations for the PPO actor (issue #9's lever for the small capsule).

Why: the `cpu` teacher never lifts the small capsule. It closes its tips on top of it and presses it into the table,
and neither reward changes nor exploration aids (RND, pre-grasp start states) moved it off that local optimum
(docs/results/teacher_cpu_v4.md, teacher_cpu_pregrasp.md). `sim.scripted.SideGraspScript`, which reads where the
object stands as the teacher's privileged observation does, lifts it from the paper's start pose under the paper's
randomization (docs/results/teacher_cpu_bc.md). So the actor is shown that grasp directly.

How (the demo-augmented policy gradient idea, Rajeswaran et al. 2018, "DAPG"): before training, the script is rolled
out on the listed objects from training start states; the successful episodes' (92-d privileged observation,
delta-theta) pairs are kept. After every PPO update, `steps` behaviour-cloning steps regress the actor's mean action
on minibatches of those pairs, with their own Adam optimizer whose learning rate decays linearly from `lr` to 0 over
`decay_iterations`. Once it is 0 the actor optimizes the paper's reward alone, so the optimum is the paper's.
Only the mean is cloned; the action std stays PPO's. The critic is untouched.

Wired into rsl-rl without changing its runner: the algorithm's `class_name` names `PPOWithScriptedDemos` and its
config carries a `scripted_demos` dict (presets/teacher.py `with_scripted_demos`), so it is recorded in the run's
`teacher_config.json` and checked on resume like every PPO setting.
"""

from __future__ import annotations

import logging

import torch
from rsl_rl.algorithms import PPO
from tensordict import TensorDict

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.teacher.scripted_demos import ScriptedDemos, collect

log = logging.getLogger("blindgrasp.teacher")


class PPOWithScriptedDemos(PPO):
    """rsl-rl's PPO, then behaviour-cloning steps on scripted demonstrations after every update (module docstring)."""

    def __init__(self, actor, critic, storage, *, scripted_demos: dict, **kwargs):
        super().__init__(actor, critic, storage, **kwargs)
        self.demo_cfg = ScriptedDemos(**{**scripted_demos, "objects": tuple(scripted_demos["objects"])})
        data = collect(self.demo_cfg)
        if len(data["obs"]) == 0:
            raise ValueError(f"the side-grasp script lifted none of {self.demo_cfg.objects}: no demonstrations")
        log.info("scripted demos: %d pairs; script success %s", len(data["obs"]), data["success"])
        self.demo_success = data["success"]
        self.demo_obs = torch.from_numpy(data["obs"]).to(self.device)
        self.demo_actions = torch.from_numpy(data["actions"]).to(self.device)
        self.bc_optimizer = torch.optim.Adam(self.actor.parameters(), lr=self.demo_cfg.lr)
        self.bc_iteration = 0  # updates done; train.py sets it on resume so the decay continues
        self._gen = torch.Generator(device="cpu").manual_seed(self.demo_cfg.seed)

    def update(self) -> dict[str, float]:
        losses = super().update()  # also refreshes the observation normalizer the cloning steps then use
        lr = self.demo_cfg.lr_at(self.bc_iteration)
        self.bc_iteration += 1
        losses["bc"] = self.bc_loss() if lr <= 0 else self._clone(lr)
        losses["bc_lr"] = lr
        return losses

    def _batch(self) -> tuple[TensorDict, torch.Tensor]:
        idx = torch.randint(len(self.demo_obs), (self.demo_cfg.batch_size,), generator=self._gen)
        obs = TensorDict({"privileged": self.demo_obs[idx]}, batch_size=[len(idx)], device=self.device)
        return obs, self.demo_actions[idx]

    def _clone(self, lr: float) -> float:
        for group in self.bc_optimizer.param_groups:
            group["lr"] = lr
        total = 0.0
        for _ in range(self.demo_cfg.steps):
            obs, target = self._batch()
            mean = self.actor(obs, stochastic_output=False)
            loss = ((mean - target) / spec.ACTION_BOUND_RAD).pow(2).mean()  # in units of the action bound
            self.bc_optimizer.zero_grad()
            loss.backward()
            torch.nn.utils.clip_grad_norm_(self.actor.parameters(), self.max_grad_norm)
            self.bc_optimizer.step()
            total += loss.item()
        return total / self.demo_cfg.steps

    @torch.no_grad()
    def bc_loss(self) -> float:
        """The cloning loss on one minibatch without a step (logged after the decay: does PPO keep the grasp?)."""
        obs, target = self._batch()
        return float(((self.actor(obs, stochastic_output=False) - target) / spec.ACTION_BOUND_RAD).pow(2).mean())
