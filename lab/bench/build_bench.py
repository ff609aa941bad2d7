"""How long the env takes to build: `BatchedGraspEnv` construction at several env counts, on one backend.

    python -m lab.bench --bench.type=build --bench.num_envs=[300,1800,9000] --bench.json=true

Each count is built `--bench.repeats` times in this process, after one untimed build of `--bench.warmup_envs` envs
(Warp initializes and loads its kernels from its cache then, so the timed builds do not include compiling); the
table gives the fastest of the repeats, and each build's wall time and the load average before it. A build is
everything `BatchedGraspEnv(cfg)` does: compiling the catalogue's object models, the Table II draws, the physics
(the batch backend: one randomized MjModel per env; Warp: one model per object geometry type with per-world rows
written on the device), and the task's per-env state. It ends when the constructor returns, and on a GPU after
the device has finished its work.
"""

from __future__ import annotations

import gc
import os
import time
from dataclasses import dataclass, field

from lab.bench import BenchConfig
from lerobot_blindgrasp.sim.batched_config import GraspEnvConfig
from lerobot_blindgrasp.sim.batched_env import BatchedGraspEnv


@BenchConfig.register_subclass("build")
@dataclass
class BenchBuildConfig(BenchConfig):
    """Env construction time per env count."""

    num_envs: list[int] = field(default_factory=lambda: [300, 1800, 9000])  # env counts, built in this order
    backend: str = "warp"  # physics backend: warp (Warp's default device) or batch
    device: str | None = None  # Warp device (default: the GPU if there is one, else "cpu")
    repeats: int = 1  # timed builds per count
    warmup_envs: int = 18  # one untimed build first (0: none)
    seed: int = 0

    def __post_init__(self):
        if self.backend not in ("batch", "warp"):
            raise ValueError(f"--bench.backend must be batch or warp, got {self.backend!r}")
        if self.repeats < 1 or not self.num_envs or min(self.num_envs) < 1:
            raise ValueError("--bench.repeats and every --bench.num_envs must be >= 1")


def _build(cfg: BenchBuildConfig, n: int) -> tuple[float, BatchedGraspEnv]:
    env_cfg = GraspEnvConfig(num_envs=n, seed=cfg.seed, backend=cfg.backend, device=cfg.device)
    t = time.perf_counter()
    env = BatchedGraspEnv(env_cfg)
    if env.device.type == "cuda":
        import torch
        import warp as wp

        wp.synchronize_device(env.physics.wp_device)
        torch.cuda.synchronize(env.device)
    return time.perf_counter() - t, env


def run(cfg: BenchBuildConfig) -> dict:
    if cfg.warmup_envs:
        _build(cfg, cfg.warmup_envs)[1].close()
    rows = []
    for n in cfg.num_envs:
        builds = []
        for _ in range(cfg.repeats):
            gc.collect()
            load = os.getloadavg()[0]
            seconds, env = _build(cfg, n)
            builds.append({"seconds": seconds, "load_before": load})
            device = str(env.device)
            env.close()
            del env
        best = min(b["seconds"] for b in builds)
        rows.append({"num_envs": n, "seconds": best, "envs_per_s": n / best, "device": device, "builds": builds})
    result = {"backend": cfg.backend, "cpu_count": os.cpu_count(), "rows": rows, "load_after": os.getloadavg()[0]}
    if not cfg.json:
        print(f"blindgrasp-bench build ({cfg.backend}): BatchedGraspEnv construction, fastest of {cfg.repeats}")
        print("| envs | device | build s | envs/s | load before |")
        print("|---:|---|---:|---:|---:|")
        for r in rows:
            loads = "/".join(f"{b['load_before']:.1f}" for b in r["builds"])
            print(f"| {r['num_envs']} | {r['device']} | {r['seconds']:.2f} | {r['envs_per_s']:,.0f} | {loads} |")
    return result
