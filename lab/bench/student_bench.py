"""`python -m lab.bench --bench.type=student`: what one lerobot-train sample of the student costs, against its
compute floor, with each of LeRobot's data paths side by side.

    python -m lab.bench --bench.type=student --bench.dataset_root=outputs/pipeline_quick_blind/demos --bench.size=cpu \\
        --bench.batch_size=128 --bench.json=true

Per training sample, measured in this process on one torch thread, one after another in one run. On a shared
machine each figure is its least-disturbed repeat (the fastest block of reads, the fastest step, the fastest GEMM
round), the same rule for all, so the ratios within a run hold:
- **load**, each data path on the given dataset with the policy's 30-frame observation window: `lerobot` (LeRobot's
  own `DatasetReader.get_item`, what lerobot-train did before the student's data path), `cache` (the plugin's
  in-memory low-dim cache, `policies/blindgrasp_transformer/window_cache.py`, what lerobot-train does now),
  `streaming` (`--dataset.streaming=true`: StreamingLeRobotDataset's iterator); `lerobot_row` / `lerobot_window`
  split LeRobot's into its frame read and its window read;
- **loader**: samples/s through torch's DataLoader as lerobot-train builds it (spawned persistent workers,
  `prefetch_factor`), per path and worker count, in steady state (total time over the timed batches);
- **update**: forward, backward, gradient clipping and AdamW step on a batch of windows (what the training process
  does per sample), with LeRobot's AdamW and the `foreach` / `fused` variants; `--bench.profile=true` also splits
  forward + backward by operator (matrix products, attention, the rest) and counts the operators, and
  `--bench.compile=true` times `torch.compile` of the model against eager, one step of each in turn;
- **floor**: the model's training FLOPs per sample (3 x the forward's) at this machine's GEMM rate for the model's
  own matrix shapes.
`--train_steps=N` also runs the real `lerobot-train` for N steps on each of the two map-style paths
(BLINDGRASP_LOW_DIM_CACHE=0 and 1) and reports its samples/s.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import torch

from lab.bench import BenchConfig
from lab.bench.policy_bench import flops_per_step, make_policy
from lab.bench.student_data import cache_memory, load_ms, loader_samples_per_s, synthetic_demos
from lab.bench.student_parts import compiled_vs_eager, format_table, gemm_gflops, update_parts
from lerobot_blindgrasp.policies.blindgrasp_transformer.configuration_blindgrasp_transformer import SIZES
from lerobot_blindgrasp.policies.blindgrasp_transformer.window_cache import ENV_SWITCH, SERVED_LOG


@BenchConfig.register_subclass("student")
@dataclass
class BenchStudentConfig(BenchConfig):
    """Per-sample cost of student training: each data path, the update's parts, and the model's FLOP floor."""

    dataset_root: Path | None = None  # a blindgrasp LeRobotDataset (the loader's cost depends on its schema)
    # No dataset_root: time on a synthetic dataset of this many episodes in the demos' schema (random values).
    synthetic_episodes: int = 0
    size: str = "cpu"  # student size (presets.student.SIZES)
    batch_size: int = 128
    load_samples: int = 400  # random samples read per path for the load figures
    update_steps: int = 10  # timed optimizer steps (after 2 warm-up steps)
    num_workers: int = 1  # loader processes beside the training thread, for the bound
    loader_workers: list[int] = field(default_factory=lambda: [0, 2])  # DataLoader worker counts to time
    loader_batches: int = 4  # timed batches per DataLoader row (after the first); 0 skips the loader rows
    prefetch_factors: list[int] = field(default_factory=lambda: [4])  # per worker row; 4 is lerobot-train's
    profile: bool = False  # also split forward + backward by operator (torch.profiler)
    compile: bool = False  # also time torch.compile of the model against eager (minutes of compiling on a CPU)
    train_steps: int = 0  # >0: also time the real lerobot-train for this many steps, on both map-style paths
    log_freq: int = 50  # lerobot-train's --log_freq in those runs: its updt_s / data_s are read per logged window
    device: str = "cpu"  # where the update and lerobot-train's policy run (cuda: a GPU); loading stays on the CPU
    seed: int = 0

    def __post_init__(self):
        if self.size not in SIZES:
            raise ValueError(f"--bench.size must be one of {sorted(SIZES)}, got {self.size!r}")
        if self.dataset_root is None and self.synthetic_episodes > 0:
            pass  # made in run()
        elif self.dataset_root is None or not (Path(self.dataset_root) / "meta" / "info.json").is_file():
            raise ValueError(
                f"--bench.dataset_root must be a LeRobotDataset folder (or give --bench.synthetic_episodes), "
                f"got {self.dataset_root}"
            )
        if min(self.loader_workers, default=0) < 0 or min(self.prefetch_factors, default=0) < 1:
            raise ValueError("--bench.loader_workers must be >= 0 and --bench.prefetch_factors >= 1")
        if self.device != "cpu":
            if not torch.device(self.device).type == "cuda" or not torch.cuda.is_available():
                raise ValueError(
                    f"--bench.device must be cpu, or cuda on a machine with a GPU, got {self.device!r}"
                )
            if self.profile or self.compile:
                raise ValueError("--bench.profile and --bench.compile time the update on the CPU only")


def lerobot_train_samples_per_s(cfg: BenchStudentConfig, cache: bool) -> dict:
    """Run the real lerobot-train (its module, so that no console script is needed) for cfg.train_steps steps:
    samples/s from its wall clock (start-up included), and its own per-step `updt_s` / `data_s`, averaged over
    the logged windows after the first (which holds the start-up)."""
    with tempfile.TemporaryDirectory() as tmp:
        cmd = [
            sys.executable,
            "-m",
            "lerobot.scripts.lerobot_train",
            "--policy.type=blindgrasp_transformer",
            f"--policy.size={cfg.size}",
            f"--policy.device={cfg.device}",
            "--dataset.repo_id=local/bench",
            f"--dataset.root={cfg.dataset_root}",
            f"--output_dir={tmp}/out",
            f"--steps={cfg.train_steps}",
            f"--batch_size={cfg.batch_size}",
            f"--log_freq={cfg.log_freq}",
            "--save_checkpoint=false",
            "--policy.push_to_hub=false",
            f"--num_workers={cfg.num_workers}",
            "--wandb.enable=false",
            f"--seed={cfg.seed}",
        ]
        env = {**os.environ, "OMP_NUM_THREADS": "1", "HF_HUB_OFFLINE": "1", ENV_SWITCH: "1" if cache else "0"}
        t = time.perf_counter()
        done = subprocess.run(cmd, env=env, capture_output=True, text=True)
        wall = time.perf_counter() - t
    if done.returncode:
        raise RuntimeError(f"lerobot-train failed ({done.returncode}):\n{done.stderr[-3000:]}")
    log = done.stdout + done.stderr
    windows = train_log_windows(log)
    steady = windows[1:] or windows
    mean = {k: float(np.mean([w[k] for w in steady])) if steady else None for k in ("updt_s", "data_s")}
    return {
        "path": "cache" if cache else "lerobot",
        "device": cfg.device,
        "steps": cfg.train_steps,
        "num_workers": cfg.num_workers,
        "wall_s": wall,
        "samples_per_s": cfg.train_steps * cfg.batch_size / wall,
        "logged_windows": len(windows),
        "cache_served": SERVED_LOG in log,  # window_cache's log line: the reader was upgraded
        "updt_s": mean["updt_s"],
        "data_s": mean["data_s"],
        "steady_samples_per_s": cfg.batch_size / (mean["updt_s"] + mean["data_s"]) if steady else None,
    }


def train_log_windows(log: str) -> list[dict]:
    """lerobot-train's logged windows (`step:... updt_s:... data_s:...`), in order."""
    rows = []
    for line in log.splitlines():
        found = dict(re.findall(r"\b(step|updt_s|data_s):([0-9.]+[KMB]?)", line))
        if {"updt_s", "data_s"} <= set(found):
            rows.append(
                {"step": found.get("step"), "updt_s": float(found["updt_s"]), "data_s": float(found["data_s"])}
            )
    return rows


