"""blindgrasp_transformer processors: target <-> delta / 0.3, q_now passed along, state z-scoring, save/load."""

from __future__ import annotations

import pytest
import torch
from lerobot.configs import FeatureType, NormalizationMode, PolicyFeature
from lerobot.policies.factory import make_pre_post_processors
from lerobot.processor import PolicyProcessorPipeline
from lerobot.processor.converters import (
    batch_to_transition,
    policy_action_to_transition,
    transition_to_batch,
    transition_to_policy_action,
)
from lerobot.utils.constants import ACTION, OBS_STATE

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.policies.blindgrasp_transformer import (
    BlindgraspTransformerConfig,
    BlindgraspTransformerPolicy,
    make_blindgrasp_transformer_pre_post_processors,
)
from lerobot_blindgrasp.policies.blindgrasp_transformer.processor_blindgrasp_transformer import (
    Q_NOW,
    TargetToNormalizedDeltaStep,
    normalized_delta_to_target,
)

BOUND = spec.ACTION_BOUND_RAD
T = 30


pytestmark = pytest.mark.usefixtures("one_torch_thread")


def make_config(**kw) -> BlindgraspTransformerConfig:
    return BlindgraspTransformerConfig(
        size="quick",
        device="cpu",
        input_features={OBS_STATE: PolicyFeature(FeatureType.STATE, (spec.STATE_DIM,))},
        output_features={ACTION: PolicyFeature(FeatureType.ACTION, (spec.ACTION_DIM,))},
        **kw,
    )


def make_stats() -> dict:
    g = torch.Generator().manual_seed(0)
    state_mean, state_std = torch.randn(spec.STATE_DIM, generator=g), torch.rand(spec.STATE_DIM, generator=g) + 0.5
    # Action stats deliberately far from (0, 1): if they were applied to the delta the round trip would break.
    action = {"mean": torch.full((spec.ACTION_DIM,), 5.0), "std": torch.full((spec.ACTION_DIM,), 3.0)}
    action |= {"min": action["mean"] - 1, "max": action["mean"] + 1}
    state = {"mean": state_mean, "std": state_std, "min": state_mean - 1, "max": state_mean + 1}
    return {OBS_STATE: state, ACTION: action}


def random_state(*shape: int, seed: int = 0) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    state = torch.randn(*shape, spec.STATE_DIM, generator=g)
    state[..., spec.STATE_FORCE_SLICE] = state[..., spec.STATE_FORCE_SLICE].abs() * 3  # forces in N, >= 0
    return state


@pytest.fixture
def pipelines():
    return make_blindgrasp_transformer_pre_post_processors(make_config(), make_stats())


def test_training_batch_action_becomes_delta_over_bound_from_last_frame(pipelines):
    pre, _ = pipelines
    window = random_state(4, T)
    delta = torch.empty(4, spec.ACTION_DIM).uniform_(-BOUND, BOUND)
    target = window[:, -1, spec.STATE_JOINT_SLICE] + delta  # q_now is the LAST frame of the window
    out = pre({OBS_STATE: window, ACTION: target, f"{OBS_STATE}_is_pad": torch.zeros(4, T, dtype=torch.bool)})
    torch.testing.assert_close(out[ACTION], delta / BOUND, atol=1e-5, rtol=0)
    # A delta taken from the first frame instead would be wrong: make sure the frames differ enough to tell.
    wrong = (target - window[:, 0, spec.STATE_JOINT_SLICE]) / BOUND
    assert not torch.allclose(out[ACTION], wrong.clamp(-1, 1), atol=1e-3)


def test_state_is_z_scored_with_dataset_stats(pipelines):
    pre, _ = pipelines
    stats = make_stats()[OBS_STATE]
    window = random_state(2, T)
    out = pre({OBS_STATE: window.clone(), ACTION: window[:, -1, :9]})
    torch.testing.assert_close(out[OBS_STATE], (window - stats["mean"]) / stats["std"], atol=1e-5, rtol=1e-5)


def test_round_trip_target_delta_target_at_inference(pipelines):
    pre, _ = pipelines
    obs = random_state(3, seed=1)  # one observation per env, as lerobot-eval sends it
    delta = torch.empty(3, spec.ACTION_DIM).uniform_(-BOUND, BOUND)
    target = obs[:, spec.STATE_JOINT_SLICE] + delta
    out = pre({OBS_STATE: obs, ACTION: target})
    torch.testing.assert_close(out[ACTION], delta / BOUND, atol=1e-5, rtol=0)
    torch.testing.assert_close(normalized_delta_to_target(out[ACTION], out[Q_NOW]), target, atol=1e-5, rtol=0)


