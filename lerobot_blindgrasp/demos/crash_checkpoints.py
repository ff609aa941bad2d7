"""Durable demo collection: finalize and reopen the dataset at bounded intervals, so a kill loses little.

LeRobot's dataset writer keeps its parquet writers open and writes their footers only in `finalize()`; a killed
collector (SIGKILL, the out-of-memory killer, a power cut) never gets there, and every episode in the open files is
unreadable. `Checkpoints` finalizes the dataset every `checkpoint_s` seconds or every `num_envs` written episodes,
whichever comes first, and reopens it for appending the way `LeRobotDataset.resume` does: the next episode starts
fresh data and metadata files (LeRobot's own rule for appending to a finished dataset). Everything finalized is
complete on disk; a kill costs at most the episodes since the last checkpoint, and `--resume=true` repairs the
folder to that point (`repair.py`) and goes on.

`LeRobotDataset.resume` itself re-reads meta/episodes through `datasets` (about 1 s for a small dataset, more as it
grows), so `reopen_in_place` sets the few fields resume would rebuild
from the metadata LeRobot already holds in memory: the last episode's file indices and frame range. It checks that
LeRobot's writer has the fields it expects and falls back to `LeRobotDataset.resume` otherwise.

LeRobot's own metadata files (info.json, stats.json, tasks.parquet) are rewritten in place after every episode;
`compat.atomic_lerobot_metadata` makes those writes atomic while a collection runs, so a kill during one cannot
leave a truncated info.json (the one file the repair cannot re-derive). They are not fsynced per episode (two fsyncs per
episode cost more than the episode on a busy disk); each checkpoint fsyncs what changed since the last one, so a
power cut, too, loses at most the episodes since the last checkpoint.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from typing import Any

from lerobot_blindgrasp import durable
from lerobot_blindgrasp.demos import dataset as demo_dataset

log = logging.getLogger("blindgrasp.demos")


class Checkpoints:
    """Holds the open dataset (`.ds`); call `written(state)` after every saved episode, with the run state that goes
    with the episodes saved so far. `on_checkpoint(state)` runs after each finalize, before the reopen: it records
    that state, now that its episodes are on disk."""

    def __init__(
        self, ds, root, repo_id: str, every_s: float, every_episodes: int, on_checkpoint: Callable[[Any], None]
    ):
        self.ds, self.root, self.repo_id = ds, root, repo_id
        self.every_s, self.every_episodes = every_s, max(1, every_episodes)
        self.on_checkpoint = on_checkpoint
        self.since = 0  # episodes written since the last checkpoint
        self.last = time.monotonic()
        self.synced_at = time.time()
        self.count = 0
        self.seconds = 0.0  # time spent finalizing and reopening

    def due(self) -> bool:
        if self.every_s <= 0 or self.since == 0:
            return False
        return self.since >= self.every_episodes or time.monotonic() - self.last >= self.every_s

    def written(self, state: Any = None) -> None:
        self.since += 1
        if self.due():
            self.now(state)

    def now(self, state: Any = None) -> None:
        t0 = time.perf_counter()
        self.ds.finalize()  # footers written: every episode so far is readable from here on
        t_sync = time.time()
        durable.fsync_tree(self.root, since=self.synced_at - 2.0)  # 2 s: coarse file-system timestamps
        self.synced_at = t_sync
        episodes = self.ds.meta.total_episodes
        self.on_checkpoint(state)
        if not reopen_in_place(self.ds):
            self.ds = demo_dataset.resume(self.root, self.repo_id)
        self.since, self.last = 0, time.monotonic()
        self.count += 1
        self.seconds += time.perf_counter() - t0
        log.info("checkpoint: %d episodes durable in %s", episodes, self.root)


_WRITER_FIELDS = ("_finalized", "_latest_episode", "_pq_writer")
_META_FIELDS = ("_finalized", "latest_episode", "episodes", "_pq_writer", "_metadata_buffer")


def reopen_in_place(ds) -> bool:
    """Make a finalized LeRobotDataset accept episodes again, as `LeRobotDataset.resume` would leave it: both
    writers closed, no latest episode, and `meta.episodes[-1]` naming the last episode's files and frame range, so
    that the next episode goes to the next data and meta/episodes files. False (nothing changed) when LeRobot's
    internals are not as expected or the dataset is not finalized."""
    w, m = getattr(ds, "writer", None), getattr(ds, "meta", None)
    if (
        w is None
        or m is None
        or not hasattr(ds, "_is_finalized")
        or not all(hasattr(w, f) for f in _WRITER_FIELDS)
        or not all(hasattr(m, f) for f in _META_FIELDS)
    ):
        return False
    if w._pq_writer is not None or m._pq_writer is not None or m._metadata_buffer:
        return False  # not finalized
    if m.latest_episode is None or w._latest_episode is None:
        return w._latest_episode is None and m.latest_episode is None and _unfinalize(ds)  # nothing written yet
    last = {
        "meta/episodes/chunk_index": int(m.latest_episode["meta/episodes/chunk_index"][0]),
        "meta/episodes/file_index": int(m.latest_episode["meta/episodes/file_index"][0]),
        "dataset_to_index": int(m.latest_episode["dataset_to_index"][0]),
        "data/chunk_index": int(w._latest_episode["data/chunk_index"]),
        "data/file_index": int(w._latest_episode["data/file_index"]),
    }
    m.episodes, m.latest_episode, w._latest_episode = [last], None, None
    return _unfinalize(ds)


def _unfinalize(ds) -> bool:
    ds.meta._finalized = ds.writer._finalized = ds._is_finalized = False
    return True
