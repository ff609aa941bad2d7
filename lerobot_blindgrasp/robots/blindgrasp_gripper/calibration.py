"""Raw servo ticks -> the sim's joint zero and direction, from two hand-held poses (torque off).

1. Reference pose (q = 0 on every joint, table in `robot_configs/README.md`): fingers hang straight down from the
   plate, each finger in its own vertical plane through the claw axis.
2. Positive pose: every joint moved by hand at least `calibration_min_motion_rad` in its positive direction
   (J*0: fingertip counter-clockwise seen from above; J*1, J*2: fingertip swings away from the claw axis, opening).

The sign of (positive - reference) gives Drive_Mode bit 0 (reverse) per servo, so every servo counts up in the
sim's positive direction; Homing_Offset then puts the reference pose at `ZERO_TICK`. Both live in the servo's
EEPROM, so the firmware itself reports sim-convention positions and `DynamixelMotorsBus.is_calibrated` can check
them against the file. Drive mode is written before the homing offset is computed from a fresh reading, so the
result only relies on the firmware's documented rules (reverse negates the count, homing offset adds to it).
Converting a calibrated reading is then one affine map, the same for every joint and independent of how a servo
horn was mounted: q = (ticks - ZERO_TICK) * 2 pi / 4096.
"""

from __future__ import annotations

import dataclasses
import json
import logging
from pathlib import Path

import draccus
from lerobot.motors import MotorCalibration

from lerobot_blindgrasp import durable
from lerobot_blindgrasp.hardware.xm430 import HOMING_OFFSET_MAX, RAD_PER_TICK, TICKS_PER_REV

logger = logging.getLogger(__name__)

REVERSE_BIT = 0x01
ZERO_TICK = 2048  # Present_Position at q = 0 after calibration: mid-turn, far from 0/4095 on both sides


def ticks_to_rad(ticks: float) -> float:
    return (ticks - ZERO_TICK) * RAD_PER_TICK


def rad_to_ticks(q: float) -> int:
    return int(round(ZERO_TICK + q / RAD_PER_TICK))


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


class CalibrationFileError(ValueError):
    """A calibration file that parses but cannot be right; the robot refuses it before any motion."""


RECORD_FIELDS = tuple(f.name for f in dataclasses.fields(MotorCalibration))


def schema_problems(raw: object) -> list[str]:
    """The file's shape, checked on the raw JSON before anything converts it: an object of joint -> record, each
    record exactly LeRobot's `MotorCalibration` fields, each an integer (not a bool, a float or a string that a
    lenient decoder would coerce)."""
    if not isinstance(raw, dict):
        return [f"the top level is {type(raw).__name__}, not an object of joint -> record"]
    out = []
    for joint, record in raw.items():
        if not isinstance(record, dict):
            out.append(f"{joint}: {type(record).__name__}, not a record")
            continue
        missing = [f for f in RECORD_FIELDS if f not in record]
        extra = [f for f in record if f not in RECORD_FIELDS]
        wrong = [f"{f}={record[f]!r:.20}" for f in RECORD_FIELDS if f in record and type(record[f]) is not int]
        if missing:
            out.append(f"{joint}: lacks {missing}")
        if extra:
            out.append(f"{joint}: unknown fields {extra}")
        if wrong:
            out.append(f"{joint}: not integers: {', '.join(wrong)}")
    return out


def read_raw(fpath: Path) -> object:
    """A calibration file's JSON (gripper and glove), or ValueError saying why it is not (empty, truncated, not
    UTF-8, not JSON)."""
    data = Path(fpath).read_bytes()
    if not data.strip():
        raise ValueError("the file is empty")
    try:
        return json.loads(data.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError, RecursionError) as e:
        raise ValueError(f"not complete JSON (truncated or corrupt): {e}") from e


def problems(calibration: dict, ids: dict[str, int]) -> list[str]:
    """What is wrong with a loaded calibration, by the rules `calibrate()` builds it with: one record per joint under
    the configured servo ID, Drive_Mode 0 or 1 (reverse), a Homing_Offset the
    firmware accepts, and a position range 0 <= min < max <= 4095."""
    out = []
    missing, extra = [j for j in ids if j not in calibration], [j for j in calibration if j not in ids]
    if missing:
        out.append(f"joints {missing} are missing")
    if extra:
        out.append(f"unknown joints {extra}")
    for j in ids:
        c = calibration.get(j)
        if c is None:
            continue
        if c.id != ids[j]:
            out.append(f"{j}: servo ID {c.id}, the config says {ids[j]}")
        if c.drive_mode not in (0, REVERSE_BIT):
            out.append(f"{j}: drive_mode {c.drive_mode} (must be 0 or {REVERSE_BIT})")
        if abs(c.homing_offset) > HOMING_OFFSET_MAX:
            out.append(f"{j}: homing_offset {c.homing_offset} outside +-{HOMING_OFFSET_MAX}")
        if not 0 <= c.range_min < c.range_max <= TICKS_PER_REV - 1:
            out.append(f"{j}: range [{c.range_min}, {c.range_max}] must satisfy 0 <= min < max <= 4095")
    return out


class CheckedCalibrationFile:
    """Mixin of `BlindgraspGripper`: LeRobot's calibration file, checked when loaded and written atomically."""

    def _load_calibration(self, fpath=None) -> None:
        """Load and check the file by the rules `calibrate()` follows. A bad file is kept out of `self.calibration`
        and refused by `connect()` (lerobot-calibrate still works: it connects with calibrate=False)."""
        fpath = fpath or self.calibration_fpath
        try:
            bad = schema_problems(read_raw(fpath))
            if not bad:
                super()._load_calibration(fpath)
                bad = problems(self.calibration, dict(zip(self.joints, self.config.servo_ids, strict=True)))
        except Exception as e:  # unreadable: empty, truncated, not JSON, not UTF-8
            bad = [f"unreadable ({type(e).__name__}: {e})"]
        if bad:
            self.calibration = {}
            self.calibration_error = CalibrationFileError(
                f"Calibration file {fpath} is invalid: {'; '.join(bad)}. Nothing was moved. Run "
                f"lerobot-calibrate --robot.type={self.name} --robot.id={self.id} to replace it."
            )
            logger.error("%s", self.calibration_error)
            return
        self.calibration_error = None
        # The position range is derived data: the config's joint limits are its authority (calibrate() builds it so).
        cfg = self.config
        self.calibration = {
            j: dataclasses.replace(self.calibration[j], range_min=rad_to_ticks(lo), range_max=rad_to_ticks(hi))
            for j, lo, hi in zip(self.joints, cfg.joint_lower, cfg.joint_upper, strict=True)
        }

    def _save_calibration(self, fpath=None) -> None:
        """LeRobot's base class writes the file in place, so a full disk truncates the previous calibration. Written
        atomically instead: on failure the old file is unchanged, and `durable.WriteError` (not an OSError, so the
        safety latch does not call it a bus failure) names the file and the cause."""
        with durable.atomic_open(fpath or self.calibration_fpath) as f, draccus.config_type("json"):
            draccus.dump(self.calibration, f, indent=4)
