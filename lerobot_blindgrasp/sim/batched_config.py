"""What a `BatchedGraspEnv` is asked for (`GraspEnvConfig`), and which object each of its envs holds
(`allocate_objects`). The tools get theirs from the env factory (`rollout/envs.py`)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.sim import backends, gripper, objects, randomization, rewards


@dataclass
class GraspEnvConfig:
    num_envs: int = 18
    objects: tuple[str, ...] = objects.PAPER_OBJECTS  # assigned round-robin: env i gets objects[i % len]
    # Relative share of envs per object (same order as `objects`); None: even, as the paper's 18 x 500.
    object_weights: tuple[float, ...] | None = None
    seed: int = 0  # env i uses seed + i
    # Per-env seeds instead of seed + i: one batch can then run several objects' evaluation seeds (spec.eval_env_seed)
    env_seeds: tuple[int, ...] | None = None
    episode_s: float = spec.EPISODE_S
    dr: randomization.DomainRandomization = field(default_factory=lambda: randomization.PAPER_DR)
    reward: rewards.RewardConfig = field(default_factory=lambda: rewards.PAPER_REWARD)
    physics: gripper.PhysicsOptions = field(default_factory=gripper.PhysicsOptions)
    nthread: int = 0  # 0: all CPUs
    autoreset: bool = True
    backend: str = "batch"  # "batch" (mujoco.batch, CPU) or "warp" (MuJoCo Warp, GPU; the gpu extra)
    device: str | None = None  # warp only: "cuda:0", "cpu"; None: this process's GPU (LOCAL_RANK) if any, else CPU

    def __post_init__(self):
        backends.check_backend(self.backend)
        self.objects = objects.resolve_objects(self.objects)
        if self.num_envs < 1:
            raise ValueError(f"num_envs must be >= 1, got {self.num_envs}")
        if self.env_seeds is not None and len(self.env_seeds) != self.num_envs:
            raise ValueError(f"env_seeds needs one seed per env ({self.num_envs}), got {len(self.env_seeds)}")
        if self.object_weights is not None:
            w = np.asarray(self.object_weights, dtype=float)
            if w.shape != (len(self.objects),) or not np.isfinite(w).all() or (w <= 0).any():
                raise ValueError(
                    f"object_weights needs one positive weight per object ({len(self.objects)}), got {self.object_weights}"
                )


def allocate_objects(num_envs: int, num_objects: int, weights: tuple[float, ...] | None) -> np.ndarray:
    """Object index of each env: round-robin, or each object's weighted share (largest remainders, at least one
    each), interleaved so that any prefix of the batch holds a mix of objects."""
    if weights is None:
        return np.arange(num_envs) % num_objects
    w = np.asarray(weights, dtype=float) / np.sum(weights)
    counts = np.minimum(1, num_envs // num_objects) + np.zeros(num_objects, dtype=np.int64)
    share = w * (num_envs - counts.sum())
    counts += np.floor(share).astype(np.int64)
    rest = num_envs - counts.sum()
    counts[np.argsort(-(share - np.floor(share)), kind="stable")[:rest]] += 1
    # Interleave: sort envs by their fractional position within their object's run.
    obj = np.repeat(np.arange(num_objects), counts)
    pos = np.concatenate([(np.arange(c) + 0.5) / c for c in counts])
    return obj[np.argsort(pos, kind="stable")]
