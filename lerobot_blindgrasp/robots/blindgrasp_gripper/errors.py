"""Errors the gripper raises after a safety stop: `GripperSafetyStop` and its subclasses are all raised with the
torque already off. A refused policy (`PolicyMismatchError`, policy_contract's) and a refused tare (`ForceTareError`)
stop nothing."""

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


class GripperReadingError(GripperSafetyStop):
    """Servo position readings stayed physically implausible after the re-reads (`hardware/plausibility.py`)."""


class GripperPortBusyError(GripperSafetyStop, ConnectionError):
    """Another process (or robot object) owns the bus or force-sensor port; refused before a byte was sent."""


class GripperPortAccessError(GripperSafetyStop, ConnectionError):
    """This user may not open the bus or force-sensor port (permissions); refused before a byte was sent."""


class GripperTimingError(GripperSafetyStop):
    """The control loop overran its period for longer than `max_overrun_s`: the data would no longer be at the
    rate the policy and the dataset assume."""


class GripperHealthError(GripperSafetyStop):
    """A servo's health item (temperature, input voltage, current against its limit) reached its ERROR level, or was
    too close to its limit to start a trial or episode (`hardware/servo_diagnostics.py`): stopped before the firmware's own shutdown."""


class GripperStallError(GripperHealthError):
    """A finger sat at its current limit for `xm430.STALL_STOP_S` (stopped, torque off). Only the command was at
    fault, so an evaluation ends that trial as a failure and reconnects for the next one."""


class GripperConsistencyError(GripperSafetyStop):
    """Two inputs that see the same physics disagree beyond what physics allows (`hardware/consistency.py`): a fingertip force
    its finger's servos do not hold, or a servo that does not drive its joint toward the goal."""


class GripperProtectionError(GripperSafetyStop):
    """A register that protects a servo while no host watches it (Shutdown, Temperature_Limit, the voltage window,
    PWM_Limit, Current_Limit) could not be restored to its configured value: refused at connect."""


class GripperFirmwareError(GripperSafetyStop):
    """A servo's firmware is older than a defence needs (Drive_Mode and Bus_Watchdog: v38); refused at connect."""
