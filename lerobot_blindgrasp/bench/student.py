"""`blindgrasp-bench --bench.type=student`: what one lerobot-train sample of the student costs, against its
compute floor, with each of LeRobot's data paths side by side.

    blindgrasp-bench --bench.type=student --bench.dataset_root=outputs/pipeline_quick_blind/demos --bench.size=cpu \\
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
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.bench import BenchConfig
from lerobot_blindgrasp.bench.policy import flops_per_step, make_policy
from lerobot_blindgrasp.bench.student_parts import compiled_vs_eager, format_table, gemm_gflops, update_parts
from lerobot_blindgrasp.policies.blindgrasp_transformer.window_cache import ENV_SWITCH, SERVED_LOG
from lerobot_blindgrasp.presets.student import SIZES


@BenchConfig.register_subclass("student")
@dataclass
class BenchStudentConfig(BenchConfig):
    """Per-sample cost of student training: each data path, the update's parts, and the model's FLOP floor."""

    dataset_root: Path | None = None  # a blindgrasp LeRobotDataset (required: the loader's cost depends on it)
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
        if self.dataset_root is None or not (Path(self.dataset_root) / "meta" / "info.json").is_file():
            raise ValueError(f"--bench.dataset_root must be a LeRobotDataset folder, got {self.dataset_root}")
        if min(self.loader_workers, default=0) < 0 or min(self.prefetch_factors, default=0) < 1:
            raise ValueError("--bench.loader_workers must be >= 0 and --bench.prefetch_factors >= 1")
        if self.device != "cpu":
            if not torch.device(self.device).type == "cuda" or not torch.cuda.is_available():
                raise ValueError(
                    f"--bench.device must be cpu, or cuda on a machine with a GPU, got {self.device!r}"
                )
            if self.profile or self.compile:
                raise ValueError("--bench.profile and --bench.compile time the update on the CPU only")


def _delta(n_obs_steps: int) -> dict:
    return {spec.STATE_KEY: [i / spec.CONTROL_HZ for i in range(1 - n_obs_steps, 1)]}


def _per_sample_ms(read, indices, block: int = 25) -> float:
    """ms per sample of the fastest block of `block` reads: on a shared machine the least-disturbed block is the
    closest to the path's own cost (the same rule for every path and for the update, so their ratios hold)."""
    read(int(indices[0]))  # opens the files, builds a cache
    best = float("inf")
    for start in range(0, len(indices), block):
        chunk = indices[start : start + block]
        t = time.perf_counter()
        for i in chunk:
            read(int(i))
        best = min(best, (time.perf_counter() - t) / len(chunk))
    return best * 1e3


def load_ms(root: Path, n_obs_steps: int, samples: int, seed: int) -> dict[str, float]:
    """ms per sample of each data path with the student's observation window, on the same random frames."""
    from lerobot.datasets.dataset_reader import DatasetReader
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    ds = LeRobotDataset(repo_id="local/bench", root=root, delta_timestamps=_delta(n_obs_steps))
    reader = ds.reader
    idx = np.random.default_rng(seed).integers(0, len(ds), samples)
    out = {
        "lerobot": _per_sample_ms(lambda i: DatasetReader.get_item(reader, i), idx),
        "cache": _per_sample_ms(lambda i: ds[i], idx),
    }
    col = reader.hf_dataset[spec.STATE_KEY]
    out["lerobot_row"] = _per_sample_ms(lambda i: reader.hf_dataset[i], idx)
    out["lerobot_window"] = _per_sample_ms(lambda i: col[list(range(max(0, i - n_obs_steps + 1), i + 1))], idx)
    out["streaming"] = streaming_ms(root, n_obs_steps, samples, seed)
    return out


