"""One real trial's start on the emulated gripper, run as a subprocess so that a test can kill the host while it
waits for the operator's ENTER (which never comes).

    python -m emulators.trial_wait '<json: port, force_port, calibration_dir, scale, latency_timer_ms, bus_watchdog_ms>'

It prints the env's own prompt ("place the object ...") once the gripper holds the start pose, tared, torque on.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from lerobot_blindgrasp.envs.operator import OperatorKeys
from lerobot_blindgrasp.envs.real_env import BlindGraspRealEnvConfig
from lerobot_blindgrasp.envs.real_trial import GripperSession, RealGraspEnv
from lerobot_blindgrasp.robots.blindgrasp_gripper import BlindgraspGripperConfig, ForceSensorConfig


class SilentKeyboard:
    """A keyboard nobody touches: LeRobot's listener shape, never dispatching a key."""

    def __init__(self, dispatch, controls_help=""):
        pass

    def stop(self):
        pass


def main(argv: list[str]) -> None:
    args = json.loads(argv[0])
    fs = ForceSensorConfig(port=args["force_port"], scale_n_per_count=args["scale"], tare_s=0.2)
    robot = BlindgraspGripperConfig(id="rig", port=args["port"], calibration_dir=Path(args["calibration_dir"]),
                                    force_sensor=fs, latency_timer_ms=args["latency_timer_ms"],
                                    bus_watchdog_ms=args["bus_watchdog_ms"])  # fmt: skip
    cfg = BlindGraspRealEnvConfig(robot=robot, task="sphere_medium")
    env = RealGraspEnv(GripperSession(cfg, OperatorKeys(SilentKeyboard)), "sphere_medium")
    try:
        env.reset()
    finally:
        env.close()


if __name__ == "__main__":
    main(sys.argv[1:])
