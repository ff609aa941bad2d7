"""Where a start is (connect, a recording episode, a loop resuming after a pause): health is then judged at the start
levels, and a recording's episode needs room on disk (`recording_space.py`). LeRobot's Robot interface has no call at
an episode's start; lerobot-record's `log_say` line at INFO reaches every root handler, `EpisodeStarts` among them.
"""

from __future__ import annotations

import logging

from lerobot_blindgrasp import compat

from .recording_space import RecordingSpace


class EpisodeStarts(logging.Handler):
    """A root-logger handler that marks LeRobot's episode announcements; `take()` reads and clears the mark."""

    def __init__(self) -> None:
        super().__init__(level=logging.INFO)
        self._pending = False

    def emit(self, record: logging.LogRecord) -> None:
        if compat.is_episode_announcement(record):
            self._pending = True

    def take(self) -> bool:
        pending, self._pending = self._pending, False
        return pending

    def install(self) -> None:
        self._pending = False
        root = logging.getLogger()
        if self not in root.handlers:
            root.addHandler(self)

    def uninstall(self) -> None:
        logging.getLogger().removeHandler(self)


class Starts:
    """A start pending at a control period: an episode announced since the last one (`episodes`), or the first
    period after a pause of `pause_s` or more. A start of a recording (`recording`, set at connect) checks its room
    on disk first."""

    def __init__(self, episodes: EpisodeStarts, pause_s: float):
        self.episodes, self.pause_s = episodes, pause_s
        self.recording: RecordingSpace | None = None
        self._last_call: float | None = None

    def restart(self) -> None:
        self._last_call = None

    def pending(self, now: float) -> bool:
        resumed = self._last_call is not None and now - self._last_call >= self.pause_s
        self._last_call = now
        start = self.episodes.take() or resumed
        if start and self.recording is not None:
            self.recording.check()
        return start
