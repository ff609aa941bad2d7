"""The student bench's data-path figures (`python -m lab.bench --bench.type=student`): per-sample cost of each of
LeRobot's data paths and of the plugin's low-dim cache, the DataLoader as lerobot-train builds it (workers and
prefetch), the cache's memory per process, and a synthetic dataset in the demos' schema to time them on."""

from __future__ import annotations

import multiprocessing
import os
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
import torch

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.policies.blindgrasp_transformer.window_cache import ENV_SWITCH


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


def loader_samples_per_s(root: Path, n_obs_steps: int, cfg) -> list[dict]:
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


def _loader_rate(ds, workers: int, prefetch: int | None, cfg) -> float:
    extra = {"multiprocessing_context": "spawn", "persistent_workers": True, "prefetch_factor": prefetch}
    warm = 1 + workers * (prefetch or 0)  # start-up, then what the workers had queued
    # Shuffled as lerobot-train shuffles, over as many epochs as the batches need: a dataset smaller than them
    # continues into the next permutation without the stall of a new epoch's iterator.
    sampler = torch.utils.data.RandomSampler(
        ds,
        num_samples=(warm + cfg.loader_batches) * cfg.batch_size,
        generator=torch.Generator().manual_seed(cfg.seed),
    )
    loader = torch.utils.data.DataLoader(
        ds, batch_size=cfg.batch_size, sampler=sampler, num_workers=workers, **(extra if workers else {})
    )
    it = iter(loader)
    for _ in range(warm):
        next(it)
    t = time.perf_counter()
    for _ in range(cfg.loader_batches):
        next(it)
    rate = cfg.loader_batches * cfg.batch_size / (time.perf_counter() - t)
    del it, loader
    return rate


def cache_memory(root: Path, n_obs_steps: int) -> dict:
    """What one process's low-dim cache holds for this dataset: bytes per frame from its tensors (the columns'
    dtypes), and, as a check, how much the anonymous resident memory (Linux) of a fresh process grows when a second
    dataset object builds its cache: a fresh process, so that memory freed by earlier work is not reused, and the
    second build, so that the first one's one-off costs (imports, the allocator's first arenas) are not counted."""
    with ProcessPoolExecutor(max_workers=1, mp_context=multiprocessing.get_context("spawn")) as pool:
        return pool.submit(_cache_memory_here, str(root), n_obs_steps).result()


def _cache_memory_here(root: str, n_obs_steps: int) -> dict:
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    def build():
        ds = LeRobotDataset(repo_id="local/bench", root=root, delta_timestamps=_delta(n_obs_steps))
        before = _rss_anon_bytes()
        ds[0]  # builds the cache
        after = _rss_anon_bytes()
        return ds, (after - before if before is not None and after is not None else None)

    first, _ = build()
    ds, growth = build()
    cache = ds.reader.__dict__.get("_low_dim_cache")
    if cache is None:
        raise RuntimeError(f"{root}: the low-dim cache does not serve this dataset")
    columns = sum(t.nbytes for t in cache.columns.values())
    return {
        "frames": len(ds),
        "bytes_per_frame": columns / len(ds),
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


def synthetic_demos(root: Path, episodes: int, frames: int = 98, seed: int = 0) -> Path:
    """A demo dataset in the collector's schema (`demos/dataset.py`) with random values, `episodes` x `frames`:
    what the student's data path and update cost does not depend on the values, so a lab can time them before it
    has demos. 98 frames is a curated episode's mean length in the main job's demos."""
    from lerobot_blindgrasp.demos import dataset as demo_dataset

    ds = demo_dataset.create(root, "local/bench")
    rng = np.random.default_rng(seed)
    per_episode = {k: ft["shape"][0] for k, ft in demo_dataset.EPISODE_FEATURES.items() if k != "episode.seed"}
    with demo_dataset.skip_empty_image_embedding():
        for e in range(episodes):
            frame = {
                spec.STATE_KEY: rng.normal(size=(frames, spec.STATE_DIM)).astype(np.float32),
                spec.ACTION_KEY: rng.normal(size=(frames, spec.ACTION_DIM)).astype(np.float32),
                **{k: np.tile(rng.random(n, dtype=np.float32), (frames, 1)) for k, n in per_episode.items()},
                "episode.seed": np.tile(np.array([e, 0], dtype=np.int64), (frames, 1)),
                "timestamp": (np.arange(frames) / demo_dataset.FPS).astype(np.float32),
                "frame_index": np.arange(frames, dtype=np.int64),
                "index": np.zeros(frames, dtype=np.int64),  # index and task_index: save_episode writes them
                "task_index": np.zeros(frames, dtype=np.int64),
            }
            ds.save_episode(
                episode_data={
                    **frame,
                    "size": frames,
                    "task": [f"grasp object {e % 18}"] * frames,
                    "episode_index": e,
                }
            )
    ds.finalize()
    return root
