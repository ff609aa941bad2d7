"""A 20 Hz control loop on the emulated gripper, run as a subprocess so that tests can deliver real signals to it.

    python -m emulators.robot_loop '<json: port, force_port, calibration_dir, scale, latency_timer_ms>'

It is shaped like LeRobot's scripts (connect, loop, `finally: disconnect`), prints READY once the torque is on,
and sweeps the proximal joints so that a servo that keeps moving after the process died would show.
"""

from __future__ import annotations

import json
import math
import sys
import time
from pathlib import Path

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.robots.blindgrasp_gripper import (
    BlindgraspGripper,
    BlindgraspGripperConfig,
    ForceSensorConfig,
)


def main(argv: list[str]) -> None:
    args = json.loads(argv[0])
    fs = ForceSensorConfig(port=args["force_port"], scale_n_per_count=args["scale"], tare_s=0.2)
    cfg = BlindgraspGripperConfig(id="rig", port=args["port"], calibration_dir=Path(args["calibration_dir"]),
                                  force_sensor=fs, latency_timer_ms=args["latency_timer_ms"])  # fmt: skip
    robot = BlindgraspGripper(cfg)
    robot.connect(calibrate=False)
    print("READY", flush=True)
    t0 = time.monotonic()
    try:
        while True:
            obs = robot.get_observation()
            phase = math.sin(2 * math.pi * 0.5 * (time.monotonic() - t0))
            target = {k: obs[k] for k in spec.ACTION_NAMES}
            for k in spec.ACTION_NAMES[1::3]:  # J*1: sweep +-0.6 rad around 0.5 rad
                target[k] = 0.5 + 0.6 * phase
            robot.send_action(target)
            time.sleep(spec.CONTROL_DT)
    finally:
        if robot.is_connected:
            robot.disconnect()


if __name__ == "__main__":
    main(sys.argv[1:])
