"""`blindgrasp-bench --bench.type=student`: what one lerobot-train sample of the student costs, against its
compute floor.

    blindgrasp-bench --bench.type=student --bench.dataset_root=outputs/pipeline_quick_blind/demos --bench.size=cpu \\
        --bench.batch_size=128 --bench.json=true

Three figures, each per training sample, measured in this process on one torch thread:
- **load**: LeRobotDataset `__getitem__` with the policy's 30-frame observation window (what each lerobot-train
  data-loader worker does per sample), on the given dataset;
- **update**: forward, backward and AdamW step of the policy on a batch of such windows (what the training process
  does per sample);
- **floor**: the model's training FLOPs per sample (3 x the forward's: forward + backward) at this machine's
  measured GEMM rate for the model's own matrix shapes.
The stage's throughput on `cores` cores, with `num_workers` loader processes beside one training thread, is bounded
by the slower of the two pipelines: samples/s <= min(workers / load, 1 / update); the floor shows how far the update
is from pure arithmetic. `--train_steps=N` also runs the real `lerobot-train` for N steps and reports its samples/s.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F  # noqa: N812

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.bench import BenchConfig
from lerobot_blindgrasp.bench.policy import flops_per_step, make_policy
from lerobot_blindgrasp.presets.student import SIZES


@BenchConfig.register_subclass("student")
@dataclass
class BenchStudentConfig(BenchConfig):
    """Per-sample cost of student training: data loading, the update, and the model's FLOP floor."""

    dataset_root: Path | None = None  # a blindgrasp LeRobotDataset (required: the loader's cost depends on it)
    size: str = "cpu"  # student size (presets.student.SIZES)
    batch_size: int = 128
    load_samples: int = 400  # random samples read for the load figure
    update_steps: int = 10  # timed optimizer steps (after 2 warm-up steps)
    num_workers: int = 1  # loader processes beside the training thread, for the bound
    train_steps: int = 0  # >0: also time the real lerobot-train for this many steps (adds its start-up)
    seed: int = 0

    def __post_init__(self):
        if self.size not in SIZES:
            raise ValueError(f"--bench.size must be one of {sorted(SIZES)}, got {self.size!r}")
        if self.dataset_root is None or not (Path(self.dataset_root) / "meta" / "info.json").is_file():
            raise ValueError(f"--bench.dataset_root must be a LeRobotDataset folder, got {self.dataset_root}")


