"""Facts about the XM430-W350 servo (ROBOTIS e-Manual, 12 V), read by the sim's actuator model and the robot alike,
so the sim's torque limit and the real current limit cannot drift apart."""

from __future__ import annotations

import math

MODEL = "xm430-w350"  # the model name in LeRobot's Dynamixel tables

# --- motor --------------------------------------------------------------------------------------------------------
STALL_TORQUE_NM = 4.1  # at 12 V
STALL_CURRENT_A = 2.3  # at 12 V
NO_LOAD_SPEED_RAD_S = 46.0 * 2.0 * math.pi / 60.0  # 46 rpm at 12 V

# --- control table units ------------------------------------------------------------------------------------------
TICKS_PER_REV = 4096  # Present_Position / Goal_Position: 12-bit absolute encoder
RAD_PER_TICK = 2.0 * math.pi / TICKS_PER_REV
CURRENT_UNIT_A = 0.00269  # Present_Current / Goal_Current / Current_Limit: 2.69 mA per unit
CURRENT_LIMIT_MAX_UNITS = 1193  # Current_Limit register maximum (~3.2 A)
HOMING_OFFSET_MAX = 1_044_479  # Homing_Offset(20) range, +-
WATCHDOG_UNIT_MS = 20  # Bus_Watchdog(98) counts 20 ms units
WATCHDOG_TRIPPED = 255  # Bus_Watchdog reads -1 (one unsigned byte) after the watchdog stopped the servo
# Firmware the defences need (e-Manual): Drive_Mode(10) (half of the calibration) and Bus_Watchdog(98) (the dead
# host's stop) are "available from firmware v38"; Startup_Configuration(60) and Backup_Ready(147) from v45.
FIRMWARE_MIN = 38
FIRMWARE_STARTUP_CONFIGURATION = 45
STARTUP_TORQUE_ON = 0x01  # Startup_Configuration(60) bit 0: the torque comes on by itself at power-up
# Items of the e-Manual's control table that LeRobot's X-series table lacks: (address, size).
EXTRA_REGISTERS = {"Startup_Configuration": (60, 1), "Backup_Ready": (147, 1)}
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


# --- health items and their limits (XM430-W350 e-Manual: control table, "Specifications") ---------------------------
# The datasheet's own numbers; every health level below is derived from them here, and nowhere else.
TEMPERATURE_UNIT_C = 1.0  # Present_Temperature(146), Temperature_Limit(31): 1 degC per unit
TEMPERATURE_LIMIT_DEFAULT_C = 80  # Temperature_Limit(31) factory value; range 0..100
VOLTAGE_UNIT_V = 0.1  # Present_Input_Voltage(144), Max/Min_Voltage_Limit(32/34): 0.1 V per unit
MAX_VOLTAGE_LIMIT_DEFAULT_V = 16.0  # Max_Voltage_Limit(32) factory value (160); range 9.5..16.0 V
MIN_VOLTAGE_LIMIT_DEFAULT_V = 9.5  # Min_Voltage_Limit(34) factory value (95)
RATED_VOLTAGE_V = (10.0, 14.8)  # operating voltage range of the XM430-W350 (recommended 12.0 V)
RECOMMENDED_VOLTAGE_V = 12.0
SHUTDOWN_DEFAULT = 0x34  # Shutdown(63): overheating | electrical shock | overload turn the torque off
# The EEPROM registers that protect a servo while no host watches it, at the factory values the sim's servo model and
# the health levels assume: restored at every connect, or the connect is refused (`servo_registers.py`).
NO_HOST_PROTECTION = {
    "Shutdown": SHUTDOWN_DEFAULT,  # which hardware errors drop the torque by themselves
    "Temperature_Limit": TEMPERATURE_LIMIT_DEFAULT_C,  # the overheating error's threshold
    "Max_Voltage_Limit": round(MAX_VOLTAGE_LIMIT_DEFAULT_V / VOLTAGE_UNIT_V),  # the input-voltage error's window
    "Min_Voltage_Limit": round(MIN_VOLTAGE_LIMIT_DEFAULT_V / VOLTAGE_UNIT_V),
    "PWM_Limit": 885,  # the motor's voltage cap: its torque and speed with or without a host (100 %)
}

# What the host does before the firmware does (ROS 2 diagnostics' OK / WARN / ERROR): margins below the limits.
TEMPERATURE_WARN_MARGIN_C = 15.0  # WARN at 65 degC with the default limit
TEMPERATURE_START_MARGIN_C = 8.0  # a trial or episode does not start at >= 72 degC
TEMPERATURE_STOP_MARGIN_C = 3.0  # named stop, torque off, at >= 77 degC (the firmware's own shutdown is 80)
TEMPERATURE_TREND_HORIZON_S = 30.0  # stop when the trend reaches Temperature_Limit within this horizon
VOLTAGE_WARN_LOW_V = 11.0  # under load, below this the servo no longer has its 12 V torque
VOLTAGE_START_LOW_V = 10.8  # no trial below this at rest: the load will sag it under the rating
VOLTAGE_STOP_LOW_V = RATED_VOLTAGE_V[0]  # below the rating for VOLTAGE_STOP_HOLD_S: named stop
VOLTAGE_HIGH_V = RATED_VOLTAGE_V[1]  # above the rating: refused / stopped
VOLTAGE_STOP_HOLD_S = 0.5
STALL_FRACTION = 0.95  # |Present_Current| >= this x the current limit is "at the limit"
STALL_WARN_S = 2.0  # at the limit this long: WARN
# At the limit this long: named stop. ROBOTIS does not publish the overload error's time constant; this keeps a held
# grasp (the trial needs >= 1 s of hold) and stops a finger stalled against something for most of a trial.
STALL_STOP_S = 6.0


def current_units_to_amps(units: int) -> float:
    return units * CURRENT_UNIT_A


def voltage_v(units: int) -> float:
    return units * VOLTAGE_UNIT_V
