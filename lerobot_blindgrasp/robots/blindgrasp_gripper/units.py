"""XM430-W350 register units <-> the physical units of `spec` (rad, A, N m).

The calibration (see `calibration.py`) writes Drive_Mode and Homing_Offset so that the servo itself reports
ZERO_TICK at the sim's q = 0 and counts up in the sim's positive direction. Converting is then one affine map,
the same for every joint and independent of how a servo horn was mounted.
"""

from __future__ import annotations

import math

TICKS_PER_REV = 4096  # AS5045 12-bit encoder
RAD_PER_TICK = 2.0 * math.pi / TICKS_PER_REV
ZERO_TICK = 2048  # Present_Position at q = 0 after calibration: mid-turn, far from 0/4095 on both sides

# Present_Current / Goal_Current / Current_Limit unit of the XM430-W350 (e-Manual): 2.69 mA.
CURRENT_UNIT_A = 0.00269
# Stall at 12 V: 4.1 N m at 2.3 A. The sim clips each joint torque at 4.1 N m (`sim.gripper.PhysicsOptions
# .torque_limit`), so a 2.3 A current limit is the same saturation on the real servo (torque ~ current near stall).
STALL_TORQUE_NM = 4.1
STALL_CURRENT_A = 2.3
CURRENT_LIMIT_MAX_UNITS = 1193  # register maximum (~3.2 A)


def ticks_to_rad(ticks: float) -> float:
    return (ticks - ZERO_TICK) * RAD_PER_TICK


def rad_to_ticks(q: float) -> int:
    return int(round(ZERO_TICK + q / RAD_PER_TICK))


def amps_to_current_units(amps: float) -> int:
    return int(round(amps / CURRENT_UNIT_A))


def current_units_to_amps(units: float) -> float:
    return units * CURRENT_UNIT_A


def torque_at_current_nm(amps: float) -> float:
    """Torque the servo can hold at this current limit, on the stall line (linear, through the origin)."""
    return STALL_TORQUE_NM * amps / STALL_CURRENT_A
