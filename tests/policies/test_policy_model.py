"""blindgrasp_transformer model and config: sizes, fast path == plain path, padding, rolling context, schedule."""

from __future__ import annotations

import pytest
import torch
from lerobot.configs import FeatureType, PolicyFeature, PreTrainedConfig
from lerobot.policies.factory import get_policy_class
from lerobot.utils.constants import ACTION, OBS_STATE

from lab.bench.policy_bench import flops_per_step
from lerobot_blindgrasp import spec
from lerobot_blindgrasp.policies.blindgrasp_transformer import (
    BlindgraspTransformerConfig,
    BlindgraspTransformerPolicy,
)
from lerobot_blindgrasp.policies.blindgrasp_transformer.processor_blindgrasp_transformer import Q_NOW

FEATURES = {
    "input_features": {OBS_STATE: PolicyFeature(FeatureType.STATE, (spec.STATE_DIM,))},
    "output_features": {ACTION: PolicyFeature(FeatureType.ACTION, (spec.ACTION_DIM,))},
}


pytestmark = pytest.mark.usefixtures("one_torch_thread")


def make_policy(size: str = "quick", seed: int = 0, **kw) -> BlindgraspTransformerPolicy:
    torch.manual_seed(seed)
    config = BlindgraspTransformerConfig(size=size, device="cpu", **FEATURES, **kw)
    policy = BlindgraspTransformerPolicy(config).eval()
    # robomimic's init (N(0, 0.02), zero positional embedding) makes an untrained model nearly constant. Give every
    # weight a unit-gain scale so that inputs and positions visibly move the output in these tests.
    with torch.no_grad():
        for _name, param in policy.model.named_parameters():
            if param.ndim == 2:
                param.normal_(0.0, param.shape[-1] ** -0.5)
        policy.model.pos_embed.normal_(0.0, 0.5)
    return policy


def test_paper_size_is_the_default_and_matches_table_iv():
    c = BlindgraspTransformerConfig(device="cpu")
    assert (c.size, c.n_layers, c.embed_dim, c.n_heads, c.head_hidden_dims) == ("paper", 6, 512, 8, [1024, 1024])
    assert (c.n_obs_steps, c.dropout, c.optimizer_lr, c.optimizer_weight_decay) == (30, 0.1, 1e-4, 0.01)
    assert c.observation_delta_indices == list(range(-29, 1))
    assert c.action_delta_indices is None
    optimizer = c.get_optimizer_preset()
    assert (optimizer.type, optimizer.lr, optimizer.weight_decay) == ("adamw", 1e-4, 0.01)
    # ~1.1 GFLOP per step, the number the latency benchmark's floor is built on.
    assert 1.1e9 < flops_per_step(c) < 1.2e9


def test_size_presets_and_explicit_overrides(tmp_path):
    c = BlindgraspTransformerConfig(size="cpu", n_layers=2, device="cpu", **FEATURES)
    assert (c.n_layers, c.embed_dim, c.n_heads) == (2, 128, 4)  # the explicit field wins over the preset
    c._save_pretrained(tmp_path)
    reloaded = PreTrainedConfig.from_pretrained(tmp_path)
    assert isinstance(reloaded, BlindgraspTransformerConfig)
    assert (reloaded.n_layers, reloaded.embed_dim, reloaded.head_hidden_dims) == (2, 128, [256, 256])
    with pytest.raises(ValueError, match="size"):
        BlindgraspTransformerConfig(size="huge", device="cpu")


def test_lerobot_resolves_the_policy_class_by_name():
    assert get_policy_class("blindgrasp_transformer") is BlindgraspTransformerPolicy


def test_features_are_checked_against_the_spec():
    bad = dict(FEATURES, input_features={OBS_STATE: PolicyFeature(FeatureType.STATE, (9,))})
    with pytest.raises(ValueError, match="observation.state"):
        BlindgraspTransformerPolicy(BlindgraspTransformerConfig(size="quick", device="cpu", **bad))


def random_pad(batch: int, t: int, seed: int) -> torch.Tensor:
    """LeRobot-style padding: a prefix of each window (0 to t-1 steps) is padded."""
    n_pad = torch.randint(0, t, (batch,), generator=torch.Generator().manual_seed(seed))
    return torch.arange(t)[None, :] < n_pad[:, None]


@pytest.mark.parametrize("size", ["quick", "cpu"])
def test_fast_path_equals_plain_path(size):
    policy = make_policy(size)
    states = torch.randn(6, 30, spec.STATE_DIM)
    is_pad = random_pad(6, 30, seed=1)
    with torch.no_grad():
        for pad in (None, is_pad):
            fast = policy.model(states, pad)
            plain = policy.model.forward_reference(states, pad)
            torch.testing.assert_close(fast, plain, atol=1e-5, rtol=1e-5)
    assert fast.shape == (6, spec.ACTION_DIM)


