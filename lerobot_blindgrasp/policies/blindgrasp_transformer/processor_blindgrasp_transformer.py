"""Pre/post processors of `blindgrasp_transformer`: state z-scoring and the absolute-target <-> delta conversion.
A LeRobot `action` is the ABSOLUTE joint target (rad), target = q_now + delta; the network predicts delta / 0.3.

    preprocessor   rename -> add batch dim -> device -> [blindgrasp_sensor_augment, training only]
                   -> blindgrasp_target_to_delta   q_now := the raw joints of observation.state's last frame,
                                                   passed on as `Q_NOW`; action := clip((target - q_now) / 0.3)
                   -> normalizer                   observation.state z-scored (MEAN_STD); q_now never is
    select_action  action := q_now + 0.3 * pred, with the q_now that came with the observation
    postprocessor  unnormalizer (identity for the action; kept for lerobot-train's overrides) -> device(cpu)

The policy makes the target (LeRobot's postprocessor sees only the policy's output), so nothing is remembered
between calls. LeRobot's `RelativeActionsProcessorStep` takes the whole state, does no bound scaling, and is refused
by lerobot-rollout's sync engine.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import torch
from lerobot.lerobot_types import EnvTransition, PolicyAction, TransitionKey
from lerobot.processor import PolicyProcessorPipeline, ProcessorStep, ProcessorStepRegistry
from lerobot.processor.factory import make_default_policy_processor_steps, make_policy_processor_pipelines
from lerobot.utils.constants import OBS_STATE
from torch import Tensor

from lerobot_blindgrasp import spec

from .configuration_blindgrasp_transformer import BlindgraspTransformerConfig

# The raw joint positions (B, 9) of the observation being acted on, added to the batch by the preprocessor.
Q_NOW = "observation.blindgrasp_q_now"


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
    """Passes q_now (from the raw state) on to the policy as `Q_NOW`, and turns an absolute-target action, if any,
    into delta / bound."""

    action_bound: float = spec.ACTION_BOUND_RAD

    def get_config(self) -> dict[str, Any]:
        return asdict(self)

    def transform_features(self, features):
        return features  # `Q_NOW` is the policy's input only, never a dataset feature; `action` changes meaning

    def __call__(self, transition: EnvTransition) -> EnvTransition:
        observation = transition.get(TransitionKey.OBSERVATION) or {}
        state = observation.get(OBS_STATE)
        if state is None:
            raise KeyError(f"blindgrasp_target_to_delta needs '{OBS_STATE}' to know the current joint positions")
        q_now = (state[:, -1] if state.ndim == 3 else state)[..., spec.STATE_JOINT_SLICE]  # a window's last frame
        new_transition = transition.copy()
        new_transition[TransitionKey.OBSERVATION] = {**observation, Q_NOW: q_now}
        action = transition.get(TransitionKey.ACTION)
        if action is not None:
            new_transition[TransitionKey.ACTION] = target_to_normalized_delta(action, q_now, self.action_bound)
        return new_transition


@ProcessorStepRegistry.register("blindgrasp_sensor_augment")
@dataclass
class SensorAugmentStep(ProcessorStep):
    """Training-time sensor errors, drawn once per sample and held over its window (beyond the paper): a force gain
    g (log-uniform in [1/(1+force_gain), 1+force_gain]), a force offset b (+-force_bias_n) and a joint calibration
    offset d (+-joint_offset_rad per joint). The observation becomes (q + d, g f + b) and the target moves by d: the
    same step, as on a gripper whose encoders are off by d. Only (B, T, 12) windows with an action (training) change."""

    force_gain: float = 0.0
    force_bias_n: float = 0.0
    joint_offset_rad: float = 0.0
    enabled: bool = True

    def get_config(self) -> dict[str, Any]:
        return asdict(self)

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
    steps = [s.rename_observations, s.add_batch_dim, s.to_device]
    if config.augmentation_active:
        steps.append(
            SensorAugmentStep(
                force_gain=config.augment_force_gain,
                force_bias_n=config.augment_force_bias_n,
                joint_offset_rad=config.augment_joint_offset_rad,
            )
        )
    steps += [TargetToNormalizedDeltaStep(action_bound=spec.ACTION_BOUND_RAD), s.normalize]
    return make_policy_processor_pipelines(input_steps=steps, output_steps=[s.unnormalize, s.to_cpu])
