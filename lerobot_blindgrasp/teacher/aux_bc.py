"""Scripted side grasps as auxiliary demonstrations for the PPO actor (issue #9's lever for the small capsule).

Why: the `cpu` teacher never lifts the small capsule. It closes its tips on top of it and presses it into the table,
and neither reward changes nor exploration aids (RND, pre-grasp start states) moved it off that local optimum
(docs/results/teacher_cpu_v4.md, teacher_cpu_pregrasp.md). `sim.scripted.SideGraspScript`, which reads where the
object stands as the teacher's privileged observation does, lifts it from the paper's start pose under the paper's
randomization (docs/results/teacher_cpu_bc.md). So the actor is shown that grasp directly.

How (the demo-augmented policy gradient idea, Rajeswaran et al. 2018, "DAPG"): before training, the script is rolled
out on the listed objects from training start states; the successful episodes' (92-d privileged observation,
delta-theta) pairs are kept, and the actor's mean action is regressed on minibatches of them in one of two forms
(`ScriptedDemos.mode`): "interleaved", `steps` cloning steps with their own Adam after every PPO update; or "joint",
the cloning loss's gradient added to PPO's in each of PPO's minibatch steps (the form the shipped teacher uses).
Either weight decays linearly to 0 over `decay_iterations`; once it is 0 the actor optimizes the paper's reward
alone, so the optimum is the paper's.
Only the mean is cloned; the action std stays PPO's. The critic is untouched.

With `relabel_every` set (DAgger, Ross et al. 2011), the current actor is also rolled out from fresh start states
every few updates and the script's action at every state it reaches joins the demonstrations, so the cloning also
corrects the actor where it drifts off the script's path, not only on the script's own states. A resumed run
rebuilds the aggregate from the script's demos and the rounds after the resume.

Wired into rsl-rl without changing its runner: the algorithm's `class_name` names `PPOWithScriptedDemos` and its
config carries a `scripted_demos` dict (`ScriptedDemos.runner_cfg`), so it is recorded in the run's
`teacher_config.json` and checked on resume like every PPO setting.
"""

from __future__ import annotations

import logging

import numpy as np
import torch
from rsl_rl.algorithms import PPO
from tensordict import TensorDict

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.teacher.scripted_demos import ScriptedDemos, collect, relabel

log = logging.getLogger("blindgrasp.teacher")


