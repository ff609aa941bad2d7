"""Keeping time in the host's control loop.

`PeriodMonitor` measures the period of whatever loop calls it once per step: the robot ticks it in every
`get_observation`, so lerobot-record, lerobot-rollout and the real eval env are all measured, whoever's loop it is.
A period over `(1 + tolerance)` times the nominal one is an overrun. Overruns back to back are a streak, named as it
happens: one warning when it starts and one when it ends (its length in periods and seconds, its worst period), so a
second stall after a first is heard too. A streak of `max_overrun_s` and at least `min_overruns` periods stops
(`LoopOverrunError`): the data no longer come at the rate the policy and the dataset assume, and the policy's hold
(the success rule's 1 s) would be judged at another rate; the count keeps a few deliberately slow steps (a script
that waits between calls) from stopping. A gap of `pause_s` or more is a pause of the loop (a dataset save, an
operator prompt), not an overrun: it ends a streak.

`SampleSpacing` keeps any loop's samples at least 0.9 period apart: the robot holds a read back when the previous
one ended too recently (after a slow read), so no loop takes two samples a few ms apart for two periods.

`StepPacer` paces a loop we own (the real eval env's trial). It sleeps to the next tick; when a step comes late it
re-bases the schedule on now, so after a stall the loop goes on at its period instead of firing the missed ticks
back to back, and it spaces its reads as `SampleSpacing` does.
"""

from __future__ import annotations

import logging
import time
from collections import deque
from dataclasses import dataclass, field

logger = logging.getLogger(__name__)


class LoopOverrunError(RuntimeError):
    """The loop overran its period for longer than `max_overrun_s`."""


@dataclass
class Streak:
    """A run of overruns back to back."""

    start: float  # when its first slow period ended (monotonic s)
    periods: int = 0
    seconds: float = 0.0
    worst_s: float = 0.0


@dataclass
class PeriodMonitor:
    period_s: float
    max_overrun_s: float = 1.0  # 0: name the streaks, never stop
    tolerance: float = 0.5
    pause_s: float = 1.0
    min_overruns: int = 10
    what: str = "control loop"
    periods: int = 0
    overruns: int = 0
    worst_s: float = 0.0
    recent: deque = field(default_factory=lambda: deque(maxlen=200))  # the last periods measured (s)
    streaks: deque = field(default_factory=lambda: deque(maxlen=100))  # the last streaks that ended
    streak: Streak | None = None  # the streak under way
    _last: float | None = None

    def restart(self) -> None:
        """The next tick starts a new measurement (after a deliberate non-loop operation: connect, tare)."""
        self._end_streak("the loop restarted")
        self._last = None

    def _end_streak(self, why: str) -> None:
        s, self.streak = self.streak, None
        if s is None:
            return
        self.streaks.append(s)
        logger.warning("%s: slow streak ended (%s) after %d periods, %.2f s (about %.1f Hz instead of %.0f Hz), "
                       "worst period %.0f ms.", self.what, why, s.periods, s.seconds, s.periods / s.seconds,
                       1 / self.period_s, s.worst_s * 1e3)  # fmt: skip

    def tick(self, now: float | None = None) -> float | None:
        """Call once per loop step; returns the period just measured (None on the first tick or after a pause)."""
        now = time.monotonic() if now is None else now
        last, self._last = self._last, now
        if last is None:
            return None
        period = now - last
        if period >= self.pause_s:
            self._end_streak(f"a pause of {period:.1f} s")
            return None
        self.periods += 1
        self.recent.append(period)
        if period <= self.period_s * (1.0 + self.tolerance):
            self._end_streak(f"a {period * 1e3:.0f} ms period")
            return period
        self.overruns += 1
        self.worst_s = max(self.worst_s, period)
        if self.streak is None:
            self.streak = Streak(start=now)
            logger.warning("%s: slow streak started: a %.0f ms period (nominal %.0f ms; %d overruns in %d periods "
                           "so far).", self.what, period * 1e3, self.period_s * 1e3, self.overruns,
                           self.periods)  # fmt: skip
        s = self.streak
        s.periods, s.seconds, s.worst_s = s.periods + 1, s.seconds + period, max(s.worst_s, period)
        if self.max_overrun_s and s.seconds >= self.max_overrun_s and s.periods >= self.min_overruns:
            self._end_streak("stopped")
            raise LoopOverrunError(
                f"The {self.what} has overrun its {self.period_s * 1e3:.0f} ms period for {s.seconds:.1f} s "
                f"in a row ({s.periods} periods, worst {s.worst_s * 1e3:.0f} ms, about {s.periods / s.seconds:.1f} Hz "
                f"instead of {1 / self.period_s:.0f} Hz; {self.overruns} overruns in {self.periods} periods). A slow "
                "bus (latency_timer_ms, USB hub), a loaded host or a slow policy: fix it, or lower the rate and set "
                "loop_hz to match."
            )
        return period


