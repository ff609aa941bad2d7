"""Facts about the XM430-W350 servo (ROBOTIS e-Manual, 12 V), shared by the sim and the real gripper.

No MuJoCo and no LeRobot here: the sim's actuator model (`sim/gripper.py`) and the robot's registers
(`robots/blindgrasp_gripper/`) both read these numbers, so the sim's torque limit and the real current limit
cannot drift apart.
"""

from __future__ import annotations

import math

MODEL = "xm430-w350"  # the model name in LeRobot's Dynamixel tables

# --- motor --------------------------------------------------------------------------------------------------------
STALL_TORQUE_NM = 4.1  # at 12 V
STALL_CURRENT_A = 2.3  # at 12 V
NO_LOAD_SPEED_RAD_S = 46.0 * 2.0 * math.pi / 60.0  # 46 rpm at 12 V
GEAR_RATIO = 353.5

# --- control table units ------------------------------------------------------------------------------------------
TICKS_PER_REV = 4096  # Present_Position / Goal_Position: 12-bit absolute encoder
RAD_PER_TICK = 2.0 * math.pi / TICKS_PER_REV
CURRENT_UNIT_A = 0.00269  # Present_Current / Goal_Current / Current_Limit: 2.69 mA per unit
CURRENT_LIMIT_MAX_UNITS = 1193  # Current_Limit register maximum (~3.2 A)
HOMING_OFFSET_MAX = 1_044_479  # Homing_Offset(20) range, +-
WATCHDOG_UNIT_MS = 20  # Bus_Watchdog(98) counts 20 ms units
WATCHDOG_TRIPPED = 255  # Bus_Watchdog reads -1 (one unsigned byte) after the watchdog stopped the servo
HARDWARE_ERROR_BITS = {  # Hardware_Error_Status(70)
    0x01: "input voltage",
    0x04: "overheating",
    0x08: "motor encoder",
    0x10: "electrical shock",
    0x20: "overload",
}


def amps_to_current_units(amps: float) -> int:
    return int(round(amps / CURRENT_UNIT_A))


def torque_at_current_nm(amps: float) -> float:
    """Torque the servo can hold at this current limit, on the stall line (linear, through the origin). So the
    2.3 A default current limit is the sim's 4.1 N m torque clip (torque ~ current near stall)."""
    return STALL_TORQUE_NM * amps / STALL_CURRENT_A


def decode_hardware_error(bits: int) -> str:
    names = [name for bit, name in HARDWARE_ERROR_BITS.items() if bits & bit]
    return ", ".join(names) or f"bits {bits:#04x}"
