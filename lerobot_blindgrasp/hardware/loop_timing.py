"""Keeping time in the host's control loop: `PeriodMonitor` (overrun streaks, and a stop once the data no longer come
at the rate the policy and the dataset assume), `SampleSpacing` (samples at least 0.9 period apart, in any loop) and
`StepPacer` (a loop we own, re-based on now after a late step, never a burst of missed ticks)."""

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
    """Ticked once per loop step. A period over `(1 + tolerance)` x nominal is an overrun; a streak of them lasting
    `max_overrun_s` and `min_overruns` periods (the count spares a script that waits between calls) stops. A gap of
    `pause_s` is a pause (a dataset save, an operator prompt), not an overrun."""

    period_s: float
    max_overrun_s: float = 1.0  # 0: name the streaks, never stop
    tolerance: float = 0.5
    pause_s: float = 1.0
    min_overruns: int = 10
    what: str = "control loop"
    periods: int = 0
    overruns: int = 0
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

    LeRobot's loops sleep `period - (time since the loop's start)`, so after a slow read the next sample would come a
    few ms later, which the policy and the dataset take for a whole period. So each read waits until it will end no
    earlier than `min_gap_s` after the previous one ended, taking the shortest of the recent reads (after
    `MIN_READS`) as its duration. A steadily loaded loop never waits, and after a wait the caller's own sleep
    shrinks by as much, so the waits die out."""

    MIN_READS = 4

    def __init__(self, period_s: float, slack: float = 0.1, clock=time.monotonic, sleep=time.sleep):
        self.period_s = period_s
        self._clock, self._sleep = clock, sleep  # injectable, so the rule can be checked on an emulated clock
        self.min_gap_s = period_s * (1.0 - slack)
        self.waits = 0  # reads that were held back
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
        self._sleep(delay)
        return delay

    def after_read(self, started: float, ended: float) -> None:
        self._reads.append(ended - started)
        self._last_end = ended


class StepPacer:
    """One step per period, its read spaced by `SampleSpacing`; a late step, or a read the spacing held back,
    re-bases the schedule on now (never a burst of catch-up steps)."""

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
