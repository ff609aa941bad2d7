"""The `blindgrasp_transformer` student: robomimic's BC-Transformer (`TransformerActorNetwork` + `GPT_Backbone`,
deterministic head) over o_t = (9 joint positions, 3 forces). B batch, T context (30), D embed_dim, A = 9 joints:

    token_t = Dropout(LayerNorm(Linear(12 -> D)(o_t) + pos[t]))      learned pos = nn.Parameter(1, T, D), zeros
    n_layers x pre-LN block: x + Attn(LN(x)), x + MLP(LN(x))      fused qkv (no bias), GELU MLP 4x
    final LayerNorm -> MLP head [1024, 1024] on the LAST token -> A -> tanh

A window that starts before its episode repeats the first frame, flagged in `observation.state_is_pad`; padded keys
are masked out of attention, and the inference context starts the same way, so step t sees what training saw for
frame t. `forward` runs the last layer for the last token only; `forward_reference` (every token) checks it.
"""

from __future__ import annotations

from collections import deque

import torch
import torch.nn.functional as F  # noqa: N812
from lerobot.policies.pretrained import PreTrainedPolicy
from lerobot.utils.constants import ACTION, OBS_STATE
from torch import Tensor, nn

from lerobot_blindgrasp import policy_contract, project, spec

from .configuration_blindgrasp_transformer import BlindgraspTransformerConfig, TrainedFor
from .processor_blindgrasp_transformer import Q_NOW, normalized_delta_to_target

STATE_IS_PAD = f"{OBS_STATE}_is_pad"
# The distribution that registers this policy type with LeRobot: the model card says to install it.
PACKAGE = "lerobot_policy_blindgrasp"
CARD_INSTALL = f"""
## Install first

This policy type comes from a LeRobot plugin. Install it next to `lerobot` so that LeRobot finds the
`blindgrasp_transformer` type (plugin discovery imports `{PACKAGE}`; no extra flag is needed):

```bash
{{install}}
```

Then, for example, evaluate it in the blindgrasp simulation:

```bash
lerobot-eval --policy.path={{repo_id}} --env.type=blindgrasp --env.task=all --eval.n_episodes=20
```

{{code_line}}

"""


def padding_attention_mask(is_pad: Tensor) -> Tensor:
    """(B, T) padding flags -> (B, 1, T, T) boolean mask, True where query i may attend to key j: causal, padded
    keys removed, the diagonal open so that a padded query keeps one finite score."""
    t = is_pad.shape[-1]
    causal = torch.ones(t, t, dtype=torch.bool, device=is_pad.device).tril()
    eye = torch.eye(t, dtype=torch.bool, device=is_pad.device)
    return causal & ((~is_pad)[:, None, None, :] | eye)


