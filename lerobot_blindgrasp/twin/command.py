"""`blindgrasp-twin`: the gripper's physics twin on virtual serial ports.

    blindgrasp-twin --ports_json=outputs/twin/ports.json --trial_log=outputs/twin/trials.jsonl

It prints the two port paths and the operator socket, writes them to `--ports_json`, and serves until Ctrl-C or
SIGTERM. Point the real stack at it as at a real gripper (`--env.robot.latency_timer_ms=60` on a shared machine:
the emulators are Python threads):

    --env.robot.port=<dynamixel_port> --env.robot.force_sensor.port=<force_port> --env.operator_socket=<socket>
"""

from __future__ import annotations

import json
import logging
import signal
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

from lerobot_blindgrasp import compat, durable
from lerobot_blindgrasp.cli import parse_config

# A 10 kg (98 N), 1 mV/V cell on an HX711 at gain 128 with 5 V excitation (docs/force_board.md, "Load cell range"):
# 98.0665 N give 5 mV, and the ADC's +-19.53 mV input spans +-2^23 counts.
CELL_SCALE_N_PER_COUNT = 9.80665 * 10 / (5.0 * 2**23 / 19.53)


@dataclass
class LoadCellConfig:
    """Each fingertip's load cell and ADC as the force board's emulator models them: counts = offset + gain x F /
    scale + noise. `scale_n_per_count` is the datasheet scale (what ports.json publishes); `gain` is each cell's
    own error against it (typically +-10 %), which only `blindgrasp-calibrate-force` finds."""

    scale_n_per_count: list[float] = field(default_factory=lambda: [CELL_SCALE_N_PER_COUNT] * 3)
    offset_counts: list[float] = field(default_factory=lambda: [81_000.0, -52_000.0, 12_000.0])
    # ADC noise (counts, 1 sigma): 300 counts = 14 mN, an HX711's on a 1 mV/V cell (the sim's 0.5 N is a training
    # randomization: the host's "below -1 N is a fault" check would stop the gripper every few seconds).
    noise_counts: float = 300.0
    gain: list[float] = field(default_factory=lambda: [1.0, 1.0, 1.0])
    rate_hz: float = 80.0  # the force board firmware's rate (one frame per fresh sample)

    def __post_init__(self):
        for name in ("scale_n_per_count", "offset_counts", "gain"):
            if len(getattr(self, name)) != 3:
                raise ValueError(f"load_cell.{name} needs one value per fingertip (3)")
        if not all(g > 0 for g in self.gain) or not all(s != 0 for s in self.scale_n_per_count):
            raise ValueError("load_cell.gain must be > 0 and scale_n_per_count non-zero")

    def true_scale(self) -> list[float]:
        """N per count of each cell as built (what the emulator converts with)."""
        return [s / g for s, g in zip(self.scale_n_per_count, self.gain, strict=True)]


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
    # > 0: the servo bus, force board and physics threads run SCHED_FIFO at this priority (root or CAP_SYS_NICE),
    # as the gripper's own processors answer within microseconds: on a loaded machine a Python thread may miss the
    # host's reply window, and the real stack stops on a timeout no gripper would cause.
    realtime_priority: int = 0
    load_cell: LoadCellConfig = field(default_factory=LoadCellConfig)


def serve_twin(cfg: TwinConfig, stop: threading.Event) -> dict:
    """Run the twin until `stop` is set; returns its final status."""
    from lerobot_blindgrasp.twin.runner import Twin  # MuJoCo: only in the twin's process

    with Twin(cfg) as twin:
        ports = twin.ports()
        if cfg.ports_json is not None:  # before the printed line: whoever reads that line finds the file too
            durable.atomic_write_json(cfg.ports_json, ports, indent=2)
        print(json.dumps(ports), flush=True)
        print(
            f"blindgrasp-twin: Dynamixel bus {ports['dynamixel_port']}, force board {ports['force_port']}, "
            f"operator socket {ports['operator_socket']}. Ctrl-C stops.",
            flush=True,
        )
        # Short waits: a signal's Python handler runs only when the main thread runs; an endless wait never does.
        last = time.monotonic()
        while not stop.wait(0.5):
            if cfg.status_every_s and time.monotonic() - last >= cfg.status_every_s:
                last = time.monotonic()
                print("twin status " + json.dumps(twin.status()), flush=True)
        status = twin.status()
    print("twin final status " + json.dumps(status), flush=True)
    return status


def main(argv: list[str] | None = None) -> None:
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(levelname)s %(message)s")
    cfg = parse_config(TwinConfig, argv)
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        compat.set_signal_handler(sig, lambda *_: stop.set())
    serve_twin(cfg, stop)


if __name__ == "__main__":
    main()
