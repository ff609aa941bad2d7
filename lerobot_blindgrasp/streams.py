"""One "latest frame" stream for the devices that push data at their own rate: the fingertip force sensors (serial)
and the glove bridge (UDP).

A background thread receives and decodes frames and keeps only the newest valid one, with its arrival time on
this host's monotonic clock. The control loop never blocks on the device. It asks for the newest frame and its age,
and treats a frame older than `stale_timeout_s` as a fault. A device that fails (unplugged USB cable, closed
socket) ends the thread. The failure is then raised at the next read, so it is not discarded.

Subclasses say how to open, receive and close (`_open`, `_receive`, `_close`), and may filter frames (`_keep`).
Hand-written because neither LeRobot nor pyserial offers this; LeRobot's cameras do the same inside
`OpenCVCamera.async_read`, which is specific to frames from OpenCV.
"""

from __future__ import annotations

import logging
import threading
import time
from typing import Generic, TypeVar

logger = logging.getLogger(__name__)

F = TypeVar("F")


class StreamError(ConnectionError):
    """No fresh valid frame: the device failed, never sent a valid frame, or went quiet."""


class LatestFrameStream(Generic[F]):
    name = "stream"  # what the operator reads in error messages ("Force-sensor", "Glove")
    error_type: type[ConnectionError] = StreamError
    lost_hint = "unplugged?"  # the likely cause of a failed device, for the operator

    def __init__(self, source: str, stale_timeout_s: float):
        self.source = source  # port or address, for messages
        self.stale_timeout_s = stale_timeout_s
        self.frames = 0  # frames kept since the stream started
        self._latest: F | None = None
        self._latest_t = 0.0
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

    # --- lifecycle ----------------------------------------------------------------------------------------------
    @property
    def is_running(self) -> bool:
        return self._thread is not None

    def start(self) -> None:
        self._open()
        with self._cond:
            # A frame from an earlier session must neither count as fresh nor shadow a restarted sender's counter.
            self._latest, self._error = None, None
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
                        self._latest, self._latest_t = f, now
                        self.frames += 1
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

    def fresh(self) -> F:
        """The newest frame if it is at most `stale_timeout_s` old; raises `error_type` otherwise."""
        frame, age = self.latest()
        if age > self.stale_timeout_s:
            raise self.error_type(
                f"{self.name} data is stale: newest frame is {age * 1e3:.0f} ms old "
                f"(limit {self.stale_timeout_s * 1e3:.0f} ms{self._stale_detail()})."
            )
        return frame

    def _stale_detail(self) -> str:
        return ""
