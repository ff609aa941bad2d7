"""One "latest frame" stream for the devices that push data at their own rate (the force board, the glove bridge).

A background thread keeps the newest valid frame and its arrival time, so the control loop never blocks on the
device; a device failure ends the thread and is raised at the next read. A subclass's `_keep` drops re-sent or
replayed frames (`counter_faults`), and a `_content` channel identical for `frozen_frames` frames stops counting as
fresh. Stale: no fresh frame for `stale_timeout_s`. Slow: fewer fresh frames per second than `min_rate_hz` over the
newest `RATE_WINDOW` intervals (a host stall is not slow: the frames arrive in a burst after it). Hand-written:
neither LeRobot nor pyserial offers this.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import deque

logger = logging.getLogger(__name__)

RATE_WINDOW = 16  # arrival intervals the rate estimate looks at (at most)
RATE_MIN_INTERVALS = 4  # and at least, before any rate is judged


class StreamError(ConnectionError):
    """No fresh valid frame: the device failed, never sent a valid frame, or went quiet."""


class LatestFrameStream[F]:
    name = "stream"  # what the operator reads in error messages ("Force-sensor", "Glove")
    error_type: type[ConnectionError] = StreamError
    lost_hint = "unplugged?"  # the likely cause of a failed device, for the operator

    def __init__(self, source: str, stale_timeout_s: float, frozen_frames: int = 0, min_rate_hz: float = 0.0):
        self.source = source  # port or address, for messages
        self.stale_timeout_s = stale_timeout_s
        self.frozen_frames = frozen_frames
        self.min_rate_hz = min_rate_hz
        self._arrivals: deque[float] = deque(maxlen=RATE_WINDOW + 1)  # host arrival times of the newest frames
        self.frames = 0  # frames kept since the stream started
        self.counter_faults = 0  # frames dropped because their counter repeated or ran backwards
        self._latest: F | None = None
        self._latest_t = 0.0  # arrival of the newest frame that proves the device alive (not frozen)
        self._runs: list[int] = []  # per content channel: frames in a row with the same value
        self._previous_content: tuple = ()
        self._error: BaseException | None = None
        self._cond = threading.Condition()
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()

    # --- the device (subclasses) ------------------------------------------------------------------------------
    def _open(self) -> None:
        raise NotImplementedError

    def _receive(self) -> list[F]:
        """Decoded valid frames from one read. Returns [] after at most ~50 ms without any, so the thread sees a
        stop request. Raises if the device has failed."""
        raise NotImplementedError

    def _close(self) -> None:
        raise NotImplementedError

    def _keep(self, frame: F, now: float) -> bool:
        """Whether `frame` replaces the newest one (called under the lock; `self._latest` is the previous one)."""
        return True

    def _content(self, frame: F) -> tuple:
        """The noisy values of a frame, one entry per channel, for the frozen-value check."""
        return ()

    def _content_names(self) -> list[str]:
        return [f"channel {i}" for i in range(len(self._runs))]

    def frozen_channels(self) -> list[str]:
        """Channels whose value has been identical for `frozen_frames` frames or more."""
        if not self.frozen_frames:
            return []
        names = self._content_names()
        runs = enumerate(self._runs)
        return [names[i] if i < len(names) else str(i) for i, r in runs if r + 1 >= self.frozen_frames]

    def _note_content(self, frame: F) -> None:
        content = self._content(frame)
        if len(content) != len(self._previous_content):
            self._runs = [0] * len(content)
        else:
            self._runs = [
                r + 1 if a == b and a is not None else 0  # None: no such channel in this frame
                for r, a, b in zip(self._runs, content, self._previous_content)
            ]
        self._previous_content = content

    # --- lifecycle ----------------------------------------------------------------------------------------------

    def start(self) -> None:
        self._open()
        with self._cond:
            # A frame from an earlier session must neither count as fresh nor shadow a restarted sender's counter.
            self._latest, self._error = None, None
            self._runs, self._previous_content = [], ()
            self._arrivals.clear()
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name=f"{self.name}-stream", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=1.0)
            self._thread = None
        self._close()

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                frames = self._receive()
            except Exception as e:  # the device is gone: stop reading; the next read reports it
                if not self._stop.is_set():
                    logger.error("%s stream on %s failed: %s", self.name, self.source, e)
                    self._error = e
                return
            if not frames:
                continue
            now = time.monotonic()
            with self._cond:
                for f in frames:
                    if self._keep(f, now):
                        self._note_content(f)
                        if self._latest is None or not self.frozen_channels():
                            self._latest_t = now
                        self._latest = f
                        self.frames += 1
                        self._arrivals.append(now)
                self._cond.notify_all()

    # --- readers ------------------------------------------------------------------------------------------------
    def wait_frames(self, n: int, timeout_s: float) -> bool:
        """Wait until `n` more frames have been kept; False on timeout."""
        deadline = time.monotonic() + timeout_s
        with self._cond:
            target = self.frames + n
            while self.frames < target:
                left = deadline - time.monotonic()
                if left <= 0 or self._error is not None:
                    return False
                self._cond.wait(min(left, 0.05))
        return True

    def latest(self) -> tuple[F, float]:
        """(newest frame, its age in s). Raises `error_type` if the device failed or no frame has arrived."""
        with self._cond:
            frame, t = self._latest, self._latest_t
        if self._error is not None:
            raise self.error_type(f"{self.name} port '{self.source}' failed ({self.lost_hint}): {self._error}")
        if frame is None:
            raise self.error_type(f"No {self.name.lower()} frame received on '{self.source}'.")
        return frame, time.monotonic() - t

    def reset_rate_window(self) -> None:
        """Forget the arrival times (call under the lock, from `_keep`): a device that restarted was silent while it
        booted, which is not a slow device."""
        self._arrivals.clear()

    def rate_hz(self) -> float | None:
        """Frames per second the device sends: the newest arrival intervals over the time they span; None until
        `RATE_MIN_INTERVALS` intervals were seen."""
        with self._cond:
            times = list(self._arrivals)
        if len(times) - 1 < RATE_MIN_INTERVALS:
            return None
        span = times[-1] - times[0]
        return float("inf") if span <= 0 else (len(times) - 1) / span

    def fresh(self) -> F:
        """The newest frame if it is at most `stale_timeout_s` old, flags no fault and the stream is not slow;
        raises `error_type` otherwise, saying which it is. A fault the device names comes before "slow": a device
        with a failed channel sends fewer frames, and the failed channel is the cause to report."""
        frame, age = self.latest()
        if age > self.stale_timeout_s:
            raise self.error_type(
                f"{self.name} data is stale: newest frame is {age * 1e3:.0f} ms old "
                f"(limit {self.stale_timeout_s * 1e3:.0f} ms{self._stale_detail()})."
            )
        if fault := self._fault(frame):
            raise self.error_type(fault)
        if self.min_rate_hz and (rate := self.rate_hz()) is not None and rate < self.min_rate_hz:
            raise self.error_type(
                f"{self.name} stream is slow: fresh frames arrive at {rate:.1f}/s, below the {self.min_rate_hz:g}/s "
                f"the control loop needs{self._slow_detail()}."
            )
        return frame

    def _fault(self, frame: F) -> str:
        """The fault a frame itself flags, for the operator ("" when none)."""
        return ""

    def _slow_detail(self) -> str:
        return ""

    def _stale_detail(self) -> str:
        out = ""
        if frozen := self.frozen_channels():
            out += (f"; {frozen} repeat the same value bit for bit for >= {self.frozen_frames} frames, which the "
                    "sensor noise never does (frozen firmware or ADC)")  # fmt: skip
        if self.counter_faults:
            out += (
                f"; {self.counter_faults} frames with a repeated or backward counter (re-sent or replayed frames)"
            )
        return out