class SampleSpacing:
    """No two samples closer than `min_gap_s` (0.9 of a period), whoever's loop it is and however long its reads.

    LeRobot's loops (lerobot-record, lerobot-rollout) sleep `period - (time since the loop's start)`: after an
    observation that took long to read (a slow bus, a loaded host: 30 ms or 49 ms alike), the loop goes straight
    on, and the next observation's data would be read a few ms after the slow one's, which the policy and the
    dataset take for one whole period. So before every read the robot waits until the read will end no earlier
    than `min_gap_s` after the previous one ended. It cannot know how long the read will take: it takes the
    shortest of the recent reads (none until it has seen `MIN_READS` since the loop (re)started).
    A steadily loaded loop does not wait: its samples come one caller period apart, and a read that takes up to the
    slack (5 ms at 20 Hz: a health read, bus jitter) longer than the shortest recent one leaves the next gap
    inside the contract. After a wait the caller's next start comes that much later and its own sleep shrinks by as
    much, so the waits die out and the caller's pacing takes over again."""

    MIN_READS = 4

    def __init__(self, period_s: float, slack: float = 0.1, clock=time.monotonic, sleep=time.sleep):
        self.period_s = period_s
        self._clock, self._sleep = clock, sleep  # injectable, so the rule can be checked on an emulated clock
        self.min_gap_s = period_s * (1.0 - slack)
        self.waits = 0  # reads that were held back, and for how long in all (for tests and logs)
        self.waited_s = 0.0
        self._last_end: float | None = None
        self._reads: deque = deque(maxlen=20)  # recent read durations (s)

    def restart(self) -> None:
        self._last_end = None
        self._reads.clear()

    def expected_read_s(self) -> float:
        if len(self._reads) < self.MIN_READS:
            return 0.0
        return min(self._reads)

    def before_read(self) -> float:
        """Sleep until this read may start; returns the time slept (s)."""
        if self._last_end is None:
            return 0.0
        delay = self._last_end + self.min_gap_s - self.expected_read_s() - self._clock()
        if delay <= 0:
            return 0.0
        self.waits += 1
        self.waited_s += delay
        self._sleep(delay)
        return delay

    def after_read(self, started: float, ended: float) -> None:
        self._reads.append(ended - started)
        self._last_end = ended


class StepPacer:
    """Paces a loop we own (the eval trial): one step per period, its read spaced from the last by
    `SampleSpacing`. A step that comes late re-bases the schedule on now (never a burst of catch-up steps); a read
    held back by the spacing re-bases it on the held read, so after a slow read the loop is back at its period at
    once instead of over several steps."""

    def __init__(self, period_s: float, slack: float = 0.1):
        self.period_s = period_s
        self.spacing = SampleSpacing(period_s, slack)
        self.rebased = 0
        self._next = time.monotonic() + period_s

    def start(self) -> None:
        self._next = time.monotonic() + self.period_s
        self.spacing.restart()

    def wait(self) -> None:
        """Sleep until the next tick and until the read is due. If the tick has already passed, go on at once and
        put the tick after it one full period from now."""
        now = time.monotonic()
        if now < self._next:
            time.sleep(self._next - now)
        else:
            self.rebased += 1
            self._next = now
        if self.spacing.before_read() > 0:
            self._next = time.monotonic()
        self._next += self.period_s

    def sampled(self, started: float, ended: float) -> None:
        """The step's observation was read from `started` to `ended` (time.monotonic)."""
        self.spacing.after_read(started, ended)