def load_ms(root: Path, n_obs_steps: int, samples: int, seed: int) -> float:
    """ms per sample of LeRobotDataset.__getitem__ with the student's observation window."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    delta = {spec.STATE_KEY: [i / spec.CONTROL_HZ for i in range(1 - n_obs_steps, 1)]}
    ds = LeRobotDataset(repo_id="local/bench", root=root, delta_timestamps=delta)
    idx = np.random.default_rng(seed).integers(0, len(ds), samples)
    ds[int(idx[0])]  # opens the files
    t = time.perf_counter()
    for i in idx:
        ds[int(i)]
    return (time.perf_counter() - t) / samples * 1e3


def update_ms(size: str, batch_size: int, steps: int, seed: int) -> float:
    """ms per sample of forward + backward + AdamW step on random normalized windows."""
    torch.manual_seed(seed)
    policy = make_policy(size).train()
    opt = policy.config.get_optimizer_preset().build(policy.parameters())
    t_ctx = policy.config.n_obs_steps
    batch = {spec.STATE_KEY: torch.randn(batch_size, t_ctx, spec.STATE_DIM),
             f"{spec.STATE_KEY}_is_pad": torch.zeros(batch_size, t_ctx, dtype=torch.bool),
             spec.ACTION_KEY: torch.rand(batch_size, spec.ACTION_DIM) * 2 - 1}

    def step():
        loss, _ = policy.forward(batch)
        opt.zero_grad()
        loss.backward()
        opt.step()

    for _ in range(2):
        step()
    t = time.perf_counter()
    for _ in range(steps):
        step()
    return (time.perf_counter() - t) / (steps * batch_size) * 1e3


def gemm_gflops(size: str, batch_size: int, repeats: int = 20) -> float:
    """GFLOP/s of this machine's matrix products at the model's training shapes (batch x 30 tokens rows)."""
    policy = make_policy(size)
    d, t = policy.config.embed_dim, policy.config.n_obs_steps
    rows = batch_size * t
    shapes = [(rows, d, 3 * d), (rows, d, d), (rows, d, 4 * d), (rows, 4 * d, d)]
    mats = [(torch.randn(m, k), torch.randn(n, k)) for m, k, n in shapes]
    flops = sum(2 * m * k * n for m, k, n in shapes)
    for a, w in mats:
        F.linear(a, w)
    t0 = time.perf_counter()
    for _ in range(repeats):
        for a, w in mats:
            F.linear(a, w)
    return flops * repeats / (time.perf_counter() - t0) / 1e9


def lerobot_train_samples_per_s(cfg: BenchStudentConfig) -> dict:
    """Run the real lerobot-train for cfg.train_steps steps; samples/s from its wall clock (start-up included)."""
    with tempfile.TemporaryDirectory() as tmp:
        cmd = [str(Path(sys.executable).parent / "lerobot-train"), "--policy.type=blindgrasp_transformer",
               f"--policy.size={cfg.size}", "--dataset.repo_id=local/bench", f"--dataset.root={cfg.dataset_root}",
               f"--output_dir={tmp}/out", f"--steps={cfg.train_steps}", f"--batch_size={cfg.batch_size}",
               f"--save_freq={cfg.train_steps}", "--policy.push_to_hub=false", "--policy.device=cpu",
               f"--num_workers={cfg.num_workers}", "--wandb.enable=false", f"--seed={cfg.seed}"]
        env = {**os.environ, "OMP_NUM_THREADS": "1", "HF_HUB_OFFLINE": "1"}
        t = time.perf_counter()
        subprocess.run(cmd, check=True, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        wall = time.perf_counter() - t
    return {"steps": cfg.train_steps, "wall_s": wall, "samples_per_s": cfg.train_steps * cfg.batch_size / wall}


def run(cfg: BenchStudentConfig) -> dict:
    torch.set_num_threads(1)
    policy = make_policy(cfg.size)
    train_flops = 3 * flops_per_step(policy.config, last_token_only=True)
    load = load_ms(Path(cfg.dataset_root), policy.config.n_obs_steps, cfg.load_samples, cfg.seed)
    update = update_ms(cfg.size, cfg.batch_size, cfg.update_steps, cfg.seed)
    gflops = gemm_gflops(cfg.size, cfg.batch_size)
    floor = train_flops / (gflops * 1e9) * 1e3
    bound = min(cfg.num_workers / load, 1 / update) * 1e3
    result = {
        "size": cfg.size, "batch_size": cfg.batch_size, "num_workers": cfg.num_workers,
        "load_ms_per_sample": load, "update_ms_per_sample": update,
        "train_flops_per_sample": train_flops, "gemm_gflops": gflops, "floor_ms_per_sample": floor,
        "update_over_floor": update / floor, "bound_samples_per_s": bound,
        "limited_by": "loading" if load / cfg.num_workers > update else "update",
    }
    if cfg.train_steps:
        result["lerobot_train"] = lerobot_train_samples_per_s(cfg)
    if not cfg.json:
        print(format_table(result))
    return result


def format_table(r: dict) -> str:
    lines = [
        f"student {r['size']}, batch {r['batch_size']}, one torch thread, {r['num_workers']} loader process(es)",
        f"  load (LeRobotDataset, 30-frame window): {r['load_ms_per_sample']:.2f} ms/sample",
        f"  update (fwd + bwd + AdamW):             {r['update_ms_per_sample']:.3f} ms/sample",
        f"  floor ({r['train_flops_per_sample'] / 1e6:.1f} MFLOP at {r['gemm_gflops']:.1f} GFLOP/s):"
        f"     {r['floor_ms_per_sample']:.3f} ms/sample (update = {r['update_over_floor']:.1f} x floor)",
        f"  bound: {r['bound_samples_per_s']:.0f} samples/s, limited by {r['limited_by']}",
    ]
    if "lerobot_train" in r:
        lt = r["lerobot_train"]
        lines.append(f"  lerobot-train: {lt['steps']} steps in {lt['wall_s']:.1f} s = {lt['samples_per_s']:.0f} samples/s")
    return "\n".join(lines)
