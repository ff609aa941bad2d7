"""Pre/post processors of `blindgrasp_transformer`: state z-scoring and the absolute-target <-> delta conversion.

The action contract (`spec.ACTION_NAMES`): a LeRobot `action` is the ABSOLUTE joint target in radians, target = q_now +
delta, while the paper's network predicts delta / 0.3 in [-1, 1]. The pipelines saved with the checkpoint prepare
both directions, so a checkpoint is self-contained:

    preprocessor  (training batch or one observation -> model input)
        rename -> add batch dim -> device
        -> blindgrasp_target_to_delta   q_now := the raw joints of observation.state, passed on as `Q_NOW`;
                                        action (training) := clip((target - q_now) / 0.3, -1, 1)
        -> normalizer                   observation.state z-scored with dataset stats (MEAN_STD)
    policy.select_action                action := q_now + 0.3 * pred, with the q_now that came with the observation
    postprocessor (policy output -> action for the robot / sim env)
        -> unnormalizer                 identity for the action (kept so lerobot-train's fine-tuning overrides,
                                        which address `unnormalizer_processor`, find their step)
        -> device(cpu)

q_now is the current step's 9 joint positions, raw radians, from `observation.state`: its last frame for a training
window (B, T, 12), the observation itself at inference (B, 12). The target->delta step reads it before the
normalizer, so it is never z-scored.

Why the policy, not the postprocessor, turns its prediction into a target: LeRobot calls `postprocessor(action)`
with nothing but the policy's output tensor, and loads the two pipelines of a checkpoint independently of each
other, so a postprocessor step could only learn q_now through state shared behind LeRobot's back. The observation
does reach the policy, so q_now travels with it (`Q_NOW`) and nothing is remembered between calls: any number of
policies and pipelines can run interleaved in one process.

The action is bounded once per layer: the model's output mapping keeps pred in [-1, 1] (tanh), and the env or the
robot clips the step to +-0.3 rad around the joints it measures and the target to the joint limits. This module adds
no third bound; the clip in the target -> delta step is of training targets, not of actions.

Why not LeRobot's own `RelativeActionsProcessorStep` / `AbsoluteActionsProcessorStep`: they take the whole state
(not the last frame of a window), do no bound scaling, and lerobot-rollout's sync engine refuses any pipeline that
contains an enabled `RelativeActionsProcessorStep` (it assumes action chunks); this policy acts one step at a time.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import torch
from lerobot.configs import PipelineFeatureType, PolicyFeature
from lerobot.lerobot_types import EnvTransition, PolicyAction, TransitionKey
from lerobot.processor import (
    PolicyProcessorPipeline,
    ProcessorStep,
    ProcessorStepRegistry,
)
from lerobot.processor.factory import make_default_policy_processor_steps, make_policy_processor_pipelines
from lerobot.utils.constants import OBS_STATE
from torch import Tensor

from lerobot_blindgrasp import spec

from .configuration_blindgrasp_transformer import BlindgraspTransformerConfig

# The raw joint positions (B, 9) of the observation being acted on, added to the batch by the preprocessor.
Q_NOW = "observation.blindgrasp_q_now"


def current_joints_from_state(state: Tensor) -> Tensor:
    """Raw `observation.state` -> q_now: (B, T, 12) window -> its last frame's joints; (B, 12) -> its joints."""
    if state.ndim == 3:
        state = state[:, -1]
    return state[..., spec.STATE_JOINT_SLICE]


def target_to_normalized_delta(target: Tensor, q_now: Tensor, bound: float = spec.ACTION_BOUND_RAD) -> Tensor:
    """Absolute joint target (rad) -> delta / bound, clipped to [-1, 1] (the robot clips |delta| <= bound too)."""
    q_now = q_now.to(target)
    if target.ndim == q_now.ndim + 1:  # (B, H, 9) action chunks
        q_now = q_now.unsqueeze(-2)
    return ((target - q_now) / bound).clamp(-1.0, 1.0)


def normalized_delta_to_target(pred: Tensor, q_now: Tensor, bound: float = spec.ACTION_BOUND_RAD) -> Tensor:
    """Network output delta / bound (in [-1, 1], the model bounds it) -> absolute joint target q_now + bound * pred."""
    q_now = q_now.to(pred)
    if pred.ndim == q_now.ndim + 1:  # (B, 1, 9) from predict_action_chunk
        q_now = q_now.unsqueeze(-2)
    return q_now + bound * pred


