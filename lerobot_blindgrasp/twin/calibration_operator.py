"""`blindgrasp-twin-calibrate`: run the real calibration commands against a running twin, playing their operator.

    blindgrasp-twin-calibrate --ports_json=outputs/twin/ports.json --robot_id=twin \\
        --calibration_dir=outputs/twin/calibration

The twin's hand holds `lerobot-calibrate`'s poses, and `blindgrasp-calibrate-force` (unless `--force=false`) gets
`mass_kg` on the pad each prompt names, so both calibrations are measured, not copied from the twin.
"""

from __future__ import annotations

import json
import socket
import subprocess
import sys
import time
from collections.abc import Callable
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
    force: bool = True  # also weigh the fingertips (blindgrasp-calibrate-force)
    mass_kg: float = 0.5  # the weight the twin rests on each pad
    latency_timer_ms: int = 16  # the robot's default
    timeout_s: float = 120.0  # per command


def robot_flags(cfg: TwinCalibrateConfig, ports: dict) -> list[str]:
    flags = [
        "--robot.type=blindgrasp_gripper",
        f"--robot.id={cfg.robot_id}",
        f"--robot.port={ports['dynamixel_port']}",
        f"--robot.force_sensor.port={ports['force_port']}",
        f"--robot.latency_timer_ms={cfg.latency_timer_ms}",
    ]
    if cfg.calibration_dir is not None:
        flags.append(f"--robot.calibration_dir={cfg.calibration_dir}")
    return flags


def servo_answers(sock: str, positive_q: float) -> Callable[[str], str | None]:
    """lerobot-calibrate's prompts: the twin's hand holds each pose, then ENTER."""

    def answer(prompt: str) -> str | None:
        if "calibrate again" in prompt:
            return "c"
        for word, q in (("REFERENCE", 0.0), ("POSITIVE", positive_q)):
            if word in prompt:
                request(sock, {"op": "hand", "q": [q] * spec.NUM_JOINTS})
                time.sleep(0.3)
                return ""
        return None

    return answer


def force_answers(sock: str, mass_kg: float) -> Callable[[str], str | None]:
    """blindgrasp-calibrate-force's five prompts: the weight goes on the pad the prompt names, or comes off."""

    def answer(prompt: str) -> str | None:
        if "Step" not in prompt:
            return None
        named = [k for k, n in enumerate(spec.FORCE_SENSOR_NAMES) if f"on the {n} pad" in prompt]
        request(sock, {"op": "weight", "tip": named[0] if named else None, "mass_kg": mass_kg})
        return ""

    return answer


def play(cmd: list[str], answer: Callable[[str], str | None], timeout_s: float) -> int:
    """Run `cmd`, echoing its output; each complete prompt (ends with ': ' and asks for ENTER) goes to `answer`,
    whose text (None: not a prompt it knows) is typed in."""
    proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True, bufsize=1)  # fmt: skip
    deadline = time.monotonic() + timeout_s
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
            typed = answer(buf)
            if typed is None:
                continue
            proc.stdin.write(typed + "\n")
            proc.stdin.flush()
            buf = ""
        sys.stdout.write(proc.stdout.read() or "")
        return proc.wait(timeout=max(1.0, deadline - time.monotonic()))
    finally:
        if proc.poll() is None:
            proc.kill()


def calibrate_twin(cfg: TwinCalibrateConfig) -> int:
    ports = json.loads(cfg.ports_json.read_text())
    sock = ports["operator_socket"]
    flags = robot_flags(cfg, ports)
    try:
        rc = play([str(BIN / "lerobot-calibrate"), *flags], servo_answers(sock, cfg.positive_q), cfg.timeout_s)
    finally:
        request(sock, {"op": "hand", "q": None})  # let go: the fingers hang free again
    if rc != 0 or not cfg.force:
        return rc
    cmd = [str(BIN / "blindgrasp-calibrate-force"), *flags, f"--mass_kg={cfg.mass_kg}"]
    try:
        return play(cmd, force_answers(sock, cfg.mass_kg), cfg.timeout_s)
    finally:
        request(sock, {"op": "weight", "tip": None})


def main(argv: list[str] | None = None) -> None:
    sys.exit(calibrate_twin(parse_config(TwinCalibrateConfig, argv)))


if __name__ == "__main__":
    main()
