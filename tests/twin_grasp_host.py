"""A host that grasps on the twin: connects to the twin's ports, closes the claw on the object and keeps squeezing
at 20 Hz, printing READY once two fingertips are loaded, and `STOPPED <error>` when the robot's safety latch stops
it (tests/test_twin_faults.py injects the faults, or kills it).

    python tests/twin_grasp_host.py '<json: dynamixel_port, force_port, calibration_dir>'
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.robots.blindgrasp_gripper import (
    BlindgraspGripper,
    BlindgraspGripperConfig,
    ForceSensorConfig,
)

# Reply timeout = 2 x this + 2 ms: the twin shares a loaded CI machine's CPU with the host (tests only).
LATENCY_TIMER_MS = 150
# Proximal joints well past the contact with a 4 cm sphere at the claw centre (about -0.2 rad): the servos squeeze.
CLOSE = dict(zip(spec.ACTION_NAMES, [0.0, -0.45, 0.0] * 3, strict=True))


def robot_config(ports: dict, calibration_dir: Path) -> BlindgraspGripperConfig:
    return BlindgraspGripperConfig(
        id="twin",
        port=ports["dynamixel_port"],
        calibration_dir=Path(calibration_dir),
        latency_timer_ms=LATENCY_TIMER_MS,
        max_overrun_s=0,
        force_sensor=ForceSensorConfig(port=ports["force_port"], tare_s=0.2),
    )


def main(args: dict) -> None:
    robot = BlindgraspGripper(robot_config(args, args["calibration_dir"]))
    robot.connect()
    ready = False
    try:
        while True:
            obs = robot.get_observation()
            robot.send_action(CLOSE)
            if not ready and sum(obs[f"{s}.force"] > 1.0 for s in spec.FORCE_SENSOR_NAMES) >= 2:
                print("READY", flush=True)
                ready = True
            time.sleep(spec.CONTROL_DT)
    except Exception as e:  # the robot's safety latch: the torque is already off
        print(f"STOPPED {type(e).__name__}: {e}", flush=True)
        sys.exit(1)
    finally:
        if robot.is_connected:
            robot.disconnect()


if __name__ == "__main__":
    main(json.loads(sys.argv[1]))
