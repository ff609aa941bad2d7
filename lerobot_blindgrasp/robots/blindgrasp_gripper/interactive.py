"""The gripper's two interactive procedures, run by LeRobot's `lerobot-calibrate` and `lerobot-setup-motors`: the
only places the robot asks anything (connect never prompts when a calibration file exists)."""

from __future__ import annotations

import logging

from lerobot.motors.dynamixel import OperatingMode

from lerobot_blindgrasp.hardware.xm430 import MODEL

from . import servo_calibration as calib
from .servo_calibration import ticks_to_rad

logger = logging.getLogger(__name__)

REFERENCE_POSE_HELP = (
    "REFERENCE pose (q = 0 on all 9 joints): every finger hangs straight down from the plate, proximal and distal "
    "links in line, each finger in its own vertical plane through the claw axis (see robot_configs/README.md)."
)
POSITIVE_POSE_HELP = (
    "POSITIVE pose: from the reference pose, move EVERY joint by hand by at least ~10-15 degrees in its positive "
    "direction: J*0 turns the fingertip counter-clockwise seen from above; J*1 and J*2 swing the fingertip away "
    "from the claw axis (opening the claw)."
)


def calibrate_servos(robot) -> None:
    """Torque off: the calibration file to the servos when the operator keeps it, else `calibrate_by_hand`."""
    if robot.calibration:
        answer = input(
            f"Press ENTER to write the calibration file of '{robot.id}' to the servos, "
            "or type 'c' and press ENTER to calibrate again: "
        )
        if answer.strip().lower() != "c":
            robot.bus.write_calibration(robot.calibration)
            return
    calibrate_by_hand(robot)


def calibrate_by_hand(robot) -> None:
    """Two hand-held poses (torque off): Drive_Mode from the direction each joint moved, then Homing_Offset so that
    every servo reads 2048 at q = 0; written to the servos and to the calibration file."""
    bus = robot.bus
    for j in robot.joints:
        # Multi-turn mode so that readings never wrap at 0/4095 while the fingers are moved by hand.
        bus.write("Operating_Mode", j, OperatingMode.EXTENDED_POSITION.value)
        bus.write("Drive_Mode", j, 0)
        bus.write("Homing_Offset", j, 0)
    input(f"\nTorque is off. Hold the gripper in the {REFERENCE_POSE_HELP}\nPress ENTER when it is there: ")
    reference = bus.sync_read("Present_Position")
    input(f"\nNow the {POSITIVE_POSE_HELP}\nPress ENTER while holding it: ")
    positive = bus.sync_read("Present_Position")
    modes = calib.directions(reference, positive, robot.config.calibration_min_motion_rad)
    for j in robot.joints:
        bus.write("Drive_Mode", j, modes[j])
    present = bus.sync_read("Present_Position")
    homings = calib.homing_offsets(reference, positive, present)
    ids = {j: m.id for j, m in bus.motors.items()}
    robot.calibration = calib.build(ids, modes, homings, robot.lower, robot.upper)
    bus.write_calibration(robot.calibration)
    robot._save_calibration()
    check = bus.sync_read("Present_Position")
    print("\nCalibrated joint angles in the positive pose (all should be > 0):")
    for j in robot.joints:
        print(f"  {j:7s} id {ids[j]:2d}  drive_mode {modes[j]}  q = {ticks_to_rad(check[j]):+.3f} rad")
    logger.info("Calibration saved to %s", robot.calibration_fpath)


def setup_motors(robot) -> None:
    """`lerobot-setup-motors`: give factory-fresh servos (ID 1, 57 600 bps) their D'Claw ID and the bus baud rate,
    one servo on the cable at a time, through LeRobot's `setup_motor`. Baud rates are tried factory rate first:
    a broadcast ping waits its full window at each rate (4 s at 9600 bps, LeRobot's first guess)."""
    bus = robot.bus
    bus.use_latency_timer()
    bus.default_baudrate = robot.config.baudrate  # the rate setup_motor writes into each servo
    rates = list(dict.fromkeys([57_600, robot.config.baudrate, *bus.model_baudrate_table[MODEL]]))
    try:
        for j in reversed(robot.joints):
            input(
                f"Connect the controller board to the '{j}' servo (ID {bus.motors[j].id}) only, then press ENTER: "
            )
            for k, rate in enumerate(rates):
                try:
                    bus.setup_motor(j, initial_baudrate=rate)
                    break
                except RuntimeError:
                    if k == len(rates) - 1:
                        raise
            print(f"'{j}' servo: ID {bus.motors[j].id} at {robot.config.baudrate} bps")
    finally:
        if bus.is_connected:
            bus.disconnect(disable_torque=False)