@ProcessorStepRegistry.register("blindgrasp_target_to_delta")
@dataclass
class TargetToNormalizedDeltaStep(ProcessorStep):
    """Passes q_now on to the policy (`Q_NOW`) and turns an absolute-target action into delta / bound.

    Runs on raw (not yet normalized) state. Observations without an action (inference) only get `Q_NOW`.
    """

    action_bound: float = spec.ACTION_BOUND_RAD

    def get_config(self) -> dict[str, Any]:
        return {"action_bound": self.action_bound}

    def transform_features(
        self, features: dict[PipelineFeatureType, dict[str, PolicyFeature]]
    ) -> dict[PipelineFeatureType, dict[str, PolicyFeature]]:
        return features  # `Q_NOW` is the policy's input only, never a dataset feature; `action` changes meaning

    def __call__(self, transition: EnvTransition) -> EnvTransition:
        observation = transition.get(TransitionKey.OBSERVATION) or {}
        state = observation.get(OBS_STATE)
        if state is None:
            raise KeyError(f"blindgrasp_target_to_delta needs '{OBS_STATE}' to know the current joint positions")
        q_now = current_joints_from_state(state)
        new_transition = transition.copy()
        new_transition[TransitionKey.OBSERVATION] = {**observation, Q_NOW: q_now}
        action = transition.get(TransitionKey.ACTION)
        if action is not None:
            new_transition[TransitionKey.ACTION] = target_to_normalized_delta(action, q_now, self.action_bound)
        return new_transition


@ProcessorStepRegistry.register("blindgrasp_sensor_augment")
@dataclass
class SensorAugmentStep(ProcessorStep):
    """Training-time sensor errors, drawn once per sample and held over its whole window (beyond the paper).

    What a real gripper adds that the simulation's noise does not: a force gain error (g, log-uniform in
    [1/(1+force_gain), 1+force_gain]), a force offset (b, uniform in +-force_bias_n) and a joint calibration offset
    (d, uniform in +-joint_offset_rad per joint). The observation becomes (q + d, g f + b); the action target moves
    by the same d, so the commanded step target - q is unchanged, as on a gripper whose encoders are off by d.

    Acts only on training batches: a (B, T, 12) window that comes with an action. Inference observations (B, 12)
    and evaluation windows pass through unchanged. Placed before the target->delta step and the normalizer.
    """

    force_gain: float = 0.0
    force_bias_n: float = 0.0
    joint_offset_rad: float = 0.0
    enabled: bool = True

    def get_config(self) -> dict[str, Any]:
        return {
            "force_gain": self.force_gain,
            "force_bias_n": self.force_bias_n,
            "joint_offset_rad": self.joint_offset_rad,
            "enabled": self.enabled,
        }

    def transform_features(self, features):
        return features

    @property
    def active(self) -> bool:
        return self.enabled and (self.force_gain > 0 or self.force_bias_n > 0 or self.joint_offset_rad > 0)

    def __call__(self, transition: EnvTransition) -> EnvTransition:
        observation = transition.get(TransitionKey.OBSERVATION) or {}
        state, action = observation.get(OBS_STATE), transition.get(TransitionKey.ACTION)
        if not self.active or action is None or state is None or state.ndim != 3:
            return transition
        b = state.shape[0]
        u = torch.rand(b, 2 + spec.NUM_JOINTS, device=state.device, dtype=state.dtype) * 2 - 1
        gain = torch.exp(u[:, :1] * torch.log1p(torch.tensor(self.force_gain, dtype=state.dtype)))
        bias = u[:, 1:2] * self.force_bias_n
        offset = u[:, 2:] * self.joint_offset_rad
        state = state.clone()
        state[..., spec.STATE_FORCE_SLICE] = state[..., spec.STATE_FORCE_SLICE] * gain[:, None] + bias[:, None]
        state[..., spec.STATE_JOINT_SLICE] += offset[:, None]
        shift = offset if action.ndim == 2 else offset[:, None]
        new_transition = transition.copy()
        new_transition[TransitionKey.OBSERVATION] = {**observation, OBS_STATE: state}
        new_transition[TransitionKey.ACTION] = action + shift
        return new_transition


def make_blindgrasp_transformer_pre_post_processors(
    config: BlindgraspTransformerConfig,
    dataset_stats: dict[str, dict[str, torch.Tensor]] | None = None,
) -> tuple[
    PolicyProcessorPipeline[dict[str, Any], dict[str, Any]],
    PolicyProcessorPipeline[PolicyAction, PolicyAction],
]:
    """The policy's pipeline pair (see the module docstring); LeRobot finds it by name for `lerobot-train`."""
    s = make_default_policy_processor_steps(config, dataset_stats)
    to_delta = TargetToNormalizedDeltaStep(action_bound=spec.ACTION_BOUND_RAD)
    augment = (
        []
        if not config.augmentation_active
        else [
            SensorAugmentStep(
                force_gain=config.augment_force_gain,
                force_bias_n=config.augment_force_bias_n,
                joint_offset_rad=config.augment_joint_offset_rad,
            )
        ]
    )
    return make_policy_processor_pipelines(
        input_steps=[s.rename_observations, s.add_batch_dim, s.to_device, *augment, to_delta, s.normalize],
        output_steps=[s.unnormalize, s.to_cpu],
    )