def test_the_observation_carries_its_raw_joints_and_the_policy_acts_with_them(pipelines):
    pre, post = pipelines
    obs = random_state(2, seed=2)
    batch = pre({OBS_STATE: obs})  # inference: no action
    torch.testing.assert_close(batch[Q_NOW], obs[:, spec.STATE_JOINT_SLICE])  # raw radians, not z-scored
    policy = BlindgraspTransformerPolicy(make_config()).eval()
    target = post(policy.select_action(batch))
    policy.reset()
    pred = policy.predict_normalized_delta(batch)
    torch.testing.assert_close(target, obs[:, spec.STATE_JOINT_SLICE] + BOUND * pred, atol=1e-6, rtol=0)
    # (B, 1, 9) chunks from predict_action_chunk broadcast over the chunk axis.
    torch.testing.assert_close(normalized_delta_to_target(pred[:, None], batch[Q_NOW]), target[:, None])


def test_training_deltas_beyond_the_bound_are_clipped_and_actions_are_bounded_once(pipelines):
    pre, post = pipelines
    obs = random_state(1, seed=3)
    q = obs[:, spec.STATE_JOINT_SLICE]
    normalized = pre({OBS_STATE: obs, ACTION: q + torch.linspace(-1.0, 1.0, 9)})[ACTION]
    assert normalized.min() == -1.0 and normalized.max() == 1.0  # training targets fit the model's tanh
    # Nothing after the model adds a bound of its own: the model's output mapping is the policy's one bound, the
    # env's or the robot's +-0.3 rad step clip the next one.
    torch.testing.assert_close(
        normalized_delta_to_target(torch.full((1, 9), 7.0), q), q + 7.0 * BOUND, atol=1e-5, rtol=0
    )
    torch.testing.assert_close(post(torch.full((1, 9), 7.0)), torch.full((1, 9), 7.0))


@pytest.mark.parametrize("tanh_output", [True, False])
def test_the_model_bounds_its_action_to_the_unit_box(tanh_output):
    policy = BlindgraspTransformerPolicy(make_config(tanh_output=tanh_output)).eval()
    with torch.no_grad():  # a last layer scaled up so that the raw output leaves [-1, 1] by far
        policy.model.head[-1].weight.mul_(1e4)
        policy.model.head[-1].bias.fill_(3.0)
    pred = policy.predict_normalized_delta({OBS_STATE: random_state(4, seed=5)})
    assert pred.abs().max() <= 1.0 and pred.abs().max() > 0.99


def test_the_policy_acts_only_on_preprocessed_observations():
    policy = BlindgraspTransformerPolicy(make_config()).eval()
    with pytest.raises(KeyError, match=Q_NOW):
        policy.select_action({OBS_STATE: random_state(1)})


def test_interleaved_policies_share_nothing():
    """No state outside the objects: two policies' pre -> act calls interleaved give each its own targets."""
    (pre_a, post_a), (pre_b, post_b) = (
        make_blindgrasp_transformer_pre_post_processors(make_config(), make_stats()) for _ in range(2)
    )
    policy_a, policy_b = (BlindgraspTransformerPolicy(make_config()).eval() for _ in range(2))
    obs_a, obs_b = random_state(1, seed=4), random_state(1, seed=5)
    batch_a, batch_b = pre_a({OBS_STATE: obs_a}), pre_b({OBS_STATE: obs_b})
    target_b, target_a = post_b(policy_b.select_action(batch_b)), post_a(policy_a.select_action(batch_a))
    for target, obs in ((target_a, obs_a), (target_b, obs_b)):
        assert (target - obs[:, spec.STATE_JOINT_SLICE]).abs().max() <= BOUND + 1e-6
    assert not any(isinstance(v, torch.Tensor) for v in vars(pre_a.steps[3]).values())