def test_padded_steps_do_not_influence_the_output():
    policy = make_policy()
    states = torch.randn(4, 30, spec.STATE_DIM)
    is_pad = torch.zeros(4, 30, dtype=torch.bool)
    is_pad[:, :12] = True
    with torch.no_grad():
        out = policy.model(states, is_pad)
        scrambled = states.clone()
        scrambled[:, :12] = torch.randn(4, 12, spec.STATE_DIM) * 10
        torch.testing.assert_close(policy.model(scrambled, is_pad), out, atol=1e-6, rtol=0)
        # A real (unpadded) step does matter: changing one must change the output.
        real_changed = states.clone()
        real_changed[:, 12] += 3.0
        assert (policy.model(real_changed, is_pad) - out).abs().max() > 1e-2
        # And without the mask the padded values would leak in.
        assert (policy.model(scrambled) - policy.model(states)).abs().max() > 1e-2


def test_select_action_shapes_and_reset():
    policy = make_policy()
    episode = torch.randn(5, 2, spec.STATE_DIM)
    policy.reset()
    q_now = torch.zeros(2, spec.NUM_JOINTS)  # what the preprocessor passes along: the raw joints

    def act(obs):
        return policy.select_action({OBS_STATE: obs, Q_NOW: q_now})

    first = [act(obs) for obs in episode]
    assert first[0].shape == (2, spec.ACTION_DIM)
    assert policy.predict_action_chunk({OBS_STATE: episode[0], Q_NOW: q_now}).shape == (2, 1, spec.ACTION_DIM)
    policy.reset()
    again = [act(obs) for obs in episode]
    for a, b in zip(first, again, strict=True):
        torch.testing.assert_close(a, b)
    # Without reset the context carries the previous episode: the same first observation predicts differently.
    assert (act(episode[0]) - first[0]).abs().max() > 1e-5


def test_rolling_context_is_the_padded_training_window():
    """Step by step through select_action's rolling context == one batched forward on LeRobot-style windows of the
    same episode.

    LeRobot's window for frame i holds frames max(0, i - 29 + k), k = 0..29, padding flagged where i - 29 + k < 0.
    """
    policy = make_policy(size="quick")
    n, t = 40, policy.config.n_obs_steps
    episode = torch.randn(n, spec.STATE_DIM)
    policy.reset()
    stepped = torch.cat([policy.predict_normalized_delta({OBS_STATE: episode[i : i + 1]}) for i in range(n)])

    idx = torch.arange(n)[:, None] + torch.arange(1 - t, 1)[None, :]
    windows, is_pad = episode[idx.clamp(min=0)], idx < 0
    with torch.no_grad():
        batched = policy.model(windows, is_pad)
        # The window seen at the last step is the dataset's window of the last frame.
        states, pad = policy.current_context()
        torch.testing.assert_close(states[0], windows[-1])
        assert torch.equal(pad[0], is_pad[-1])
    torch.testing.assert_close(stepped, batched, atol=1e-5, rtol=1e-5)


def test_training_loss_is_mse_on_the_last_token_and_learns():
    policy = make_policy(dropout=0.0)
    policy.train()
    states = torch.randn(16, 30, spec.STATE_DIM)
    is_pad = random_pad(16, 30, seed=2)
    target = torch.tanh(states[:, -1, :9])  # depends only on the current step
    batch = {OBS_STATE: states, f"{OBS_STATE}_is_pad": is_pad, ACTION: target}
    loss, info = policy.forward(batch)
    with torch.no_grad():
        expected = ((policy.model(states, is_pad) - target) ** 2).mean()
    torch.testing.assert_close(loss.detach(), expected)
    assert info["mse"] == pytest.approx(loss.item())
    per_sample, _ = policy.forward(batch, reduction="none")
    assert per_sample.shape == (16,)

    optimizer = torch.optim.AdamW(policy.get_optim_params(), lr=1e-3)
    for _ in range(60):
        optimizer.zero_grad()
        policy.forward(batch)[0].backward()
        optimizer.step()
    assert policy.forward(batch)[0].item() < 0.5 * loss.item()


def test_lr_schedule_is_constant_then_linear_decay():
    config = BlindgraspTransformerConfig(
        device="cpu", scheduler_constant_steps=100, scheduler_end_factor=0.1, **FEATURES
    )
    scheduler_config = config.get_scheduler_preset()
    optimizer = torch.optim.AdamW([torch.nn.Parameter(torch.zeros(1))], lr=1e-4)
    scheduler = scheduler_config.build(optimizer, num_training_steps=300)
    lrs = []
    for _ in range(300):
        lrs.append(optimizer.param_groups[0]["lr"])
        optimizer.step()
        scheduler.step()
    assert lrs[0] == lrs[99] == pytest.approx(1e-4)
    assert lrs[200] == pytest.approx(1e-4 * (1 - 0.9 * 0.5))
    assert lrs[299] == pytest.approx(1e-4 * (1 - 0.9 * 199 / 200))
    assert all(a >= b for a, b in zip(lrs, lrs[1:], strict=False))
