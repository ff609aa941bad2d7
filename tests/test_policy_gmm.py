"""The GMM action head (`action_head="gmm"`, beyond the paper): its likelihood, its modes, its checkpoints."""

from __future__ import annotations

import math

import pytest
import torch
from lerobot.configs import FeatureType, PolicyFeature, PreTrainedConfig
from lerobot.utils.constants import ACTION, OBS_STATE

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.policies.blindgrasp_transformer import BlindgraspTransformerConfig, BlindgraspTransformerPolicy
from lerobot_blindgrasp.policies.blindgrasp_transformer import gmm_head

pytestmark = pytest.mark.usefixtures("one_torch_thread")
A = spec.ACTION_DIM
FEATURES = {
    "input_features": {OBS_STATE: PolicyFeature(FeatureType.STATE, (spec.STATE_DIM,))},
    "output_features": {ACTION: PolicyFeature(FeatureType.ACTION, (A,))},
}


def test_the_loss_is_the_mixtures_negative_log_likelihood_by_hand():
    # Two modes with hand-picked raw parameters: means tanh(raw), stds softplus(raw) + min_std, weights softmax.
    mean_raw = torch.tensor([[0.2] * A, [-0.4] * A])
    scale_raw = torch.tensor([[0.0] * A, [1.0] * A])
    logits = torch.tensor([0.3, -0.2])
    raw = torch.cat([mean_raw.flatten(), scale_raw.flatten(), logits])[None]
    action = torch.full((1, A), 0.1)
    min_std = 1e-3

    w = logits.softmax(0)
    density = 0.0
    for k in range(2):
        mu, sd = math.tanh(mean_raw[k, 0].item()), math.log1p(math.exp(scale_raw[k, 0].item())) + min_std
        per_joint = math.exp(-0.5 * ((0.1 - mu) / sd) ** 2) / (sd * math.sqrt(2 * math.pi))
        density += w[k].item() * per_joint**A
    nll = gmm_head.negative_log_likelihood(raw, action, modes=2, min_std=min_std)
    assert nll.shape == (1,)
    assert nll.item() == pytest.approx(-math.log(density), rel=1e-5)
    # Acting: the heaviest mode's mean, and the mixture mean the MSE head would regress to.
    torch.testing.assert_close(gmm_head.act(raw, 2, min_std, "mode"), torch.tanh(mean_raw[:1]))
    expected_mean = (w[:, None] * torch.tanh(mean_raw)).sum(0, keepdim=True)
    torch.testing.assert_close(gmm_head.mixture_mean(raw, 2, min_std), expected_mean)


def _policy(head: str, seed: int = 0) -> BlindgraspTransformerPolicy:
    torch.manual_seed(seed)
    config = BlindgraspTransformerConfig(size="quick", device="cpu", dropout=0.0, action_head=head, gmm_modes=2,
                                         gmm_eval="sample", **FEATURES)
    return BlindgraspTransformerPolicy(config)


def _fit(policy: BlindgraspTransformerPolicy, steps: int = 300) -> None:
    """Two actions for the very same observations, half of the samples each: what the student meets when a small
    capsule and a medium object feel alike and the teacher goes low on one and stays high on the other."""
    gen = torch.Generator().manual_seed(1)
    optimizer = torch.optim.AdamW(policy.get_optim_params(), lr=2e-3)
    policy.train()
    for _ in range(steps):
        states = torch.randn(64, 30, spec.STATE_DIM, generator=gen) * 0.1
        sign = torch.randint(0, 2, (64, 1), generator=gen) * 2.0 - 1.0
        action = sign * 0.5 + 0.02 * torch.randn(64, A, generator=gen)
        loss, _ = policy.forward({OBS_STATE: states, ACTION: action})
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
    policy.eval()


def test_a_gmm_student_keeps_two_actions_apart_where_an_mse_student_averages_them():
    mse, gmm = _policy("mse"), _policy("gmm")
    _fit(mse)
    _fit(gmm)
    states = torch.randn(400, 30, spec.STATE_DIM, generator=torch.Generator().manual_seed(7)) * 0.1
    torch.manual_seed(3)
    mse_act = mse.predict_normalized_delta({OBS_STATE: states})
    gmm_act = gmm.predict_normalized_delta({OBS_STATE: states})
    assert mse_act.abs().mean() < 0.15  # the mean of +0.5 and -0.5: an action the data never shows
    # Every GMM action is one of the two the data shows, and both are drawn about as often as they were shown.
    assert (gmm_act.abs() - 0.5).abs().max() < 0.1
    high = (gmm_act[:, 0] > 0).float().mean().item()
    assert 0.3 < high < 0.7
    # "mode" picks the heavier one every time: deterministic.
    gmm.config.gmm_eval = "mode"
    first = gmm.predict_normalized_delta({OBS_STATE: states})
    torch.testing.assert_close(first, gmm.predict_normalized_delta({OBS_STATE: states}))
    assert (first.abs() - 0.5).abs().max() < 0.1


def test_the_head_round_trips_through_a_checkpoint_and_old_checkpoints_stay_mse(tmp_path):
    policy = _policy("gmm")
    policy.save_pretrained(tmp_path / "gmm")
    reloaded = BlindgraspTransformerPolicy.from_pretrained(tmp_path / "gmm").eval()
    assert (reloaded.config.action_head, reloaded.config.gmm_modes) == ("gmm", 2)
    states = torch.randn(2, 30, spec.STATE_DIM)
    torch.testing.assert_close(reloaded.model(states), policy.eval().model(states))
    assert reloaded.model(states).shape == (2, gmm_head.output_dim(2))

    # A checkpoint saved before the head existed has no action_head field: it loads as the paper's MSE student.
    config = BlindgraspTransformerConfig(size="quick", device="cpu", **FEATURES)
    (tmp_path / "old").mkdir()
    config._save_pretrained(tmp_path / "old")
    saved = (tmp_path / "old" / "config.json").read_text()
    stripped = "\n".join(line for line in saved.splitlines() if "gmm" not in line and "action_head" not in line)
    (tmp_path / "old" / "config.json").write_text(stripped)
    assert PreTrainedConfig.from_pretrained(tmp_path / "old").action_head == "mse"


@pytest.mark.parametrize("bad", [{"action_head": "l1"}, {"gmm_modes": 0}, {"gmm_min_std": 0.0},
                                 {"gmm_eval": "mean"}])
def test_bad_head_settings_are_refused(bad):
    with pytest.raises(ValueError, match=next(iter(bad))):
        BlindgraspTransformerConfig(size="quick", device="cpu", **FEATURES, **bad)