def test_saved_pipelines_reload(tmp_path):
    config = make_config()
    pre, post = make_blindgrasp_transformer_pre_post_processors(config, make_stats())
    pre.save_pretrained(tmp_path)
    post.save_pretrained(tmp_path)

    pre2 = PolicyProcessorPipeline.from_pretrained(
        tmp_path, "policy_preprocessor.json", to_transition=batch_to_transition, to_output=transition_to_batch
    )
    post2 = PolicyProcessorPipeline.from_pretrained(
        tmp_path,
        "policy_postprocessor.json",
        to_transition=policy_action_to_transition,
        to_output=transition_to_policy_action,
    )
    step = next(s for s in pre2.steps if isinstance(s, TargetToNormalizedDeltaStep))
    assert step.get_config() == {"action_bound": BOUND}
    pre3, post3 = make_pre_post_processors(config, pretrained_path=str(tmp_path))
    for p, q in ((pre2, post2), (pre3, post3)):
        obs = random_state(2, seed=6)
        delta = torch.empty(2, spec.ACTION_DIM).uniform_(-BOUND, BOUND)
        out = p({OBS_STATE: obs, ACTION: obs[:, spec.STATE_JOINT_SLICE] + delta})
        torch.testing.assert_close(out[ACTION], delta / BOUND, atol=1e-5, rtol=0)
        torch.testing.assert_close(out[Q_NOW], obs[:, spec.STATE_JOINT_SLICE])
        torch.testing.assert_close(q(out[ACTION]), out[ACTION])  # the postprocessor leaves the action as it is
    # The saved normalizer stats came back too.
    stats = make_stats()[OBS_STATE]
    obs = random_state(1, seed=8)
    torch.testing.assert_close(pre3({OBS_STATE: obs})[OBS_STATE], (obs - stats["mean"]) / stats["std"])


def test_action_normalization_must_stay_identity():
    with pytest.raises(ValueError, match="IDENTITY"):
        mapping = {"STATE": NormalizationMode.MEAN_STD, "ACTION": NormalizationMode.MIN_MAX}
        make_config(normalization_mapping=mapping)


def test_sensor_augmentation_shifts_joints_and_target_together_and_only_in_training():
    from lerobot_blindgrasp.policies.blindgrasp_transformer.processor_blindgrasp_transformer import (
        SensorAugmentStep,
    )

    cfg = make_config(augment_force_gain=0.3, augment_force_bias_n=2.0, augment_joint_offset_rad=0.05)
    pre, _ = make_blindgrasp_transformer_pre_post_processors(cfg, make_stats())
    plain_pre, _ = make_blindgrasp_transformer_pre_post_processors(make_config(), make_stats())
    assert any(isinstance(s, SensorAugmentStep) for s in pre.steps)
    assert not any(isinstance(s, SensorAugmentStep) for s in plain_pre.steps)  # the paper's recipe: no step
    step = next(s for s in pre.steps if isinstance(s, SensorAugmentStep))
    b = 256
    state = random_state(b, T)
    target = state[:, -1, spec.STATE_JOINT_SLICE] + 0.1
    torch.manual_seed(0)
    out = step(batch_to_transition({OBS_STATE: state, ACTION: target}))
    new_state, new_target = out["observation"][OBS_STATE], out["action"]
    offset = new_state[..., spec.STATE_JOINT_SLICE] - state[..., spec.STATE_JOINT_SLICE]
    # One offset per sample and joint, held over the window, within the range, and the target moved with it.
    assert torch.allclose(offset, offset[:, :1].expand_as(offset), atol=1e-6)
    assert offset.abs().max() <= 0.05 + 1e-6 and offset.abs().max() > 0.04
    assert torch.allclose(new_target - target, offset[:, 0], atol=1e-6)
    # Forces: g f + b per sample, g in [1/1.3, 1.3], |b| <= 2 N (fit g, b from two frames of the window).
    f, nf = state[..., spec.STATE_FORCE_SLICE], new_state[..., spec.STATE_FORCE_SLICE]
    g = (nf[:, 1, 0] - nf[:, 0, 0]) / (f[:, 1, 0] - f[:, 0, 0])
    bias = nf[:, 0, 0] - g * f[:, 0, 0]
    assert g.min() >= 1 / 1.3 - 1e-4 and g.max() <= 1.3 + 1e-4 and bias.abs().max() <= 2.0 + 1e-4
    assert torch.allclose(nf, g[:, None, None] * f + bias[:, None, None], atol=1e-4)
    # Inference: a single observation (no action) and an action-less window pass unchanged.
    obs = random_state(4)
    assert torch.equal(step(batch_to_transition({OBS_STATE: obs}))["observation"][OBS_STATE], obs)
    win = random_state(4, T)
    assert torch.equal(step(batch_to_transition({OBS_STATE: win}))["observation"][OBS_STATE], win)
    # Saved with the checkpoint's preprocessor: it reloads with its ranges.
    assert step.get_config() == {"force_gain": 0.3, "force_bias_n": 2.0, "joint_offset_rad": 0.05, "enabled": True}
