"""Scripted side grasps cloned into the PPO actor, as in DAPG (Rajeswaran et al. 2018): how the shipped teacher
learned to lift the small capsule, which `cpu` alone presses into the table whatever the reward or exploration. The
weighted MSE of the actor's mean against the script's successful (observation, delta-theta) pairs joins PPO's loss
in each minibatch step, its weight decaying linearly to 0, after which the optimum is the paper's reward alone.
Wired in through rsl-rl's `class_name` (`ScriptedDemos.runner_cfg`), so it is recorded and checked on resume.
"""

from __future__ import annotations

import logging

import torch
from rsl_rl.algorithms import PPO
from tensordict import TensorDict

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.teacher.scripted_demos import ScriptedDemos, collect_scripted_demos

log = logging.getLogger("blindgrasp.teacher")


class PPOWithScriptedDemos(PPO):
    """rsl-rl's PPO plus the cloning loss, which `_JointCloningOptimizer` adds to each of PPO's optimizer steps."""

    def __init__(self, actor, critic, storage, *, scripted_demos: dict, **kwargs):
        super().__init__(actor, critic, storage, **kwargs)
        self.demo_cfg = ScriptedDemos(**{**scripted_demos, "objects": tuple(scripted_demos["objects"])})
        data = collect_scripted_demos(self.demo_cfg)
        if len(data["actions"]) == 0:
            raise ValueError(f"the side-grasp script lifted none of {self.demo_cfg.objects}: no demonstrations")
        log.info("scripted demos: %d pairs; script success %s", len(data["actions"]), data["success"])
        # Both observation groups: the actor reads whichever its obs_groups name.
        self.demo_obs = TensorDict(
            {k: torch.from_numpy(v) for k, v in data["obs"].items()},
            batch_size=[len(data["actions"])],
            device=self.device,
        )
        self.demo_actions = torch.from_numpy(data["actions"]).to(self.device)
        self.bc_iteration = 0  # updates done; train.py sets it on resume so the decay continues
        self._gen = torch.Generator(device="cpu").manual_seed(self.demo_cfg.seed)
        self._joint_weight = 0.0
        self._joint_losses: list[float] = []
        self._grad_ratios: list[float] = []
        self.optimizer = _JointCloningOptimizer(self.optimizer, self)

    def update(self) -> dict[str, float]:
        weight = self.demo_cfg.weight_at(self.bc_iteration)
        self._joint_weight = weight
        self._joint_losses, self._grad_ratios = [], []
        losses = super().update()
        self.bc_iteration += 1
        if self._joint_losses:
            losses["bc"] = sum(self._joint_losses) / len(self._joint_losses)
            losses["bc_grad_ratio"] = sum(self._grad_ratios) / len(self._grad_ratios)
        else:
            losses["bc"] = self.bc_loss()
        losses["bc_weight"] = weight
        return losses

    def add_joint_gradient(self) -> None:
        """Add weight x the cloning loss's gradient to the actor's gradients PPO has just computed."""
        if self._joint_weight <= 0:
            return
        obs, target = self._batch()
        loss = cloning_loss(self.actor(obs, stochastic_output=False), target)
        params = [p for p in self.actor.parameters() if p.requires_grad]
        grads = torch.autograd.grad(self._joint_weight * loss, params, allow_unused=True)
        ppo_sq = bc_sq = 0.0
        for p, g in zip(params, grads):
            if p.grad is not None:
                ppo_sq += float(p.grad.pow(2).sum())
            if g is not None:
                bc_sq += float(g.pow(2).sum())
                p.grad = g if p.grad is None else p.grad + g
        self._joint_losses.append(loss.item())
        # How hard the cloning pulls next to PPO (both on the actor), logged as Loss/bc_grad_ratio
        self._grad_ratios.append((bc_sq / max(ppo_sq, 1e-30)) ** 0.5)

    def _batch(self) -> tuple[TensorDict, torch.Tensor]:
        idx = torch.randint(len(self.demo_actions), (self.demo_cfg.batch_size,), generator=self._gen)
        return self.demo_obs[idx], self.demo_actions[idx]

    @torch.no_grad()
    def bc_loss(self) -> float:
        """The cloning loss on one minibatch without a step (logged after the decay: does PPO keep the grasp?)."""
        obs, target = self._batch()
        return float(cloning_loss(self.actor(obs, stochastic_output=False), target))


def cloning_loss(mean: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """Mean squared error of the actor's mean against the script's action, in units of the action bound."""
    return ((mean - target) / spec.ACTION_BOUND_RAD).pow(2).mean()


class _JointCloningOptimizer:
    """PPO's optimizer, whose `step` first adds the cloning gradient (a joint loss without rewriting PPO.update);
    everything else is delegated, so schedules and checkpoints see the wrapped optimizer itself."""

    def __init__(self, inner: torch.optim.Optimizer, alg: PPOWithScriptedDemos):
        self._inner = inner
        self._alg = alg

    def step(self, *args, **kwargs):
        self._alg.add_joint_gradient()
        return self._inner.step(*args, **kwargs)

    def __getattr__(self, name):
        return getattr(self._inner, name)
