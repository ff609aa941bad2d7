"""The Dynamixel bus on the host: LeRobot's bus with retries and an exclusive port (`bus.py`), and the USB adapter's
latency timer (`latency_timer.py`)."""

from . import latency_timer
from .bus import PortLostError, RetryingDynamixelBus

__all__ = ["PortLostError", "RetryingDynamixelBus", "latency_timer"]