def streaming_ms(root: Path, n_obs_steps: int, samples: int, seed: int) -> float:
    """ms per sample of `--dataset.streaming=true`'s dataset (StreamingLeRobotDataset), after its first sample."""
    from lerobot.datasets.streaming_dataset import StreamingLeRobotDataset

    ds = StreamingLeRobotDataset(
        repo_id="local/bench", root=root, delta_timestamps=_delta(n_obs_steps), max_num_shards=1, seed=seed
    )
    it = iter(ds)
    return _per_sample_ms(lambda _: next(it), np.zeros(samples + 1, dtype=int))


def loader_samples_per_s(root: Path, n_obs_steps: int, cfg: BenchStudentConfig) -> list[dict]:
    """samples/s through torch's DataLoader as lerobot-train builds it, per data path, worker count and prefetch
    factor, in steady state: timed after the first batch and the `workers x prefetch` batches the workers had
    queued by then."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    rows, before = [], os.environ.get(ENV_SWITCH)
    for path, switch in (("lerobot", "0"), ("cache", "1")):
        os.environ[ENV_SWITCH] = switch  # the spawned workers read it at their plugin import
        ds = LeRobotDataset(repo_id="local/bench", root=root, delta_timestamps=_delta(n_obs_steps))
        for workers in cfg.loader_workers:
            for prefetch in cfg.prefetch_factors if workers else [None]:  # no workers: nothing to prefetch
                rate = _loader_rate(ds, workers, prefetch, cfg)
                rows.append(
                    {"path": path, "num_workers": workers, "prefetch_factor": prefetch, "samples_per_s": rate}
                )
    if before is None:
        os.environ.pop(ENV_SWITCH, None)
    else:
        os.environ[ENV_SWITCH] = before
    return rows


def _loader_rate(ds, workers: int, prefetch: int | None, cfg: BenchStudentConfig) -> float:
    extra = {"multiprocessing_context": "spawn", "persistent_workers": True, "prefetch_factor": prefetch}
    loader = torch.utils.data.DataLoader(
        ds,
        batch_size=cfg.batch_size,
        shuffle=True,
        num_workers=workers,
        generator=torch.Generator().manual_seed(cfg.seed),
        **(extra if workers else {}),
    )
    it = iter(loader)
    for _ in range(1 + workers * (prefetch or 0)):  # start-up, then what the workers had queued
        next(it)
    t = time.perf_counter()
    for _ in range(cfg.loader_batches):
        next(it)
    rate = cfg.loader_batches * cfg.batch_size / (time.perf_counter() - t)
    del it, loader
    return rate


def cache_memory(root: Path, n_obs_steps: int) -> dict:
    """What one process's low-dim cache holds for this dataset: bytes per frame from its tensors (the columns'
    dtypes), and the growth of the process's anonymous resident memory (Linux) when a second dataset object builds
    its cache, so that the first build's one-off costs (imports, the allocator's first arenas) are not counted."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    def build():
        ds = LeRobotDataset(repo_id="local/bench", root=root, delta_timestamps=_delta(n_obs_steps))
        before = _rss_anon_bytes()
        ds[0]  # builds the cache
        after = _rss_anon_bytes()
        return ds, (after - before if before is not None and after is not None else None)

    warm, _ = build()
    ds, growth = build()
    cache = ds.reader.__dict__.get("_low_dim_cache")
    if cache is None:
        raise RuntimeError(f"{root}: the low-dim cache does not serve this dataset")
    del warm
    columns = sum(t.nbytes for t in cache.columns.values())
    frames = len(ds)
    return {
        "frames": frames,
        "bytes_per_frame": columns / frames,
        "cache_bytes": columns + cache.ep_from.nbytes + cache.ep_to.nbytes,
        "rss_anon_growth_bytes": growth,
        "columns": {
            k: str(t.dtype).removeprefix("torch.") + str(list(t.shape[1:])) for k, t in cache.columns.items()
        },
    }


def _rss_anon_bytes() -> int | None:
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("RssAnon:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return None


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
    torch.set_num_threads(1)
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