class CausalSelfAttention(nn.Module):
    def __init__(self, embed_dim: int, n_heads: int, dropout: float):
        super().__init__()
        self.embed_dim, self.n_heads = embed_dim, n_heads
        self.qkv = nn.Linear(embed_dim, 3 * embed_dim, bias=False)
        self.proj = nn.Linear(embed_dim, embed_dim)
        self.attn_dropout = dropout
        self.resid_dropout = nn.Dropout(dropout)

    def _heads(self, x: Tensor) -> Tensor:  # (B, T, D) -> (B, H, T, D/H)
        b, t, _ = x.shape
        return x.view(b, t, self.n_heads, -1).transpose(1, 2)

    def _merge(self, y: Tensor) -> Tensor:  # (B, H, T, D/H) -> projected (B, T, D)
        b, _, t, _ = y.shape
        return self.resid_dropout(self.proj(y.transpose(1, 2).reshape(b, t, self.embed_dim)))

    def forward(self, x: Tensor, mask: Tensor | None) -> Tensor:
        q, k, v = (self._heads(p) for p in self.qkv(x).split(self.embed_dim, dim=-1))
        p = self.attn_dropout if self.training else 0.0
        return self._merge(
            F.scaled_dot_product_attention(q, k, v, attn_mask=mask, dropout_p=p, is_causal=mask is None)
        )

    def forward_last_query(self, x: Tensor, key_mask: Tensor | None) -> Tensor:
        """Attention output of the last token only: (B, T, D) -> (B, 1, D). key_mask: (B, 1, 1, T) or None."""
        d = self.embed_dim
        # Rows [0, D) of the fused weight project queries, rows [D, 3D) keys and values (contiguous views).
        q = F.linear(x[:, -1:], self.qkv.weight[:d])
        k, v = F.linear(x, self.qkv.weight[d:]).split(d, dim=-1)
        p = self.attn_dropout if self.training else 0.0
        # The last query sits after every key, so causality needs no mask here.
        y = F.scaled_dot_product_attention(
            self._heads(q), self._heads(k), self._heads(v), attn_mask=key_mask, dropout_p=p
        )
        return self._merge(y)

    def forward_reference(self, x: Tensor, mask: Tensor) -> Tensor:
        """Plain eager attention over all tokens (mask: (B or 1, 1, T, T) boolean)."""
        q, k, v = (self._heads(p) for p in self.qkv(x).split(self.embed_dim, dim=-1))
        att = (q @ k.transpose(-2, -1)) / (q.shape[-1] ** 0.5)
        att = att.masked_fill(~mask, float("-inf")).softmax(dim=-1)
        att = F.dropout(att, self.attn_dropout, self.training)
        return self._merge(att @ v)


class Block(nn.Module):
    """Pre-LN transformer block (robomimic `SelfAttentionBlock` with GELU)."""

    def __init__(self, embed_dim: int, n_heads: int, dropout: float):
        super().__init__()
        self.ln1 = nn.LayerNorm(embed_dim)
        self.attn = CausalSelfAttention(embed_dim, n_heads, dropout)
        self.ln2 = nn.LayerNorm(embed_dim)
        self.mlp = nn.Sequential(
            nn.Linear(embed_dim, 4 * embed_dim),
            nn.GELU(),
            nn.Linear(4 * embed_dim, embed_dim),
            nn.Dropout(dropout),
        )

    def forward(self, x: Tensor, mask: Tensor | None) -> Tensor:
        x = x + self.attn(self.ln1(x), mask)
        return x + self.mlp(self.ln2(x))

    def forward_last(self, x: Tensor, key_mask: Tensor | None) -> Tensor:
        """This block's output for the last token only: (B, T, D) -> (B, 1, D)."""
        x_last = x[:, -1:] + self.attn.forward_last_query(self.ln1(x), key_mask)
        return x_last + self.mlp(self.ln2(x_last))

    def forward_reference(self, x: Tensor, mask: Tensor) -> Tensor:
        x = x + self.attn.forward_reference(self.ln1(x), mask)
        return x + self.mlp(self.ln2(x))


