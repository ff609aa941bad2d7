"""`blindgrasp-twin-calibrate`: run the real `lerobot-calibrate` against a running twin, playing its operator.

    blindgrasp-twin-calibrate --ports_json=outputs/twin/ports.json --robot_id=twin \\
        --calibration_dir=outputs/twin/calibration

lerobot-calibrate asks for the REFERENCE pose (q = 0) and a POSITIVE pose by hand, torque off. Here the hand is
the twin's (`hold_by_hand` over the operator socket): at each prompt the twin's joints are held in that pose
(`positive_q` on every joint), then ENTER is pressed. The twin's mounting is not told to the host: Drive_Mode and
Homing_Offset come out of the calibration itself, as on a freshly assembled gripper.
"""

from __future__ import annotations

import json
import socket
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.cli import parse_config

BIN = Path(sys.executable).parent


def request(socket_path: str, msg: dict, timeout_s: float = 10.0) -> dict:
    """One request to the twin's operator socket (`twin/operator_server.py`), its reply."""
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
        s.settimeout(timeout_s)
        s.connect(socket_path)
        with s.makefile("rb") as lines:
            lines.readline()  # the hello
            s.sendall((json.dumps(msg) + "\n").encode())
            return json.loads(lines.readline())


@dataclass
class TwinCalibrateConfig:
    ports_json: Path  # what blindgrasp-twin wrote
    robot_id: str = "twin"
    calibration_dir: Path | None = None  # None: LeRobot's default (HF_LEROBOT_CALIBRATION)
    positive_q: float = 0.3  # rad on every joint in the positive pose
    latency_timer_ms: int = 60
    timeout_s: float = 120.0


def calibrate_command(cfg: TwinCalibrateConfig, ports: dict) -> list[str]:
    cmd = [
        str(BIN / "lerobot-calibrate"),
        "--robot.type=blindgrasp_gripper",
        f"--robot.id={cfg.robot_id}",
        f"--robot.port={ports['dynamixel_port']}",
        f"--robot.force_sensor.port={ports['force_port']}",
        f"--robot.latency_timer_ms={cfg.latency_timer_ms}",
    ]
    if cfg.calibration_dir is not None:
        cmd.append(f"--robot.calibration_dir={cfg.calibration_dir}")
    return cmd


def run(cfg: TwinCalibrateConfig) -> int:
    ports = json.loads(cfg.ports_json.read_text())
    sock = ports["operator_socket"]
    proc = subprocess.Popen(
        calibrate_command(cfg, ports),
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        bufsize=1,
    )
    deadline = time.monotonic() + cfg.timeout_s
    buf = ""
    try:
        while proc.poll() is None and time.monotonic() < deadline:
            ch = proc.stdout.read(1)
            if not ch:
                break
            sys.stdout.write(ch)
            buf += ch
            if not (buf.endswith(": ") and "ENTER" in buf):  # a prompt, complete
                continue
            if "calibrate again" in buf:
                proc.stdin.write("c\n")
            elif "REFERENCE" in buf:
                request(sock, {"op": "hand", "q": [0.0] * spec.NUM_JOINTS})
                time.sleep(0.3)
                proc.stdin.write("\n")
            elif "POSITIVE" in buf:
                request(sock, {"op": "hand", "q": [cfg.positive_q] * spec.NUM_JOINTS})
                time.sleep(0.3)
                proc.stdin.write("\n")
            else:
                continue
            proc.stdin.flush()
            buf = ""
        sys.stdout.write(proc.stdout.read() or "")
        return proc.wait(timeout=max(1.0, deadline - time.monotonic()))
    finally:
        if proc.poll() is None:
            proc.kill()
        request(sock, {"op": "hand", "q": None})  # let go: the fingers hang free again


def main(argv: list[str] | None = None) -> None:
    sys.exit(run(parse_config(TwinCalibrateConfig, argv)))


if __name__ == "__main__":
    main()
