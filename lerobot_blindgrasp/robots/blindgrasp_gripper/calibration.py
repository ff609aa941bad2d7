"""Raw servo ticks -> the sim's joint zero and direction, from two hand-held poses (torque off).

1. Reference pose (q = 0 on every joint, table in `robot_configs/README.md`): fingers hang straight down from the
   plate, each finger in its own vertical plane through the claw axis.
2. Positive pose: every joint moved by hand at least `calibration_min_motion_rad` in its positive direction
   (J*0: fingertip counter-clockwise seen from above; J*1, J*2: fingertip swings away from the claw axis, opening).

The sign of (positive - reference) gives Drive_Mode bit 0 (reverse) per servo, so every servo counts up in the
sim's positive direction; Homing_Offset then puts the reference pose at `units.ZERO_TICK`. Both live in the servo's
EEPROM, so the firmware itself reports sim-convention positions and `DynamixelMotorsBus.is_calibrated` can check
them against the file. Drive mode is written before the homing offset is computed from a fresh reading, so the
result only relies on the firmware's documented rules (reverse negates the count, homing offset adds to it).
"""

from __future__ import annotations

from lerobot.motors import MotorCalibration

from .units import RAD_PER_TICK, TICKS_PER_REV, ZERO_TICK, rad_to_ticks

REVERSE_BIT = 0x01


def wrapped_delta(a: int, b: int) -> int:
    """b - a in ticks, folded into one turn (a hand move never exceeds half a turn)."""
    d = (b - a) % TICKS_PER_REV
    return d - TICKS_PER_REV if d > TICKS_PER_REV // 2 else d


def directions(reference: dict[str, int], positive: dict[str, int], min_motion_rad: float) -> dict[str, int]:
    """Drive_Mode per joint (0 normal, 1 reverse) from the two poses; refuses joints that did not move enough."""
    min_ticks = min_motion_rad / RAD_PER_TICK
    still = [j for j in reference if abs(wrapped_delta(reference[j], positive[j])) < min_ticks]
    if still:
        raise ValueError(
            f"Joints {still} moved less than {min_motion_rad:.2f} rad between the reference and positive poses; "
            "move each of them clearly in its positive direction and calibrate again."
        )
    return {j: (0 if wrapped_delta(reference[j], positive[j]) > 0 else REVERSE_BIT) for j in reference}


def homing_offsets(
    reference: dict[str, int], positive: dict[str, int], present_after_drive_mode: dict[str, int]
) -> dict[str, int]:
    """Homing_Offset that makes the reference pose read ZERO_TICK.

    `present_after_drive_mode` is read in the positive pose after writing Drive_Mode (homing offset 0). In the new
    direction the reference pose lies |delta| ticks below that reading.
    """
    return {
        j: ZERO_TICK - (present_after_drive_mode[j] - abs(wrapped_delta(reference[j], positive[j])))
        for j in reference
    }


def build(
    ids: dict[str, int], drive_modes: dict[str, int], homings: dict[str, int], lower, upper
) -> dict[str, MotorCalibration]:
    """The LeRobot calibration record; range_min/max are the joint limits in calibrated ticks."""
    return {
        j: MotorCalibration(
            id=ids[j],
            drive_mode=drive_modes[j],
            homing_offset=homings[j],
            range_min=rad_to_ticks(lo),
            range_max=rad_to_ticks(hi),
        )
        for j, lo, hi in zip(ids, lower, upper, strict=True)
    }
