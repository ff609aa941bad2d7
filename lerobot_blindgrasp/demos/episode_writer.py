"""Dataset writes off the rollout loop: `LeRobotDataset.save_episode` costs tens of milliseconds per episode, a stall
of the physics. `EpisodeWriter` runs the writes (and whatever else touches the dataset or the run's records) on one
thread in submission order, so the dataset is the one the loop would write; errors are raised in the caller.
Hand-written because LeRobot 0.6.1's only asynchronous writer (`AsyncImageWriter`) writes camera frames.
"""

from __future__ import annotations

import collections
import time
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from threading import Event


class _Dropped(Exception):
    """A job that did not run because an earlier one failed (never raised to the caller)."""


class EpisodeWriter:
    def __init__(self, queue: int, name: str = "blindgrasp-episode-writer"):
        if queue < 0:
            raise ValueError("the writer queue must be >= 0 (0: write in the caller's thread)")
        self.queue = queue
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix=name) if queue else None
        self._pending: collections.deque[Future] = collections.deque()
        self._stop = Event()  # set by a failed job, or by a Ctrl-C while closing: later jobs are dropped
        self.wait_s = 0.0  # time the caller spent waiting for the writer (backpressure and the final drain)

    @property
    def pending(self) -> int:
        """Jobs submitted and not yet seen finished by the caller."""
        return len(self._pending)

    def submit(self, job: Callable[[], object]) -> None:
        """Run `job` after every job submitted before it. Waits while `queue` jobs wait; raises an earlier job's
        error (then `job` is not queued)."""
        self._reap(keep=self.queue - 1 if not self._stop.is_set() else 0)  # a failed job: its error, first
        if self._stop.is_set():
            raise RuntimeError(
                "the episode writer is stopped (an earlier job failed, or it was closed); nothing more is written"
            )
        if self._pool is None:
            self._run(job)
        else:
            self._pending.append(self._pool.submit(self._run, job))

    def flush(self) -> None:
        """Wait until every submitted job has run; raises the first error among them. A Ctrl-C while it waits
        drops the jobs not started yet: the one in progress completes, then the KeyboardInterrupt is raised."""
        try:
            self._reap(keep=0)
        except KeyboardInterrupt:
            self._stop.set()
            self._wait_uninterrupted()
            raise

    def close(self) -> None:
        """`flush`, then stop the thread."""
        try:
            self.flush()
        finally:
            if self._pool is not None:
                self._stop.set()
                self._wait_uninterrupted()
                self._pool.shutdown(wait=True)

    def _run(self, job: Callable[[], object]) -> None:
        if self._stop.is_set():
            raise _Dropped
        try:
            job()
        except BaseException:
            self._stop.set()
            raise

    def _reap(self, keep: int) -> None:
        """Collect finished jobs, waiting for the oldest until at most `keep` are pending; raise the first error."""
        t0 = time.perf_counter()
        try:
            while self._pending and (len(self._pending) > keep or self._pending[0].done()):
                future = self._pending[0]
                try:
                    future.result()  # the job's own exception, raised here in the caller's thread
                except _Dropped:
                    pass
                finally:
                    if future.done():  # an interrupted wait leaves it pending, to be waited for again
                        self._pending.popleft()
        finally:
            self.wait_s += time.perf_counter() - t0

    def _wait_uninterrupted(self) -> None:
        """Wait until no job is running, whatever signals arrive: a save cut short would corrupt the dataset."""
        interrupted = False
        while self._pending:
            try:
                self._pending[-1].exception()  # the last one: every earlier job has ended by then
                self._pending.clear()
            except KeyboardInterrupt:
                interrupted = True
        if interrupted:
            raise KeyboardInterrupt
