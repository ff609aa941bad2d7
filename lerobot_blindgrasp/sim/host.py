"""The host side of the env's tensors: what a numpy caller gets from them, and how their CPU ops are run.

On the CPU a tensor's numpy view shares its memory, so the CPU backend hands numpy callers the env's own results
without a copy; on a GPU this is where an env step's results cross to the host, and only when a caller asks.
"""

from __future__ import annotations

import functools

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


def one_intraop_thread(method):
    """Run an env method's torch ops on the calling thread alone when the env is on the CPU.

    The task's tensors are (envs, <= 92), far below the size where splitting an op across threads pays, yet torch
    splits transcendental elementwise ops (log, cos, sqrt, tanh) from a few thousand elements on. Waking the OpenMP
    pool for each costs ~20x the op itself on a small machine, more when its cores are busy. The physics' own
    threads are MuJoCo's and unaffected. Under ATen's OpenMP backend the setting belongs to the calling thread (the
    learner's threads elsewhere keep theirs); it is restored on return."""

    @functools.wraps(method)
    def run(self, *args, **kwargs):
        if self.device.type != "cpu":
            return method(self, *args, **kwargs)
        threads = torch.get_num_threads()
        torch.set_num_threads(1)
        try:
            return method(self, *args, **kwargs)
        finally:
            torch.set_num_threads(threads)

    return run
