"""The USB-serial adapter's latency timer: 1 ms, or a warning that says how to get it. An FTDI chip (the U2D2, a
Nano's FT232RL) holds a short packet up to `latency_timer` ms (Linux default 16) before handing it on: at three sync
reads a period, up to half of a 20 Hz budget. Other adapters and pseudo-terminals have no such file.
"""

from __future__ import annotations

import logging
import os
from dataclasses import dataclass
from pathlib import Path

logger = logging.getLogger(__name__)

SYSFS_ROOT = Path("/sys")
TARGET_MS = 1


@dataclass(frozen=True)
class LatencyTimerCheck:
    port: str
    sysfs_file: Path | None  # None: not an adapter with a latency timer (pty, CH340, CDC-ACM): nothing to do
    before_ms: int | None = None
    after_ms: int | None = None
    error: str | None = None  # why it could not be set (permission, read-only sysfs)

    @property
    def ok(self) -> bool:
        return self.after_ms is not None and self.after_ms <= TARGET_MS

    def warning(self) -> str | None:
        """The operator's message, or None when there is nothing to say."""
        if self.sysfs_file is None or self.ok:
            return None
        now = "could not be read" if self.before_ms is None else f"is {self.before_ms} ms"
        return (
            f"The USB latency timer of '{self.port}' {now} and could not be set to {TARGET_MS} ms "
            f"({self.error}). Every reply then waits up to that long (16 ms by default) in the adapter. Run\n"
            f"    echo {TARGET_MS} | sudo tee {self.sysfs_file}\n"
            "or install robot_configs/udev/99-blindgrasp.rules, which sets it at every plug-in (docs/bringup.md)."
        )


def check_latency_timer(port: str, sysfs_root: Path = SYSFS_ROOT) -> LatencyTimerCheck:
    """Read the adapter's latency timer and lower it to `TARGET_MS` where this process may write it."""
    tty = Path(os.path.realpath(port)).name  # a udev or by-id symlink names the tty whose driver has the file
    path = Path(sysfs_root) / "bus" / "usb-serial" / "devices" / tty / "latency_timer"
    if not path.is_file():
        return LatencyTimerCheck(port, None)
    try:
        before = int(path.read_text().strip())
    except (OSError, ValueError) as e:
        return LatencyTimerCheck(port, path, error=f"unreadable: {e}")
    if before <= TARGET_MS:
        return LatencyTimerCheck(port, path, before, before)
    try:
        path.write_text(f"{TARGET_MS}\n")
        after = int(path.read_text().strip())
    except OSError as e:  # not root (the usual case: the file is root's), or a read-only /sys in a container
        return LatencyTimerCheck(port, path, before, None, error=e.strerror or str(e))
    except ValueError as e:
        return LatencyTimerCheck(port, path, before, None, error=f"unreadable after the write: {e}")
    if after > TARGET_MS:
        return LatencyTimerCheck(port, path, before, after, error=f"the driver kept {after} ms")
    return LatencyTimerCheck(port, path, before, after)


def ensure_low_latency(*ports: str, sysfs_root: Path | None = None) -> list[LatencyTimerCheck]:
    """What connect() calls for each serial port: sets 1 ms where it may, logs what it did or what to run."""
    results = []
    for port in ports:
        result = check_latency_timer(port, SYSFS_ROOT if sysfs_root is None else sysfs_root)
        if (message := result.warning()) is not None:
            logger.warning(message)
        elif result.before_ms is not None and result.before_ms != result.after_ms:
            logger.info("USB latency timer of '%s': %d ms -> %d ms", port, result.before_ms, result.after_ms)
        results.append(result)
    return results
