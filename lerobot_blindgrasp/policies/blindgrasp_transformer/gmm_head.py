"""robomimic's GMM action head (`BC_Transformer_GMM`): a mixture of Gaussians over the normalized delta.

Beyond the paper, whose Eq. 8 regresses one action with MSE (`action_head="mse"`, the default). Why it is here: an
MSE student predicts the *mean* action over situations it cannot tell apart from 9 joints and 3 forces. After the
first touch a small capsule and a medium object look alike, the teacher goes low on one and stays high on the
other, and the MSE student stops in between (`docs/results/student_gap.md`). A mixture can keep both actions as
separate modes and pick one.

Head output, per sample, K = modes, A = 9 joints: [means (K*A) | scales (K*A) | logits (K)], as robomimic lays it:
    mean_k  = tanh(raw)                      the action box is [-1, 1]
    std_k   = softplus(raw) + min_std
    p(a)    = sum_k softmax(logits)_k N(a; mean_k, diag(std_k^2))
Training minimizes -log p(a) (robomimic's GMM loss). Acting (robomimic's `low_noise_eval`): the stds are dropped
and the action is one mode's mean, the mode drawn by its weight (`"sample"`, robomimic) or the heaviest one
(`"mode"`, deterministic).
"""

from __future__ import annotations

import torch
import torch.nn.functional as F  # noqa: N812
from torch import Tensor
from torch import distributions as D  # noqa: N812

from lerobot_blindgrasp import spec

EVAL_CHOICES = ("sample", "mode")


def output_dim(modes: int) -> int:
    """Width of the head's last layer for `modes` components."""
    return modes * (2 * spec.ACTION_DIM + 1)


def split(raw: Tensor, modes: int, min_std: float) -> tuple[Tensor, Tensor, Tensor]:
    """(B, output_dim) -> means (B, K, A) in [-1, 1], stds (B, K, A) >= min_std, logits (B, K)."""
    a = spec.ACTION_DIM
    if raw.shape[-1] != output_dim(modes):
        raise ValueError(f"a {modes}-mode GMM head outputs {output_dim(modes)} numbers, got {raw.shape[-1]}")
    means, scales, logits = raw.split([modes * a, modes * a, modes], dim=-1)
    means = torch.tanh(means.unflatten(-1, (modes, a)))
    stds = F.softplus(scales.unflatten(-1, (modes, a))) + min_std
    return means, stds, logits


def mixture(raw: Tensor, modes: int, min_std: float) -> D.MixtureSameFamily:
    means, stds, logits = split(raw, modes, min_std)
    return D.MixtureSameFamily(D.Categorical(logits=logits), D.Independent(D.Normal(means, stds), 1))


def negative_log_likelihood(raw: Tensor, action: Tensor, modes: int, min_std: float) -> Tensor:
    """-log p(action) per sample (B,), the GMM student's loss in place of Eq. 8."""
    return -mixture(raw, modes, min_std).log_prob(action)


def mixture_mean(raw: Tensor, modes: int, min_std: float) -> Tensor:
    """(B, A) the mixture's mean action: what an MSE student would predict from the same head (for logging)."""
    means, _, logits = split(raw, modes, min_std)
    return (logits.softmax(-1)[..., None] * means).sum(-2)


def act(raw: Tensor, modes: int, min_std: float, how: str) -> Tensor:
    """(B, A) action in [-1, 1]: the mean of one mode, drawn by weight (`sample`) or the heaviest (`mode`)."""
    means, _, logits = split(raw, modes, min_std)
    if how == "sample":
        k = D.Categorical(logits=logits).sample()
    elif how == "mode":
        k = logits.argmax(-1)
    else:
        raise ValueError(f"gmm_eval must be one of {EVAL_CHOICES}, got {how!r}")
    return means.gather(1, k[:, None, None].expand(-1, 1, means.shape[-1]))[:, 0]