class BlindgraspGPT(nn.Module):
    """(B, T, 12) normalized observations + optional (B, T) padding flags -> (B, 9) normalized delta."""

    def __init__(self, config: BlindgraspTransformerConfig):
        super().__init__()
        d, t = config.embed_dim, config.n_obs_steps
        self.context_length = t
        self.embed = nn.Linear(spec.STATE_DIM, d)
        self.pos_embed = nn.Parameter(torch.zeros(1, t, d))
        self.embed_norm = nn.LayerNorm(d)
        self.embed_dropout = nn.Dropout(config.dropout)
        self.blocks = nn.ModuleList(Block(d, config.n_heads, config.dropout) for _ in range(config.n_layers))
        self.final_norm = nn.LayerNorm(d)
        layers, width = [], d
        for hidden in config.head_hidden_dims:
            # ReLU: robomimic's MLP default; Table IV's GELU is the transformer's activation.
            layers += [nn.Linear(width, hidden), nn.ReLU()]
            width = hidden
        layers.append(nn.Linear(width, spec.ACTION_DIM))
        self.head = nn.Sequential(*layers)
        self.tanh_output = config.tanh_output
        self.apply(self._init_weights)

    @staticmethod
    def _init_weights(module: nn.Module) -> None:
        # robomimic GPT_Backbone init: N(0, 0.02) weights, zero biases (LayerNorm keeps its (1, 0) default).
        if isinstance(module, nn.Linear):
            nn.init.normal_(module.weight, mean=0.0, std=0.02)
            if module.bias is not None:
                nn.init.zeros_(module.bias)

    def _tokens(self, states: Tensor) -> Tensor:
        if states.shape[1] != self.context_length:
            raise ValueError(f"expected a context of {self.context_length} steps, got {tuple(states.shape)}")
        return self.embed_dropout(self.embed_norm(self.embed(states) + self.pos_embed))

    def _decode(self, x_last: Tensor) -> Tensor:
        out = self.head(self.final_norm(x_last))
        return torch.tanh(out) if self.tanh_output else out

    def forward(self, states: Tensor, is_pad: Tensor | None = None) -> Tensor:
        x = self._tokens(states)
        mask = key_mask = None
        if is_pad is not None:
            mask = padding_attention_mask(is_pad)
            key_mask = mask[:, :, -1:, :]  # the last query's row: (B, 1, 1, T)
        for block in self.blocks[:-1]:
            x = block(x, mask)
        x_last = self.blocks[-1].forward_last(x, key_mask)
        return self._decode(x_last[:, 0])

    def forward_reference(self, states: Tensor, is_pad: Tensor | None = None) -> Tensor:
        """The plain path: every token through every layer, explicit softmax attention. Same result as forward."""
        x = self._tokens(states)
        mask = padding_attention_mask(
            torch.zeros(x.shape[:2], dtype=torch.bool, device=x.device) if is_pad is None else is_pad
        )
        for block in self.blocks:
            x = block.forward_reference(x, mask)
        return self._decode(x[:, -1])


