"""Durable demo collection: LeRobot's writer writes its parquet footers only in `finalize()`, so `Checkpoints`
finalizes every `checkpoint_s` seconds or `num_envs` written episodes, fsyncs what changed since the last one (not
each episode: two fsyncs cost more than an episode) and reopens the dataset; a kill loses at most the episodes since.
`--resume=true` repairs the folder to the last checkpoint (`repair.py`).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from typing import Any

from lerobot_blindgrasp import compat, durable
from lerobot_blindgrasp.demos import dataset as demo_dataset

log = logging.getLogger("blindgrasp.demos")


class Checkpoints:
    """Holds the open dataset (`.ds`); call `written(state)` after every saved episode with the run state so far.
    `on_checkpoint(state)` runs after each finalize, before the reopen: it records that state, now on disk."""

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

    def written(self, state: Any = None) -> None:
        self.since += 1
        due = self.since >= self.every_episodes or time.monotonic() - self.last >= self.every_s
        if self.every_s > 0 and due:
            self.now(state)

    def now(self, state: Any = None) -> None:
        t0 = time.perf_counter()
        self.ds.finalize()  # footers written: every episode so far is readable from here on
        t_sync = time.time()
        durable.fsync_tree(self.root, since=self.synced_at - 2.0)  # 2 s: coarse file-system timestamps
        self.synced_at = t_sync
        episodes = self.ds.meta.total_episodes
        self.on_checkpoint(state)
        if not compat.reopen_finalized(self.ds):
            self.ds = demo_dataset.resume(self.root, self.repo_id)
        self.since, self.last = 0, time.monotonic()
        self.count += 1
        self.seconds += time.perf_counter() - t0
        log.info("checkpoint: %d episodes durable in %s", episodes, self.root)
