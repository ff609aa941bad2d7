"""The Dynamixel bus on the host: LeRobot's `DynamixelMotorsBus` with retries, an exclusive port and a clean line per
try (`bus.py`), and the USB adapter's latency timer (`latency_timer.py`). The XM430's own facts (units, limits,
the registers LeRobot's table lacks) are `hardware/xm430.py`, which the sim reads too."""

from . import latency_timer
from .bus import PortLostError, RetryingDynamixelBus

__all__ = ["PortLostError", "RetryingDynamixelBus", "latency_timer"]
