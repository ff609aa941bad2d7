"""torchrun launches for rsl-rl's multi-GPU mode (on when WORLD_SIZE > 1): which device and envs a process gets.

rsl-rl's `OnPolicyRunner._configure_multi_gpu` hard-codes CUDA and NCCL; on a machine without GPUs `runner_class`
returns a subclass doing the same bookkeeping with gloo on the CPU. What is synchronized, and when, stays rsl-rl's.
"""

from __future__ import annotations

import os

import torch


def world() -> tuple[int, int, int]:
    """(world size, global rank, local rank) from torchrun's environment; (1, 0, 0) outside torchrun."""
    return int(os.getenv("WORLD_SIZE", "1")), int(os.getenv("RANK", "0")), int(os.getenv("LOCAL_RANK", "0"))


def default_torch_device() -> str:
    """One process per GPU: cuda:<LOCAL_RANK> when CUDA is there, else the CPU."""
    return f"cuda:{world()[2]}" if torch.cuda.is_available() else "cpu"


def split_envs(num_envs: int, seed: int) -> tuple[int, int]:
    """This rank's share of `num_envs` (the total over all processes) and its first env seed. Ranks get disjoint,
    consecutive env-seed ranges, so the union of all ranks' envs is the single-process run's envs."""
    size, rank, _ = world()
    if num_envs < size:
        raise ValueError(f"{num_envs} envs cannot be split over {size} processes")
    base, extra = divmod(num_envs, size)
    mine = base + (rank < extra)
    first = rank * base + min(rank, extra)
    return mine, seed + first


def runner_class(device: str):
    """rsl-rl's OnPolicyRunner, or on CPU devices under torchrun the same runner with a gloo process group."""
    from rsl_rl.runners import OnPolicyRunner

    if device.startswith("cuda") or world()[0] <= 1:
        return OnPolicyRunner

    class _GlooOnPolicyRunner(OnPolicyRunner):
        """rsl-rl's multi-GPU mode on CPU processes (gloo): same cfg["multi_gpu"], same ranks; no CUDA calls."""

        def _configure_multi_gpu(self) -> None:
            self.gpu_world_size, self.gpu_global_rank, self.gpu_local_rank = world()
            self.is_distributed = self.gpu_world_size > 1
            self.cfg["multi_gpu"] = {
                "global_rank": self.gpu_global_rank,
                "local_rank": self.gpu_local_rank,
                "world_size": self.gpu_world_size,
            }
            if not torch.distributed.is_initialized():
                torch.distributed.init_process_group(
                    backend="gloo", rank=self.gpu_global_rank, world_size=self.gpu_world_size
                )

    return _GlooOnPolicyRunner
