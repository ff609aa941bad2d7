"""The operator's keys during a real-gripper evaluation (ENTER starts a trial, s/y or f/n decides it), as a queue:
from a person (`OperatorKeys`, LeRobot's key listener) or from an unattended operator on a Unix socket
(`SocketOperator`, e.g. `blindgrasp-twin`, which places the object and judges by its own rule; protocol:
`twin/operator_server.py`). The trial log records who decided (`judge`).
"""

from __future__ import annotations

import contextlib
import json
import queue
import socket
import threading
import time

SUCCESS_KEYS = frozenset({"s", "y"})
FAILURE_KEYS = frozenset({"f", "n"})


class _KeyQueue:
    judge = "operator"  # who decides the trials (the trial log's decided_by)

    def __init__(self):
        self.queue: queue.Queue[str] = queue.Queue()

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


class OperatorKeys(_KeyQueue):
    """Key presses as a queue; `listener_factory` is LeRobot's `create_key_listener` or one like it."""

    HELP = "ENTER=start trial, s/y=success, f/n=failure"

    def __init__(self, listener_factory=None):
        super().__init__()
        if listener_factory is None:
            from lerobot.utils.keyboard_input import create_key_listener as listener_factory

        self.listener = listener_factory(self.queue.put, controls_help=self.HELP)
        self.available = self.listener is not None  # the factory gives None without a keyboard (no display)

    def stop(self) -> None:
        if self.listener is not None:
            self.listener.stop()


class SocketOperator(_KeyQueue):
    """The operator at the other end of a Unix socket: told each trial's object and seed, it answers ENTER once the
    object is placed, then one outcome key. Keys carry their trial's token: a late key is never counted."""

    def __init__(self, path: str, connect_timeout_s: float = 10.0):
        super().__init__()
        self.path = path
        deadline = time.monotonic() + connect_timeout_s
        while True:
            try:
                self._sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
                self._sock.connect(path)
                break
            except OSError as e:
                self._sock.close()
                if time.monotonic() > deadline:
                    msg = f"No operator listening on {path} ({e}): is blindgrasp-twin running?"
                    raise ConnectionError(msg) from e
                time.sleep(0.2)
        self._lines = self._sock.makefile("rb")
        self.judge = str(json.loads(self._lines.readline())["judge"])
        self._token = 0
        self._asked = False
        self._reader = threading.Thread(target=self._read, name="socket-operator", daemon=True)
        self._reader.start()

    available = True

    def _send(self, msg: dict) -> None:
        self._sock.sendall((json.dumps(msg) + "\n").encode())

    def _read(self) -> None:
        try:
            for line in self._lines:
                msg = json.loads(line)
                if msg.get("token") == self._token and "key" in msg:
                    self.queue.put(msg["key"])
        except (OSError, ValueError):
            pass
        self.queue.put("operator-gone")

    def announce_trial(self, object_name: str, seed: int) -> None:
        """The next trial: `object_name` at evaluation index `seed`."""
        self._token += 1
        self._asked = False
        self._send({"op": "place", "object": object_name, "seed": seed, "token": self._token})

    def wait_for(self, keys: set[str], timeout_s: float | None = None) -> str | None:
        if keys & (SUCCESS_KEYS | FAILURE_KEYS) and not self._asked and self.queue.empty():
            self._asked = True  # the time limit: the operator answers from its verdict so far
            self._send({"op": "ask", "token": self._token})
        key = super().wait_for(keys | {"operator-gone"}, timeout_s)
        if key == "operator-gone":
            raise ConnectionError(f"The operator on {self.path} went away.")
        return key

    def clear(self) -> None:
        super().clear()
        if self._token:
            self._send({"op": "end", "token": self._token})

    def stop(self) -> None:
        # Shut down first: the reader thread's file object would keep the connection open past close().
        with contextlib.suppress(OSError):
            self._sock.shutdown(socket.SHUT_RDWR)
        with contextlib.suppress(OSError):
            self._sock.close()