class PPOWithScriptedDemos(PPO):
    """rsl-rl's PPO plus behaviour cloning of scripted demonstrations (module docstring): interleaved steps after
    every update, or a joint loss term that `_JointCloningOptimizer` adds to each of PPO's own optimizer steps."""

    def __init__(self, actor, critic, storage, *, scripted_demos: dict, **kwargs):
        super().__init__(actor, critic, storage, **kwargs)
        self.demo_cfg = ScriptedDemos(**{**scripted_demos, "objects": tuple(scripted_demos["objects"])})
        data = collect(self.demo_cfg)
        if len(data["actions"]) == 0:
            raise ValueError(f"the side-grasp script lifted none of {self.demo_cfg.objects}: no demonstrations")
        log.info("scripted demos: %d pairs; script success %s", len(data["actions"]), data["success"])
        self.demo_success = data["success"]
        self.demo_obs: TensorDict | None = None
        self.demo_actions: torch.Tensor | None = None
        self._add_demos(data)
        self.bc_optimizer = torch.optim.Adam(self.actor.parameters(), lr=self.demo_cfg.lr)
        self.bc_iteration = 0  # updates done; train.py sets it on resume so the decay continues
        self._gen = torch.Generator(device="cpu").manual_seed(self.demo_cfg.seed)
        self._joint_losses: list[float] = []
        self._grad_ratios: list[float] = []
        if self.demo_cfg.mode == "joint":
            self.optimizer = _JointCloningOptimizer(self.optimizer, self)

    def update(self) -> dict[str, float]:
        weight = self.demo_cfg.weight_at(self.bc_iteration)
        self._joint_weight = weight if self.demo_cfg.mode == "joint" else 0.0
        self._joint_losses, self._grad_ratios = [], []
        losses = super().update()  # also refreshes the observation normalizer the cloning steps then use
        self.bc_iteration += 1
        if self._joint_losses:
            losses["bc"] = sum(self._joint_losses) / len(self._joint_losses)
            losses["bc_grad_ratio"] = sum(self._grad_ratios) / len(self._grad_ratios)
        elif self.demo_cfg.mode == "interleaved" and weight > 0:
            losses["bc"] = self._clone(weight)
        else:
            losses["bc"] = self.bc_loss()
        losses["bc_weight"] = weight
        cfg, done = self.demo_cfg, self.bc_iteration - 1 - self.demo_cfg.start_iteration
        if cfg.relabel_every and weight > 0 and done % cfg.relabel_every == 0:
            data = relabel(cfg, self._act, done // cfg.relabel_every)
            self._add_demos(data)
            # The actor's own success on the round's fresh start states: a held-out-like curve at no extra cost
            losses["relabel_success"] = sum(data["success"].values()) / len(data["success"])
            losses["demo_pairs"] = float(len(self.demo_actions))
        return losses

    def _add_demos(self, data: dict) -> None:
        """Append (observation, script action) pairs. Both observation groups are kept: the actor reads whichever
        its obs_groups name (privileged, or o_t for "RL w/ o_t")."""
        obs = TensorDict({k: torch.from_numpy(v) for k, v in data["obs"].items()},
                         batch_size=[len(data["actions"])], device=self.device)
        actions = torch.from_numpy(data["actions"]).to(self.device)
        if self.demo_obs is None:
            self.demo_obs, self.demo_actions = obs, actions
        else:
            self.demo_obs = torch.cat([self.demo_obs, obs])
            self.demo_actions = torch.cat([self.demo_actions, actions])

    @torch.no_grad()
    def _act(self, obs: dict) -> np.ndarray:
        """The actor's mean action on numpy observations, as the relabelling rollouts step the env with it."""
        n = len(obs["privileged"])
        td = TensorDict({k: torch.from_numpy(v).float() for k, v in obs.items()}, batch_size=[n], device=self.device)
        return self.actor(td, stochastic_output=False).cpu().numpy().astype("float64")

    def add_joint_gradient(self) -> None:
        """Add weight x the cloning loss's gradient to the actor's gradients PPO has just computed."""
        if self._joint_weight <= 0:
            return
        obs, target = self._batch()
        loss = self._loss(self.actor(obs, stochastic_output=False), target)
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

    def _clone(self, lr: float) -> float:
        for group in self.bc_optimizer.param_groups:
            group["lr"] = lr
        total = 0.0
        for _ in range(self.demo_cfg.steps):
            obs, target = self._batch()
            mean = self.actor(obs, stochastic_output=False)
            loss = self._loss(mean, target)
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
        return float(self._loss(self.actor(obs, stochastic_output=False), target))

    def _loss(self, mean: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
        return cloning_loss(mean, target, self.demo_cfg.saturation_aware)


def cloning_loss(mean: torch.Tensor, target: torch.Tensor, saturation_aware: bool) -> torch.Tensor:
    """Mean squared error of the actor's mean against the script's action, in units of the action bound.

    The env clips every action to +-ACTION_BOUND_RAD, and the script's own actions are clipped the same way, so a
    target at the bound means "at least this far". `saturation_aware` then only penalizes a mean short of it: a
    mean of 1 rad against a target of +0.3 executes the same action and costs nothing. Without it, such states
    (most of DAgger's, where the actor is far off the script's path) dominate the loss."""
    err = mean - target
    if saturation_aware:
        bound = spec.ACTION_BOUND_RAD - 1e-6
        err = torch.where(target >= bound, torch.clamp(err, max=0.0), err)
        err = torch.where(target <= -bound, torch.clamp(err, min=0.0), err)
    return (err / spec.ACTION_BOUND_RAD).pow(2).mean()


class _JointCloningOptimizer:
    """PPO's optimizer, whose `step` first adds the cloning gradient: the joint loss without rewriting
    `PPO.update` (which calls zero_grad, backward, clip, step once per minibatch). Everything else is delegated, so
    learning-rate schedules and checkpoints see the wrapped optimizer itself."""

    def __init__(self, inner: torch.optim.Optimizer, alg: PPOWithScriptedDemos):
        self._inner = inner
        self._alg = alg

    def step(self, *args, **kwargs):
        self._alg.add_joint_gradient()
        return self._inner.step(*args, **kwargs)

    def __getattr__(self, name):
        return getattr(self._inner, name)
