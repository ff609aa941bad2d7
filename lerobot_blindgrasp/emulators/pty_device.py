"""A pseudo-terminal pair whose slave path a client opens like a USB serial adapter."""

from __future__ import annotations

import os
import select
import threading
import tty


class PtyDevice:
    """Owns a pty; subclasses implement `_on_bytes` (requests) and/or `_tick` (periodic work) in one thread."""

    tick_s = 0.002

    def __init__(self) -> None:
        self.master_fd, self._slave_fd = os.openpty()
        # Raw mode before any client opens the slave: no echo, no CR/LF translation, no flow control bytes.
        tty.setraw(self._slave_fd)
        # Non-blocking master: with no client reading, a real UART just loses bytes; we must not block either.
        os.set_blocking(self.master_fd, False)
        # Keeping our own slave fd open means reads on the master never hit EIO between client sessions.
        self.port = os.ttyname(self._slave_fd)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self) -> PtyDevice:
        self._thread = threading.Thread(target=self._run, name=type(self).__name__, daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        """Also the USB adapter pulled: every operation of a client on its open port then fails with EIO (pyserial's
        SerialException on read/write, termios.error on flush), as with a real adapter."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        for fd in (self.master_fd, self._slave_fd):
            if fd < 0:
                continue
            try:
                os.close(fd)
            except OSError:
                pass
        self.master_fd = self._slave_fd = -1

    def __enter__(self):
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

    def write(self, data: bytes) -> bool:
        """Queue bytes for the client; False (nothing sent) when its input buffer is full."""
        try:
            n = os.write(self.master_fd, data)
        except (BlockingIOError, OSError):
            return False
        if n < len(data):  # rare: finish the packet rather than leave half of it on the line
            select.select([], [self.master_fd], [], 0.05)
            try:
                os.write(self.master_fd, data[n:])
            except (BlockingIOError, OSError):
                return False
        return True

    def _run(self) -> None:
        while not self._stop.is_set():
            readable, _, _ = select.select([self.master_fd], [], [], self.tick_s)
            if readable:
                try:
                    data = os.read(self.master_fd, 4096)
                except OSError:
                    data = b""
                if data:
                    self._on_bytes(data)
            self._tick()

    def _on_bytes(self, data: bytes) -> None:
        pass

    def _tick(self) -> None:
        pass
