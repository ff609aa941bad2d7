"""A device's frame counter judged against this host's clock (docs/force_board.md, "A board reset is not a replay"):
it may advance by at most `1 + max_rate_hz * (dt + slack_s)` between frames `dt` apart (lost frames only advance it
more); stepping back is a replay unless it is a restart (marked `boot`, or after a silence of `boot_silence_s`),
which is held until `confirm_frames` more frames advance with time. Hand-written: no library judges a counter.
"""

from __future__ import annotations

import enum
from collections import deque
from dataclasses import dataclass, field

HISTORY = 17  # counted frames the counter's own rate is judged over (16 intervals, as the arrival rate)


class FrameVerdict(enum.Enum):
    LIVE = "live"  # the counter advanced with time: a fresh frame
    HOLD = "hold"  # a restarted counter not yet confirmed: keep the frame, it is not fresh
    REPEAT = "repeat"  # the same counter again: re-sent
    BACKWARD = "backward"  # behind the newest counter, and no restart: replayed
    AHEAD = "ahead"  # further ahead than the time since the last frame allows


@dataclass
class Restart:
    """One restart of the device, as the host saw it."""

    last_seq: int  # the newest counter before it
    first_seq: int  # the first counter after it
    silence_s: float  # from the last frame before it to the first after it, on this host's clock
    marked: bool  # the device marked its first frame after boot
    cause: str = ""  # what the device says reset it (its boot frame), "" when unknown
    confirmed_seq: int = -1  # the counter at which the restart was trusted (-1: not yet)


@dataclass
class CounterClock:
    max_rate_hz: float
    slack_s: float
    boot_silence_s: float
    confirm_frames: int
    modulus: int = 65536
    restarts: list[Restart] = field(default_factory=list)
    lost: int = 0  # frames the counter skipped: lost on the way
    confirmed: Restart | None = None  # the restart the last judged frame confirmed
    _ref: tuple[int, float] | None = None  # (counter, arrival) of the newest counted frame
    _last_arrival: float = 0.0  # of any frame, counted or not
    _held: tuple[int, float] | None = None  # the newest frame of a restart being confirmed
    _held_count: int = 0
    _history: deque = field(default_factory=lambda: deque(maxlen=HISTORY))  # (unwrapped counter, arrival)

    def seq_rate_hz(self) -> float | None:
        """Frames per second the device sent by its own counter over the newest counted frames (lost ones
        included); None before 4 intervals."""
        if len(self._history) < 5 or self._history[-1][1] <= self._history[0][1]:
            return None
        (c0, t0), (c1, t1) = self._history[0], self._history[-1]
        return (c1 - c0) / (t1 - t0)

    def _count(self, step: int, seq: int, now: float) -> None:
        last = self._history[-1][0] if self._history else 0
        self._history.append((last + step, now))
        self._ref = (seq, now)

    @property
    def resyncing(self) -> Restart | None:
        """The restart being confirmed, if any."""
        return self.restarts[-1] if self._held is not None else None

    def allowed_step(self, dt: float) -> float:
        return 1 + self.max_rate_hz * (dt + self.slack_s)

    def judge(self, seq: int, now: float, boot: bool = False, cause: str = "") -> FrameVerdict:
        """The verdict on a frame with counter `seq` that arrived at `now` (this host's monotonic clock); `boot`: the
        device marks it as its first frame after a reset, with `cause`. `confirmed` is then the restart this frame
        confirmed, if any."""
        silence, self._last_arrival = now - self._last_arrival, now
        self.confirmed = None
        if self._ref is None:  # the first frame of the stream (a boot frame at connect is just that)
            self._count(0, seq, now)
            return FrameVerdict.LIVE
        if self._held is not None:
            verdict = self._judge_held(seq, now, boot, silence, cause)
            if verdict is not None:
                return verdict
        step = (seq - self._ref[0]) % self.modulus
        if boot or step == 0 or step > self.modulus // 2:
            if self._restarted(seq, now, boot, silence, self._ref):
                self._hold(seq, now, self._ref[0], boot, cause)
                return FrameVerdict.HOLD
            return FrameVerdict.REPEAT if step == 0 else FrameVerdict.BACKWARD
        if step > self.allowed_step(now - self._ref[1]):
            return FrameVerdict.AHEAD
        self.lost += step - 1
        self._count(step, seq, now)
        return FrameVerdict.LIVE

    def _restarted(self, seq: int, now: float, boot: bool, silence: float, since: tuple[int, float]) -> bool:
        """A counter restarted from 0 after the frame `since` was sent can be at most what the time allows, and the
        device was silent while it booted (unless it marks its first frame after boot)."""
        small = seq <= self.allowed_step(now - since[1]) - 1
        return small and (boot or silence >= self.boot_silence_s)

    def _hold(self, seq: int, now: float, last_seq: int, boot: bool, cause: str) -> None:
        silence = now - self._ref[1]
        self.restarts.append(Restart(last_seq, seq, silence, boot, cause))
        self._held, self._held_count = (seq, now), 0

    def _judge_held(self, seq: int, now: float, boot: bool, silence: float, cause: str) -> FrameVerdict | None:
        """A frame while a restart is being confirmed; None: judge it against the old counter (the restart was a
        stray frame, and this one continues the old counter)."""
        held_seq, held_t = self._held
        step = (seq - held_seq) % self.modulus
        if not boot and 0 < step <= self.modulus // 2 and step <= self.allowed_step(now - held_t):
            self._held, self._held_count = (seq, now), self._held_count + 1
            if self._held_count < self.confirm_frames:
                return FrameVerdict.HOLD
            self.restarts[-1].confirmed_seq = seq
            self.confirmed = self.restarts[-1]
            self._held = None
            self._history.clear()
            self._count(0, seq, now)
            return FrameVerdict.LIVE
        old = (seq - self._ref[0]) % self.modulus
        if not boot and 0 < old <= self.modulus // 2 and old <= self.allowed_step(now - self._ref[1]):
            self.restarts.pop()
            self._held = None
            return None
        if (boot or step == 0 or step > self.modulus // 2) and self._restarted(
            seq, now, boot, silence, self._held
        ):
            self.restarts.pop()
            self._hold(seq, now, self._ref[0], boot, cause)
            return FrameVerdict.HOLD
        if step == 0:
            return FrameVerdict.REPEAT
        return FrameVerdict.AHEAD if step <= self.modulus // 2 else FrameVerdict.BACKWARD
