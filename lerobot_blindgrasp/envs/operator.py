"""The operator's keys during a real-gripper evaluation: ENTER starts a trial, s/y or f/n decides it.

Key presses come from LeRobot's own listener (pynput, or the controlling terminal when headless), into a queue.
"""

from __future__ import annotations

import queue
import time

SUCCESS_KEYS = frozenset({"s", "y"})
FAILURE_KEYS = frozenset({"f", "n"})


class OperatorKeys:
    """Key presses as a queue; `listener_factory` has the signature of LeRobot's `create_key_listener` (default)."""

    HELP = "ENTER=start trial, s/y=success, f/n=failure"

    def __init__(self, listener_factory=None):
        if listener_factory is None:
            from lerobot.utils.keyboard_input import create_key_listener as listener_factory

        self.queue: queue.Queue[str] = queue.Queue()
        self.listener = listener_factory(self.queue.put, controls_help=self.HELP)

    @property
    def available(self) -> bool:
        return self.listener is not None

    def clear(self) -> None:
        while not self.queue.empty():
            self.queue.get_nowait()

    def poll(self) -> str | None:
        try:
            return self.queue.get_nowait()
        except queue.Empty:
            return None

    def wait_for(self, keys: set[str], timeout_s: float | None = None) -> str | None:
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        while True:
            left = None if deadline is None else deadline - time.monotonic()
            if left is not None and left <= 0:
                return None
            try:
                key = self.queue.get(timeout=left)
            except queue.Empty:
                return None
            if key in keys:
                return key

    def stop(self) -> None:
        if self.listener is not None:
            self.listener.stop()
