"""Pre/post processors of `blindgrasp_transformer`: state z-scoring and the absolute-target <-> delta conversion.

The action contract (`spec.ACTION_NAMES`): a LeRobot `action` is the ABSOLUTE joint target in radians, target = q_now +
delta, while the paper's network predicts delta / 0.3 in [-1, 1]. Both conversions live here, in the pipelines
saved with the checkpoint, so a checkpoint is self-contained:

    preprocessor  (training batch or one observation -> model input)
        rename -> add batch dim -> device
        -> blindgrasp_target_to_delta   action := clip((target - q_now) / 0.3, -1, 1); remembers q_now
        -> normalizer                   observation.state z-scored with dataset stats (MEAN_STD)
    postprocessor (model output -> action for the robot / sim env)
        -> unnormalizer                 identity for the action (kept so lerobot-train's fine-tuning overrides,
                                        which address `unnormalizer_processor`, find their step)
        -> blindgrasp_delta_to_target   action := q_now + 0.3 * pred
        -> device(cpu)

q_now is the current step's 9 joint positions, raw radians, from `observation.state`: its last frame for a training
window (B, T, 12), the observation itself at inference (B, 12). The target->delta step reads it before the
normalizer, so it is never z-scored.

The action is bounded once per layer: the model's output mapping keeps pred in [-1, 1] (tanh), and the env or the
robot clips the step to +-0.3 rad around the joints it measures and the target to the joint limits. This module adds
no third bound; the clip in the target -> delta step is of training targets, not of actions.

How the postprocessor knows q_now. LeRobot calls `postprocessor(action_tensor)` with nothing but the policy's
output tensor, so the observation cannot travel with it. Instead the two steps form a pair sharing one
`CurrentJoints` holder: the preprocessor step writes q_now into it on every call, the postprocessor step reads it.
LeRobot's policy loops (lerobot-eval, lerobot-rollout's sync engine) run pre -> policy -> post once per
observation, which is exactly the protocol this needs. The pair is linked by a `link` id
that both steps save in their JSON config; steps with the same id share one holder in this process (a registry of
weak references), so the link survives any way of loading, `PolicyProcessorPipeline.from_pretrained` twice or
LeRobot's `make_pre_post_processors(..., pretrained_path=...)`, with no reconnection code. Loading the same
checkpoint twice in one process gives two pipeline pairs on one holder: fine as long as each observation's pre/post
calls are not interleaved with the other pair's. The postprocessor raises if it runs before any observation was
seen, and if the batch size of the action and of the remembered q_now differ.

Why not LeRobot's own `RelativeActionsProcessorStep` / `AbsoluteActionsProcessorStep`: they take the whole state
(not the last frame of a window), do no bound scaling, and lerobot-rollout's sync engine refuses any pipeline that
contains an enabled `RelativeActionsProcessorStep` (it assumes action chunks); this policy acts one step at a time.
"""

from __future__ import annotations

import uuid
import weakref
from dataclasses import dataclass, field
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


class CurrentJoints:
    """q_now (B, 9), raw radians, of the last observation the paired preprocessor step saw."""

    __slots__ = ("q", "__weakref__")

    def __init__(self):
        self.q: Tensor | None = None


_LINKS: weakref.WeakValueDictionary[str, CurrentJoints] = weakref.WeakValueDictionary()


def _current_joints(link: str) -> CurrentJoints:
    holder = _LINKS.get(link)
    if holder is None:
        holder = CurrentJoints()
        _LINKS[link] = holder
    return holder


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


@dataclass
class _LinkedStep(ProcessorStep):
    """What both halves share: the `link` naming their `CurrentJoints` holder, the bound, and their saved config."""

    link: str = ""
    action_bound: float = spec.ACTION_BOUND_RAD
    _joints: CurrentJoints = field(init=False, repr=False)

    def get_config(self) -> dict[str, Any]:
        return {"link": self.link, "action_bound": self.action_bound}

    def transform_features(
        self, features: dict[PipelineFeatureType, dict[str, PolicyFeature]]
    ) -> dict[PipelineFeatureType, dict[str, PolicyFeature]]:
        return features  # same keys and shapes; only the meaning of `action` changes


@ProcessorStepRegistry.register("blindgrasp_target_to_delta")
@dataclass
class TargetToNormalizedDeltaStep(_LinkedStep):
    """Preprocessor half of the pair: remembers q_now and turns an absolute-target action into delta / bound.

    Runs on raw (not yet normalized) state. Observations without an action (inference) only update q_now.
    """

    def __post_init__(self):
        if not self.link:
            self.link = uuid.uuid4().hex
        self._joints = _current_joints(self.link)

    def __call__(self, transition: EnvTransition) -> EnvTransition:
        observation = transition.get(TransitionKey.OBSERVATION) or {}
        state = observation.get(OBS_STATE)
        if state is None:
            raise KeyError(f"blindgrasp_target_to_delta needs '{OBS_STATE}' to know the current joint positions")
        q_now = current_joints_from_state(state)
        self._joints.q = q_now
        action = transition.get(TransitionKey.ACTION)
        if action is None:
            return transition
        new_transition = transition.copy()
        new_transition[TransitionKey.ACTION] = target_to_normalized_delta(action, q_now, self.action_bound)
        return new_transition


@ProcessorStepRegistry.register("blindgrasp_delta_to_target")
@dataclass
class NormalizedDeltaToTargetStep(_LinkedStep):
    """Postprocessor half of the pair: delta / bound from the network -> absolute target, with q_now shared by the
    preprocessor step of the same `link`."""

    def __post_init__(self):
        if not self.link:
            raise ValueError("blindgrasp_delta_to_target needs the `link` of its blindgrasp_target_to_delta step")
        self._joints = _current_joints(self.link)

    def __call__(self, transition: EnvTransition) -> EnvTransition:
        action = transition.get(TransitionKey.ACTION)
        if action is None:
            return transition
        q_now = self._joints.q
        if q_now is None:
            raise RuntimeError(
                "blindgrasp_delta_to_target: no observation seen yet. Run the policy's preprocessor on the "
                "observation before postprocessing the action computed from it."
            )
        if q_now.shape[0] != action.shape[0]:
            raise RuntimeError(
                f"blindgrasp_delta_to_target: action batch {action.shape[0]} != batch {q_now.shape[0]} of the "
                "last preprocessed observation; pre/post calls of two pipelines were interleaved."
            )
        new_transition = transition.copy()
        new_transition[TransitionKey.ACTION] = normalized_delta_to_target(action, q_now, self.action_bound)
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
        return {"force_gain": self.force_gain, "force_bias_n": self.force_bias_n,
                "joint_offset_rad": self.joint_offset_rad, "enabled": self.enabled}

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
    to_target = NormalizedDeltaToTargetStep(link=to_delta.link, action_bound=spec.ACTION_BOUND_RAD)
    augment = [] if not config.augmentation_active else [SensorAugmentStep(
        force_gain=config.augment_force_gain, force_bias_n=config.augment_force_bias_n,
        joint_offset_rad=config.augment_joint_offset_rad)]
    return make_policy_processor_pipelines(
        input_steps=[s.rename_observations, s.add_batch_dim, s.to_device, *augment, to_delta, s.normalize],
        output_steps=[s.unnormalize, to_target, s.to_cpu],
    )