def _device_name(device: str) -> str:
    return torch.cuda.get_device_name(torch.device(device)) if device != "cpu" else f"cpu ({os.cpu_count()} cores)"


def run(cfg: BenchStudentConfig) -> dict:
    if cfg.dataset_root is None:
        with tempfile.TemporaryDirectory() as tmp:
            cfg = replace(
                cfg, dataset_root=synthetic_demos(Path(tmp) / "demos", cfg.synthetic_episodes, seed=cfg.seed)
            )
            return _run(cfg)
    return _run(cfg)


def _run(cfg: BenchStudentConfig) -> dict:
    torch.set_num_threads(1)
    if cfg.device != "cpu":
        torch.backends.cuda.matmul.allow_tf32 = True  # as lerobot-train sets it: its matrix products run in TF32
    policy = make_policy(cfg.size)
    n_obs = policy.config.n_obs_steps
    train_flops = 3 * flops_per_step(policy.config, last_token_only=True)
    load = load_ms(Path(cfg.dataset_root), n_obs, cfg.load_samples, cfg.seed)
    update = update_parts(cfg.size, cfg.batch_size, cfg.update_steps, cfg.seed, cfg.profile, cfg.device)
    gflops = gemm_gflops(cfg.size, cfg.batch_size, device=cfg.device)
    floor = train_flops / (gflops * 1e9) * 1e3
    per_sample = update["lerobot_adamw"]["total"]
    result = {
        "size": cfg.size,
        "device": _device_name(cfg.device),
        "matmul_tf32": cfg.device != "cpu",
        "batch_size": cfg.batch_size,
        "num_workers": cfg.num_workers,
        "load_ms_per_sample": load,
        "update_ms_per_sample": update,
        "load_over_update": {k: v / per_sample for k, v in load.items()},
        "train_flops_per_sample": train_flops,
        "gemm_gflops": gflops,
        "floor_ms_per_sample": floor,
        "update_over_floor": per_sample / floor,
        "bound_samples_per_s": {
            p: min(max(cfg.num_workers, 1) / load[p], 1 / per_sample) * 1e3
            for p in ("lerobot", "cache", "streaming")
        },
    }
    result["cache_memory"] = cache_memory(Path(cfg.dataset_root), n_obs)
    if cfg.compile:
        result["compile"] = compiled_vs_eager(cfg.size, cfg.batch_size, max(cfg.update_steps, 3), cfg.seed)
    if cfg.loader_batches:
        result["loader"] = loader_samples_per_s(Path(cfg.dataset_root), n_obs, cfg)
    if cfg.train_steps:
        result["lerobot_train"] = [lerobot_train_samples_per_s(cfg, cache) for cache in (False, True)]
    if not cfg.json:
        print(format_table(result))
    return result
