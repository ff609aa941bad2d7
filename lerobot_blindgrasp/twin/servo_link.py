"""Between the servo emulator's registers and the twin's MuJoCo joints, both ways: `SimShaft` (the emulator's
`ShaftDynamics` hook) reads a servo's shaft from its joint, and `read_commands` turns the registers into the joint
command the physics applies every substep.
"""

from __future__ import annotations

from lerobot_blindgrasp.emulators import mount
from lerobot_blindgrasp.emulators.dynamixel import EmulatedServo
from lerobot_blindgrasp.hardware import xm430

DEFAULT_P_GAIN = 800  # XM430 factory Position_P_Gain: what the sim's nominal kp models
POSITION_MODES = (3, 4, 5)  # position, extended position, current-based position
CURRENT_POSITION = 5
# Torque ~ current on the stall line: register units per N m.
_UNITS_PER_NM = xm430.STALL_CURRENT_A / xm430.STALL_TORQUE_NM / xm430.CURRENT_UNIT_A


class SimShaft:
    """Joint k of the twin's physics as servo shaft dynamics (read from the physics thread's latest copy)."""

    def __init__(self, physics, k: int):
        self.physics, self.k = physics, k

    def advance(self, servo: EmulatedServo, dt: float) -> float:
        k, p = self.k, self.physics
        servo.shaft = float(mount.shaft_for_q(p.q[k], k))
        servo.velocity = float(mount.MOUNT_SIGN[k] * p.qd[k] * mount.TICKS_PER_RAD)
        # Positive joint torque turns the shaft by MOUNT_SIGN; the servo reports it in its Drive_Mode frame.
        return servo.direction * mount.MOUNT_SIGN[k] * float(p.tau[k]) * _UNITS_PER_NM


def read_commands(servos: list[EmulatedServo], command) -> None:
    """Fill the physics' `ServoCommand` from the registers of the servos, in spec.JOINT_NAMES order."""
    for k, s in enumerate(servos):
        mode = s.get("Operating_Mode")
        on = s.get("Torque_Enable") == 1 and mode in POSITION_MODES
        command.enabled[k] = on
        if not on:
            continue
        command.goal_q[k] = float(mount.q_for_shaft(s.position_for(s.get("Goal_Position")), k))
        limit = s.get("Current_Limit")
        if mode == CURRENT_POSITION:
            limit = min(limit, abs(s.get("Goal_Current")))
        command.torque_max_nm[k] = xm430.torque_at_current_nm(limit * xm430.CURRENT_UNIT_A)
        command.kp_factor[k] = s.get("Position_P_Gain") / DEFAULT_P_GAIN
