"""One owner per gripper: its serial ports are opened with pyserial's `exclusive=True`, an advisory flock taken before
any byte is written, so a second owner is refused before it can touch the servos. The lock goes with the file
descriptor: a crashed owner leaves no stale lock."""

from __future__ import annotations

import errno

import serial

_BUSY = {errno.EAGAIN, errno.EWOULDBLOCK, errno.EACCES}  # what a refused flock() reports
_NO_ACCESS = {errno.EACCES, errno.EPERM}  # what a refused open() reports


class PortInUseError(ConnectionError):
    """The serial port is held by another process (or another robot object): refused before sending a byte."""


class PortAccessError(ConnectionError):
    """This user may not open the serial port (not in the `dialout` group, no udev rule): nothing was sent."""


def open_exclusive(port: str, baudrate: int, what: str, **kwargs) -> serial.Serial:
    """`serial.Serial(port, baudrate, exclusive=True, **kwargs)`, with a busy port as `PortInUseError`."""
    try:
        return serial.Serial(port, baudrate, exclusive=True, **kwargs)
    except serial.SerialException as e:
        # pyserial says which step failed: "could not open port" (os.open: permissions) or "Could not exclusively
        # lock port" (flock: another owner). Both can carry EACCES, so the step decides.
        if e.errno in _NO_ACCESS and "could not open port" in str(e):
            raise PortAccessError(
                f"No permission to open the {what} port '{port}' ({e}). The ports belong to the `dialout` group: "
                "`sudo usermod -aG dialout $USER`, then log out and in again, and install "
                "robot_configs/udev/99-blindgrasp.rules (docs/bringup.md, section 5). Nothing was sent."
            ) from e
        if e.errno in _BUSY:
            raise PortInUseError(
                f"The {what} port '{port}' is already in use by another process (another lerobot script, a "
                "serial monitor, or a second robot object on the same gripper). One gripper has one owner: stop the "
                f"other one first (`fuser {port}` names it). Nothing was sent."
            ) from e
        raise
