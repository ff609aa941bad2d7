"""Demo collection speed: curated demos per CPU-minute and dataset frames written per second.

Runs a real, small `blindgrasp-collect-demos` collection into a temporary folder (curated as in the paper unless
--curation=false), then re-writes the rollouts it saw through three write paths, to measure the writer alone: what
collection uses (`save_episode(episode_data=...)` with whole arrays, LeRobot's empty image-embedding pass skipped,
see `demos.dataset.skip_empty_image_embedding`), the same with LeRobot's default pass, and `add_frame` per frame
(LeRobot's default, as lerobot-record writes). Without --teacher a throwaway `quick` teacher is trained for one
iteration: the speeds are real, its yield is not.

With --durable_side_by_side=true (default) the same collection (same seeds, so the same rollouts) runs twice in
this one process: first without crash checkpoints (`--checkpoint_s=0`, finalize only at the end: the behaviour
before durable collection), then with them every `checkpoint_s` seconds (or `num_envs` episodes), so their cost is
measured side by side: the `durable_*` keys, and `checkpoint_share_of_wall`, the time spent finalizing and
reopening. With --writer_pairs=N (default 2) it then runs N pairs of the same collection, one with the writer thread
(`--writer_queue`) and one with every episode saved in the loop (`--writer_queue=0`, the collector before its writer
thread), alternating which goes first so that a drift in the machine's load cancels: `writer_throughput_ratio` is
their curated demos per wall-clock minute, writer thread over in the loop, and `writer_pair_ratios` each pair's.
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import shutil
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from lab.bench import BenchConfig


@BenchConfig.register_subclass("demos")
@dataclass
class BenchDemosConfig(BenchConfig):
    """Demo collection speed: curated demos per CPU-minute and dataset frames written per second."""

    teacher: Path | None = None  # teacher folder, checkpoint or run dir (default: a throwaway quick teacher)
    num_envs: int = 72  # parallel envs
    objects: str = "all"  # 'all', 'medium' or a comma list of catalogue names
    episodes_per_object: int = 2  # written-episode target per object
    max_rollouts_per_object: int = 4  # bounds the run for weak teachers
    curation: bool = True  # false: keep every episode (the 'w/o curation' ablation)
    write_episodes: int = 40  # episodes re-written per writer path
    threads: int = 0  # physics threads (0: all CPUs)
    backend: str = "batch"  # physics: batch or warp (pip install .[gpu]; a GPU if there is one, else Warp's CPU)
    durable_side_by_side: bool = True  # also run the collection with crash checkpoints, and compare
    checkpoint_s: float = 10.0  # their interval here: 6x as often as the collector's default 60 s, a worst case
    writer_queue: int = 256  # episodes queued for the collector's writer thread (0: saved in the loop)
    writer_pairs: int = 2  # collections with the writer thread and in the loop, side by side (0: none)


def _throwaway_teacher(tmp: Path) -> Path:
    from lerobot_blindgrasp.teacher import train

    out = tmp / "teacher"
    with contextlib.redirect_stdout(io.StringIO()):  # keep --json output clean
        train.train(train.TrainTeacherConfig(preset="quick", output_dir=out, iterations=1, export=False))
    return out


def _writer_speed(episodes, root: Path, per_frame: bool, fast: bool = True) -> float:
    """Frames per second through one write path, on real rollouts (whole, untrimmed)."""
    from lerobot_blindgrasp import compat, spec
    from lerobot_blindgrasp.demos import curation, dataset
    from lerobot_blindgrasp.demos.collection_loop import _cleanup

    ds = dataset.create(root, "bench/writer")
    frames, t0 = 0, time.perf_counter()
    try:
        for ep in episodes:
            cut = curation.judge_episode(ep.task_reward, ep.uniaxial_force, curation.NO_CURATION)
            if not per_frame:
                frames += dataset.write_episode(ds, ep, cut, fast=fast)
                continue
            buf = dataset.episode_buffer(ep, cut, ds.meta.total_episodes)
            for t in range(buf["size"]):
                ds.add_frame(
                    {
                        spec.STATE_KEY: buf[spec.STATE_KEY][t],
                        spec.ACTION_KEY: buf[spec.ACTION_KEY][t],
                        **{k: buf[k][t].copy() for k in dataset.EPISODE_FEATURES},
                        "task": buf["task"][t],
                    }
                )
            ds.save_episode()
            frames += buf["size"]
    finally:
        with _cleanup("finalizing the dataset", sys.exc_info()[1]):  # never masks the error that ended the run
            compat.finalize_or_abandon(ds)
    return frames / (time.perf_counter() - t0)


def run(cfg: BenchDemosConfig) -> dict:
    tmp = Path(tempfile.mkdtemp(prefix="blindgrasp-bench-demos-"))
    try:
        teacher = cfg.teacher or _throwaway_teacher(tmp)
        if cfg.writer_pairs:  # the pairs compare only if neither pays the first collection's one-off costs
            _collect(_one_episode(cfg), teacher, tmp, "warmup", 0.0, queue=0)
        seen = []

        def keep_some(ep, cut, written, stats):
            if len(seen) < cfg.write_episodes and not ep.physics_failed:
                seen.append(ep)

        stats = _collect(
            cfg, teacher, tmp, "demos", 0.0 if cfg.durable_side_by_side else cfg.checkpoint_s, keep_some
        )
        durable_run = (
            _collect(cfg, teacher, tmp, "demos_durable", cfg.checkpoint_s) if cfg.durable_side_by_side else None
        )
        result = {
            "teacher": str(cfg.teacher) if cfg.teacher else "throwaway quick teacher (1 iteration)",
            "curation": cfg.curation,
            "num_envs": cfg.num_envs,
            "backend": cfg.backend,
            **_collection_figures(stats),
            **_writer_figures(seen, tmp),
        }
        if durable_run is not None:
            result.update(_durable_figures(cfg, durable_run, stats))
        if cfg.writer_pairs:
            result.update(_writer_pairs(cfg, teacher, tmp))
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    if not cfg.json:
        width = max(map(len, result))
        for k, v in result.items():
            print(f"{k:<{width}}  {v:.2f}" if isinstance(v, float) else f"{k:<{width}}  {v}")
    return result


def _collect(cfg: BenchDemosConfig, teacher: Path, tmp: Path, folder: str, checkpoint_s: float, on_episode=None,
             queue: int | None = None):  # fmt: skip
    """One collection into tmp/folder, as blindgrasp-collect-demos runs it."""
    from lerobot_blindgrasp.demos import curation
    from lerobot_blindgrasp.demos.collection_loop import collect_demos
    from lerobot_blindgrasp.demos.config import CollectConfig

    c = CollectConfig(
        teacher=teacher,
        output_dir=tmp / folder,
        repo_id="bench/demos",
        episodes_per_object=cfg.episodes_per_object,
        max_rollouts_per_object=cfg.max_rollouts_per_object,
        objects=cfg.objects,
        curation=curation.PAPER_CURATION if cfg.curation else curation.NO_CURATION,
        num_envs=cfg.num_envs,
        threads=cfg.threads,
        backend=cfg.backend,
        progress=False,
        checkpoint_s=checkpoint_s,
        writer_queue=cfg.writer_queue if queue is None else queue,
    )
    with contextlib.redirect_stderr(io.StringIO()):
        return collect_demos(c, on_episode=on_episode)


def _one_episode(cfg: BenchDemosConfig) -> BenchDemosConfig:
    """A collection of one whole episode: the imports, the first env build and the first save."""
    return dataclasses.replace(
        cfg,
        objects="cylinder_a_medium",
        num_envs=1,
        episodes_per_object=1,
        max_rollouts_per_object=1,
        curation=False,
    )


def _collection_figures(stats) -> dict:
    cpu_min = stats.cpu_s / 60.0
    return {
        "rollouts": stats.rollouts,
        "curated_demos": stats.kept,
        "frames": stats.frames,
        "wall_s": stats.wall_s,
        "cpu_s": stats.cpu_s,
        "env_steps_per_s": stats.env_steps / stats.wall_s if stats.wall_s else 0.0,
        "rollouts_per_cpu_minute": stats.rollouts / cpu_min if cpu_min else 0.0,
        "curated_demos_per_cpu_minute": stats.demos_per_cpu_minute,
        "demos_per_minute": stats.demos_per_minute,
        "write_share_of_wall": stats.write_s / stats.wall_s if stats.wall_s else 0.0,
        "writer_wait_share_of_wall": stats.writer_wait_s / stats.wall_s if stats.wall_s else 0.0,
    }


def _writer_figures(seen: list, tmp: Path) -> dict:
    """Frames per second through each write path, on the rollouts kept."""
    import datasets

    whole = whole_default = per_frame = 0.0
    bars_were_off = datasets.are_progress_bars_disabled()
    datasets.disable_progress_bars()  # LeRobot's default path maps with a bar per episode
    if seen:
        _writer_speed(seen[:3], tmp / "w_warmup", per_frame=False)  # pays the lazy imports of a first write
        whole = _writer_speed(seen, tmp / "w_episode_data", per_frame=False)
        whole_default = _writer_speed(seen, tmp / "w_episode_data_default", per_frame=False, fast=False)
        per_frame = _writer_speed(seen, tmp / "w_add_frame", per_frame=True)
    if not bars_were_off:
        datasets.enable_progress_bars()
    return {
        "frames_written_per_s": whole,
        "frames_written_per_s_lerobot_default": whole_default,
        "frames_written_per_s_add_frame": per_frame,
        "writer_episodes": len(seen),
    }


def _durable_figures(cfg: BenchDemosConfig, durable_run, stats) -> dict:
    """The collection with crash checkpoints, next to the one without."""
    ratio = lambda a, b: a / b if b else 0.0  # noqa: E731
    return {
        "durable_checkpoint_s": cfg.checkpoint_s,
        "durable_checkpoints": durable_run.checkpoints,
        "durable_checkpoint_ms_mean": 1000 * durable_run.checkpoint_s / max(1, durable_run.checkpoints),
        "durable_curated_demos": durable_run.kept,
        "durable_wall_s": durable_run.wall_s,
        "durable_env_steps_per_s": ratio(durable_run.env_steps, durable_run.wall_s),
        "durable_demos_per_minute": durable_run.demos_per_minute,
        "durable_cpu_s": durable_run.cpu_s,
        "durable_curated_demos_per_cpu_minute": durable_run.demos_per_cpu_minute,
        "durable_cpu_throughput_ratio": ratio(durable_run.demos_per_cpu_minute, stats.demos_per_cpu_minute),
        "durable_throughput_ratio": ratio(durable_run.demos_per_minute, stats.demos_per_minute),
        "checkpoint_share_of_wall": durable_run.checkpoint_s / max(durable_run.wall_s, 1e-9),
    }


def _writer_pairs(cfg: BenchDemosConfig, teacher: Path, tmp: Path) -> dict:
    """The same collection with the writer thread and in the loop, in pairs (ABBA...): their throughput ratio."""
    runs = {"thread": [], "in_loop": []}
    for k in range(cfg.writer_pairs):
        for name in ("thread", "in_loop") if k % 2 == 0 else ("in_loop", "thread"):
            queue = cfg.writer_queue if name == "thread" else 0
            runs[name].append(_collect(cfg, teacher, tmp, f"pair{k}_{name}", 0.0, queue=queue))
    demos = {name: sum(r.kept for r in rs) for name, rs in runs.items()}
    wall = {name: sum(r.wall_s for r in rs) for name, rs in runs.items()}
    return {
        "writer_pair_demos": demos["thread"],
        "writer_pair_demos_in_loop": demos["in_loop"],
        "writer_pair_wall_s": wall["thread"],
        "writer_pair_wall_s_in_loop": wall["in_loop"],
        "writer_pair_wait_share_of_wall": sum(r.writer_wait_s for r in runs["thread"]) / wall["thread"],
        "writer_pair_write_share_of_wall_in_loop": sum(r.write_s for r in runs["in_loop"]) / wall["in_loop"],
        "writer_throughput_ratio": (demos["thread"] / wall["thread"]) / (demos["in_loop"] / wall["in_loop"]),
        "writer_pair_ratios": [
            round((a.kept / a.wall_s) / (b.kept / b.wall_s), 3)
            for a, b in zip(runs["thread"], runs["in_loop"], strict=True)
        ],
    }
