"""`blindgrasp-twin`: the gripper's physics twin on virtual serial ports.

    blindgrasp-twin --ports_json=outputs/twin/ports.json --trial_log=outputs/twin/trials.jsonl

It prints the two port paths and the operator socket, writes them to `--ports_json` (atomically, for scripts),
and serves until Ctrl-C / SIGTERM, printing its real-time status every `--status_every_s`. Point the real stack at
it as at a real gripper:

    --env.robot.port=<dynamixel_port> --env.robot.force_sensor.port=<force_port> --env.operator_socket=<socket>

`--env.robot.latency_timer_ms=60` is advisable on a shared machine (the emulators are Python threads).
"""

from __future__ import annotations

import json
import logging
import signal
import threading
from dataclasses import dataclass, field
from pathlib import Path

from lerobot_blindgrasp import durable
from lerobot_blindgrasp.cli import parse_config


@dataclass
class LoadCellConfig:
    """Each fingertip's load cell and ADC as the force board's emulator models them: counts = offset + gain x F /
    scale + noise. The host is configured with `scale_n_per_count`; `gain` is the cell's error against it."""

    scale_n_per_count: list[float] = field(default_factory=lambda: [2.5e-5, 2.5e-5, 2.5e-5])
    offset_counts: list[float] = field(default_factory=lambda: [81_000.0, -52_000.0, 12_000.0])
    # ADC noise (counts, 1 sigma): 300 counts = 7.5 mN at the default scale, an HX711's noise on a 1 mV/V cell. The sim's
    # 0.5 N is a training randomization, not a sensor: at 0.5 N the host's "below -1 N is a fault" check would
    # stop the gripper every few seconds.
    noise_counts: float = 300.0
    gain: float = 1.0
    rate_hz: float = 80.0  # the force board firmware's rate (one frame per fresh sample)


@dataclass
class TwinConfig:
    ports_json: Path | None = None  # where the port paths go (JSON), for scripts
    socket: str = "/tmp/blindgrasp-twin.sock"  # the operator socket (Unix domain)
    trial_log: str | None = None  # JSON lines: each trial's placement, physics draw and the twin's verdict
    baudrate: int = 1_000_000  # the servos' Baud_Rate register: the host must open the bus at this rate
    park_object: str = "cylinder_a_medium"  # on the table, off the workspace, until the first placement
    noise_seed: int = 0
    # The physics falling behind the clock by more than this skips ahead (counted in the status as behind_s).
    max_lag_s: float = 0.05
    status_every_s: float = 30.0  # 0: quiet
    load_cell: LoadCellConfig = field(default_factory=LoadCellConfig)


def serve(cfg: TwinConfig, stop: threading.Event) -> dict:
    """Run the twin until `stop` is set; returns its final status."""
    from lerobot_blindgrasp.twin.runner import Twin  # MuJoCo: only in the twin's process

    with Twin(cfg) as twin:
        ports = twin.ports()
        print(json.dumps(ports), flush=True)
        if cfg.ports_json is not None:
            durable.atomic_write_json(cfg.ports_json, ports, indent=2)
        print(
            f"blindgrasp-twin: Dynamixel bus {ports['dynamixel_port']}, force board {ports['force_port']}, "
            f"operator socket {ports['operator_socket']}. Ctrl-C stops.",
            flush=True,
        )
        while not stop.wait(cfg.status_every_s or None):
            print("twin status " + json.dumps(twin.status()), flush=True)
        status = twin.status()
    print("twin final status " + json.dumps(status), flush=True)
    return status


def main(argv: list[str] | None = None) -> None:
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(levelname)s %(message)s")
    cfg = parse_config(TwinConfig, argv)
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        signal.signal(sig, lambda *_: stop.set())
    serve(cfg, stop)


if __name__ == "__main__":
    main()
