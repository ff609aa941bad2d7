"""Tensors to numpy for host callers: a view on the CPU; on a GPU, the one place results cross to the host."""

from __future__ import annotations

import torch


def on_host(x):
    """numpy for a tensor, recursively through dicts and tuples; anything else unchanged."""
    if isinstance(x, torch.Tensor):
        # the env's tensors carry no gradient; on the CPU .numpy() is a view (one call, not three)
        return x.numpy() if x.device.type == "cpu" and not x.requires_grad else x.detach().cpu().numpy()
    if isinstance(x, dict):
        return {k: on_host(v) for k, v in x.items()}
    if isinstance(x, tuple):
        return tuple(on_host(v) for v in x)
    return x