class BlindgraspTransformerPolicy(PreTrainedPolicy):
    """LeRobot policy wrapper: training loss, rolling inference context, LeRobot's policy interface."""

    config_class = BlindgraspTransformerConfig
    name = "blindgrasp_transformer"

    def __init__(self, config: BlindgraspTransformerConfig, **kwargs):
        # kwargs: make_policy passes dataset_stats / dataset_meta; normalization lives in the processors instead.
        super().__init__(config)
        config.validate_features()
        if kwargs.get("dataset_meta") is not None:  # lerobot-train: the dataset it trains on says the robot
            config.trained_for = TrainedFor(**policy_contract.facts_from_dataset(kwargs["dataset_meta"]))
        self.config = config
        self.model = BlindgraspGPT(config)
        self.reset()

    def generate_model_card(
        self, dataset_repo_id: str, model_type: str, license, tags, cfg=None, dataset_meta=None
    ):
        """LeRobot's card, plus the package to install and our tags (the Hub lists models by them)."""
        tags = sorted(set(tags or []) | {PACKAGE, "blindgrasp"})
        card = super().generate_model_card(dataset_repo_id, model_type, license, tags, cfg=cfg,
                                           dataset_meta=dataset_meta)  # fmt: skip
        repo_id = getattr(self.config, "repo_id", None) or "<repo_id>"
        lines = card.text.split("\n")
        # After the card's title line, so the install step is the first thing a reader sees.
        at = next((i + 1 for i, line in enumerate(lines) if line.startswith("# ")), 0)
        lines[at:at] = CARD_INSTALL.format(
            repo_id=repo_id, install=project.install_line(), code_line=project.code_line()
        ).split("\n")
        card.text = "\n".join(lines)
        return card

    def get_optim_params(self):
        # robomimic applies AdamW's weight decay to every parameter (its "L2 regularization").
        return self.parameters()

    def reset(self) -> None:
        """Start a new episode: the next observation refills the whole context."""
        self._context: deque[Tensor] = deque(maxlen=self.config.n_obs_steps)
        self._context_is_pad: deque[Tensor] = deque(maxlen=self.config.n_obs_steps)

    def _push_observation(self, state: Tensor) -> tuple[Tensor, Tensor | None]:
        """Append one (B, 12) observation to the rolling context (the first of an episode fills it with copies of
        itself, flagged as padding); return (B, T, 12) states and padding flags."""
        real = torch.zeros(state.shape[0], dtype=torch.bool, device=state.device)
        if not self._context:
            self._context.extend([state] * (self.config.n_obs_steps - 1))
            self._context_is_pad.extend([~real] * (self.config.n_obs_steps - 1))
        self._context.append(state)
        self._context_is_pad.append(real)
        states, is_pad = self.current_context()
        # Once the episode is 30 steps old nothing is padded: drop the mask for the faster causal kernel.
        return states, (is_pad if bool(is_pad.any()) else None)

    def current_context(self) -> tuple[Tensor, Tensor]:
        """The window the latest observation was predicted from: (B, T, 12) states and (B, T) padding flags."""
        if not self._context:
            raise RuntimeError("no observation since reset()")
        return torch.stack(list(self._context), dim=1), torch.stack(list(self._context_is_pad), dim=1)

    @torch.no_grad()
    def predict_normalized_delta(self, batch: dict[str, Tensor]) -> Tensor:
        """(B, 9) prediction delta / 0.3, bounded, from one new (B, 12) observation (into the rolling context, as
        `select_action`) or a full (B, T, 12) window (with optional `observation.state_is_pad`)."""
        state = batch[OBS_STATE]
        states, is_pad = (state, batch.get(STATE_IS_PAD)) if state.ndim == 3 else self._push_observation(state)
        return self._bounded(self.model(states, is_pad))

    @torch.no_grad()
    def predict_action_chunk(self, batch: dict[str, Tensor], **kwargs) -> Tensor:
        """(B, 1, 9) absolute joint targets (rad) from a preprocessed batch (see `predict_normalized_delta`)."""
        if Q_NOW not in batch:
            raise KeyError(
                f"blindgrasp_transformer acts on preprocessed observations: '{Q_NOW}' (the raw joint "
                "positions the policy's preprocessor adds) is missing"
            )
        return normalized_delta_to_target(self.predict_normalized_delta(batch), batch[Q_NOW])[:, None]

    def _bounded(self, pred: Tensor) -> Tensor:
        """The action's one bound in the policy: tanh, or without it a clamp at inference (training regresses the
        raw output). Nothing after it adds another."""
        return pred if self.config.tanh_output else pred.clamp(-1.0, 1.0)

    @torch.no_grad()
    def select_action(self, batch: dict[str, Tensor], **kwargs) -> Tensor:
        """One preprocessed (B, 12) observation in, (B, 9) absolute joint targets (rad) out."""
        return self.predict_action_chunk(batch)[:, 0]

    def forward(self, batch: dict[str, Tensor], reduction: str = "mean") -> tuple[Tensor, dict]:
        """The paper's imitation loss (`imitation_loss`) of the last token's prediction, per sample or averaged."""
        pred = self.model(batch[OBS_STATE], batch.get(STATE_IS_PAD))
        per_sample = imitation_loss(pred, batch[ACTION])
        mse = per_sample.mean()
        return (per_sample if reduction == "none" else mse), {"mse": mse.item()}


def imitation_loss(pred: Tensor, action: Tensor) -> Tensor:
    """Eq. 8, L = |pi_s(o_t) - a_t|^2, per sample (B,): both in units of the action bound (0.3 rad), so in [-1, 1].
    Averaged over the 9 joints rather than summed, as robomimic's MSE does: the same minimizer, a scale-free loss."""
    return F.mse_loss(pred, action, reduction="none").mean(dim=-1)
