"""Errors the gripper raises after a safety stop. Every one of them is raised with the torque already off."""

from __future__ import annotations


class GripperSafetyStop(RuntimeError):
    """The gripper stopped itself (torque off on all servos it could reach) and the run must not go on."""


class GripperBusError(GripperSafetyStop, ConnectionError):
    """The Dynamixel bus kept failing after the configured retries (timeouts, corrupted packets, lost servo)."""


class GripperHardwareError(GripperSafetyStop):
    """A servo reported Hardware_Error_Status bits (overload, overheating, voltage, encoder, electrical shock)."""


class ForceOverloadError(GripperSafetyStop):
    """A fingertip force exceeded the configured overload limit."""


class ForceSensorError(GripperSafetyStop, ConnectionError):
    """The fingertip force stream is stale, missing or reports a sensor fault."""


class GripperStateError(GripperSafetyStop):
    """A servo no longer holds what `configure()` set (torque, gains, current limit, watchdog): it was reset."""
