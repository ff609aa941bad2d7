"""`blindgrasp-calibrate-force`: weigh each fingertip with a known mass; save scale, offset and the verified wiring.

    blindgrasp-calibrate-force --robot.type=blindgrasp_gripper --robot.id=lab_gripper \
        --robot.force_sensor.port=/dev/ttyUSB1 --mass_kg=0.5

The same `--robot` flags as `lerobot-calibrate`, so the file lands next to that robot's servo calibration; only the
force board is opened (`lerobot-calibrate` only calls the servos' `calibrate()`).
"""

import logging
import sys
import time
from dataclasses import dataclass

import numpy as np
from lerobot.robots.config import RobotConfig
from lerobot.utils.constants import HF_LEROBOT_CALIBRATION, ROBOTS

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.cli import parse_config
from lerobot_blindgrasp.hardware.force_board import force_calibration as fc
from lerobot_blindgrasp.hardware.force_board.config_force_board import ForceSensorConfig
from lerobot_blindgrasp.hardware.force_board.reader import ForceSensorReader, ForceStreamError

logger = logging.getLogger(__name__)


@dataclass
class CalibrateForceConfig:
    # The gripper, as for lerobot-calibrate: --robot.type=blindgrasp_gripper --robot.id=... (the id names the file).
    robot: RobotConfig
    # The known mass put on each pad in turn (kg), e.g. a 500 g calibration weight. Use a mass in the range the
    # fingertips see in a grasp (a few newtons to ~20 N); it must stay within the cell's rating.
    mass_kg: float = 0.5
    # Local gravity (m/s^2); the standard value is within 0.3 percent of it anywhere on Earth.
    g: float = fc.STANDARD_GRAVITY
    # After each ENTER: wait for the pad to settle, then average this long.
    settle_s: float = 0.5
    window_s: float = 1.0
    # A channel responds when its mean moves by more than this many times its at-rest noise.
    min_snr: float = 20.0
    # Another channel moving by more than this fraction of the loaded one's response is crosstalk (refused).
    max_crosstalk: float = 0.1
    # After the weight is off, each cell must be back within this of its zero (N).
    max_zero_shift_n: float = 0.5


def _window(reader: ForceSensorReader, settle_s: float, window_s: float) -> fc.Window:
    """Counts of every stream channel over `window_s`, after `settle_s`; only fresh, fault-free frames."""
    time.sleep(settle_s)
    return fc.Window.of(reader.fresh_samples(window_s, "in this window", lambda frame: frame.counts))


def _prompts(cfg: CalibrateForceConfig) -> list[str]:
    grams = f"{cfg.mass_kg * 1000:g} g"
    out = ["Step 1/5: nothing may touch the three fingertip pads; keep the gripper still. Press ENTER: "]
    previous = ""
    for k, name in enumerate(spec.FORCE_SENSOR_NAMES):
        out.append(f"Step {k + 2}/5: {previous}put the {grams} weight on the {name} pad alone (centred, resting "
                   "freely, nothing else touching it). Press ENTER when it rests: ")  # fmt: skip
        previous = f"take the weight off {name} and "
    out.append(f"Step 5/5: {previous[:-5]}, leave all pads free. Press ENTER: ")
    return out


def calibrate_force(cfg: CalibrateForceConfig) -> fc.ForceCalibration:
    """Run the five steps on the robot's force board and save the result; returns it."""
    robot = cfg.robot
    if not isinstance(getattr(robot, "force_sensor", None), ForceSensorConfig):  # the gripper's config carries it
        raise SystemExit(f"error: --robot.type must be blindgrasp_gripper, not {robot.type}")
    if not robot.id:
        raise SystemExit("error: --robot.id is required: it names the gripper whose calibration this is")
    fs = robot.force_sensor
    calibration_dir = robot.calibration_dir or HF_LEROBOT_CALIBRATION / ROBOTS / "blindgrasp_gripper"
    reader = fs.reader([1.0] * spec.NUM_FORCES)  # raw counts: the scales are what this measures
    reader.connect()
    try:
        windows = []
        for k, prompt in enumerate(_prompts(cfg)):
            input(prompt)
            windows.append(_window(reader, cfg.settle_s, cfg.window_s))
            if 1 <= k <= spec.NUM_FORCES:
                delta = windows[-1].mean - windows[0].mean
                moved = ", ".join(f"ch {c} {d:+.0f}" for c, d in enumerate(delta))
                print(f"  counts moved: {moved}  (at-rest noise {np.round(windows[0].std).tolist()})")
                fc.check_response(k - 1, fs.channel_map, windows[0], windows[-1], cfg.min_snr, cfg.max_crosstalk)
    finally:
        reader.disconnect()
    cal = fc.fit(fs.channel_map, windows[0], windows[1:-1], windows[-1], cfg.mass_kg, cfg.g, min_snr=cfg.min_snr,
                 max_crosstalk=cfg.max_crosstalk, max_zero_shift_n=cfg.max_zero_shift_n)  # fmt: skip
    path = fc.save_force_calibration(cal, fc.path_for(calibration_dir, robot.id))
    for name, f in cal.fingers.items():
        print(f"{name}: channel {f.channel}, scale {f.scale_n_per_count:.5g} N/count, zero {f.offset_counts:.0f} "
              f"counts, at-rest noise {f.noise_n:.3f} N")  # fmt: skip
    print(f"Saved {path}. The robot '{robot.id}' uses it at connect (it replaces force_sensor.scale_n_per_count).")
    return cal


def main(argv: list[str] | None = None) -> None:
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    cfg = parse_config(CalibrateForceConfig, argv)
    try:
        calibrate_force(cfg)
    except (fc.ForceCalibrationError, ForceStreamError) as e:
        print(f"error: {e}", file=sys.stderr)
        raise SystemExit(1) from None


if __name__ == "__main__":
    main()
