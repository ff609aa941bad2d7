"""What connect() decides before it opens a port: whether a missing calibration may be made now, and the control
thread's scheduling and memory (`prepare_host`).

LeRobot's robots calibrate interactively inside `connect()` when no calibration file exists (koch_follower does).
That is right for `lerobot-teleoperate` or `lerobot-record` at a terminal, where the operator reads the prompt.
It is wrong when nobody can answer: `lerobot-eval` under nohup, a job scheduler or a pipe. There `input()` either
fails with EOFError in the middle of the calibration, torque off and a traceback, or waits for ever. The usual
cause is a `--robot.id` other than the one calibrated, so the refusal names the file it looked for and the ids
that are calibrated.
"""

from __future__ import annotations

import builtins
import sys
from pathlib import Path

from lerobot_blindgrasp.hardware import realtime
from lerobot_blindgrasp.hardware.force_board import force_calibration

from .calibration import CalibrationFileError

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


def refuse_unattended_calibration(robot) -> None:
    """Raise a CalibrationFileError if `robot` has no calibration file and no operator could calibrate it now."""
    if robot.calibration or operator_can_answer():
        return
    known = calibrated_ids(robot.calibration_dir)
    hint = (f" Calibrated ids in {robot.calibration_dir}: {', '.join(known)}; pass the one of this gripper as "
            "--robot.id (lerobot-eval: --env.robot.id).") if known else ""  # fmt: skip
    raise CalibrationFileError(
        f"No calibration file for robot id '{robot.id}' ({robot.calibration_fpath}), and no operator at this "
        f"terminal to calibrate it now (stdin is not a terminal). Nothing was moved.{hint} To calibrate, run "
        f'lerobot-calibrate --robot="include robot_configs/blindgrasp_gripper.yaml" --robot.id={robot.id}'
    )


def prepare_host(robot) -> dict[str, str]:
    """`realtime_priority` and `lock_memory` of the robot's config (`hardware/realtime.py`), applied to the calling
    thread: call it before the robot starts a thread, since threads inherit the scheduling of the one that starts
    them. Returns what the kernel granted."""
    return realtime.prepare_host(robot.config)
