"""Raw servo ticks -> the sim's joint zero and direction, from two hand-held poses (torque off): the reference pose
(q = 0) and a positive pose. The sign of the motion gives Drive_Mode's reverse bit, then Homing_Offset puts the
reference pose at `ZERO_TICK`, both in EEPROM, so the firmware reports q = (ticks - ZERO_TICK) * 2 pi / 4096. Also
reads, checks and writes the calibration file.
"""

from __future__ import annotations

import builtins
import dataclasses
import json
import logging
import sys
from pathlib import Path

import draccus
from lerobot.motors import MotorCalibration

from lerobot_blindgrasp import durable
from lerobot_blindgrasp.hardware.force_board import force_calibration
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
    """Homing_Offset that makes the reference pose read ZERO_TICK: `present_after_drive_mode`, read in the positive
    pose after writing Drive_Mode (homing offset 0), lies |delta| ticks above the reference pose."""
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


def servo_calibration_schema_problems(raw: object) -> list[str]:
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


def servo_calibration_problems(calibration: dict, ids: dict[str, int]) -> list[str]:
    """What is wrong with a loaded calibration, by the rules `calibrate()` builds it with: one record per joint under
    the configured servo ID, Drive_Mode 0 or 1, a Homing_Offset the firmware accepts, 0 <= min < max <= 4095."""
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


def load_checked(
    fpath: Path, ids: dict[str, int], lower, upper, fix: str
) -> tuple[dict, CalibrationFileError | None]:
    """The calibration file at `fpath`, checked by the rules `calibrate()` follows for servos `ids` (joint -> ID):
    (calibration, None), or ({}, the error) for a bad file, which `connect()` refuses (lerobot-calibrate still works:
    it connects with calibrate=False). `fix` is the command that replaces the file."""
    try:
        bad = servo_calibration_schema_problems(read_raw(fpath))
        if not bad:
            with open(fpath) as f, draccus.config_type("json"):  # as LeRobot's `Robot._load_calibration` reads it
                calibration = draccus.load(dict[str, MotorCalibration], f)
            bad = servo_calibration_problems(calibration, ids)
    except Exception as e:  # unreadable: empty, truncated, not JSON, not UTF-8
        bad = [f"unreadable ({type(e).__name__}: {e})"]
    if bad:
        error = CalibrationFileError(f"Calibration file {fpath} is invalid: {'; '.join(bad)}. Nothing was moved. "
                                     f"Run {fix} to replace it.")  # fmt: skip
        logger.error("%s", error)
        return {}, error
    # The position range is derived data: the config's joint limits are its authority (calibrate() builds it so).
    return {
        j: dataclasses.replace(calibration[j], range_min=rad_to_ticks(lo), range_max=rad_to_ticks(hi))
        for j, lo, hi in zip(ids, lower, upper, strict=True)
    }, None


def save_atomic(calibration: dict[str, MotorCalibration], fpath: Path) -> None:
    """LeRobot's base class writes the file in place, so a full disk truncates the previous calibration. Written
    atomically instead: on failure the old file is unchanged, and `durable.WriteError` (not an OSError, so the
    safety latch does not call it a bus failure) names the file and the cause."""
    with durable.atomic_open(fpath) as f, draccus.config_type("json"):
        draccus.dump(calibration, f, indent=4)


# --- a missing file at connect -----------------------------------------------------------------------------------
# LeRobot's robots calibrate interactively inside `connect()` when no file exists, which fails mid-calibration or
# waits for ever when nobody can answer; the usual cause is a wrong `--robot.id`, so the refusal names the known ones.
_BUILTIN_INPUT = builtins.input


def operator_can_answer() -> bool:
    """True if a prompt reaches someone: stdin is a terminal, or the program replaced `input()` with its own
    answers (a GUI, a scripted operator)."""
    if builtins.input is not _BUILTIN_INPUT:
        return True
    try:
        return sys.stdin is not None and sys.stdin.isatty()
    except ValueError:  # stdin closed
        return False


def calibrated_ids(calibration_dir: Path) -> list[str]:
    """The robot ids with a servo calibration `<id>.json` in the folder (force calibrations `<id>.force.json`
    share the folder and are not ids)."""
    files = Path(calibration_dir).glob("*.json")
    return sorted(p.stem for p in files if not force_calibration.is_force_calibration(p))


def refuse_unattended(calibration: dict, fpath: Path, robot_id: str) -> None:
    """Raise a CalibrationFileError if there is no `calibration` and no operator could calibrate it now."""
    if calibration or operator_can_answer():
        return
    known = calibrated_ids(fpath.parent)
    hint = (f" Calibrated ids in {fpath.parent}: {', '.join(known)}; pass the one of this gripper as "
            "--robot.id (lerobot-eval: --env.robot.id).") if known else ""  # fmt: skip
    raise CalibrationFileError(
        f"No calibration file for robot id '{robot_id}' ({fpath}), and no operator at this "
        f"terminal to calibrate it now (stdin is not a terminal). Nothing was moved.{hint} To calibrate, run "
        f'lerobot-calibrate --robot="include robot_configs/blindgrasp_gripper.yaml" --robot.id={robot_id}'
    )
