"""The force board in simavr on a pseudo-terminal that the real reader opens like the board's USB serial port: the
firmware's HEX image runs unchanged on an emulated ATmega328P with three emulated HX711s (`simavr/hx711_sim.c`),
which enforce the HX711's timing and report violations in `log`. Both are built on first use into `build_dir`.
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from lerobot_blindgrasp.hardware.force_board.build import build_firmware, build_simulator

START_TIMEOUT_S = 10.0  # for the harness's first line (its pty), after the builds


class SimulatedForceBoard:
    def __init__(
        self,
        *,
        scale_n_per_count=(2.5e-5, 2.5e-5, 2.5e-5),
        offset_counts=(81_000, -52_000, 12_000),
        noise_counts: int = 200,
        sps: float = 80.0,
        build_dir=None,
        defines: tuple[str, ...] = (),
    ):
        self.scale = np.asarray(scale_n_per_count, dtype=np.float64)
        self.offset = np.asarray(offset_counts, dtype=np.float64)
        self.noise_counts = int(noise_counts)
        self.sps = sps
        self._tmp = None if build_dir else tempfile.TemporaryDirectory(prefix="force-board-")
        self.build_dir = Path(build_dir or self._tmp.name)
        self.defines = tuple(defines)  # a test build of the firmware (build.build_firmware), into its own folder
        self.port = ""
        self.log = ""  # the harness's report (stderr) once stopped
        self._proc: subprocess.Popen | None = None
        self._lock = threading.Lock()

    def start(self) -> SimulatedForceBoard:
        firmware_dir = self.build_dir / "-".join(self.defines) if self.defines else self.build_dir
        hex_path = build_firmware(firmware_dir, defines=self.defines)
        exe = build_simulator(self.build_dir)
        self._proc = subprocess.Popen(
            [str(exe), str(hex_path), str(self.sps)],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        )  # fmt: skip
        line = self._first_line()
        if not line.startswith("pty "):
            err = self._proc.stderr.read() if self._proc.poll() is not None else ""
            self.stop()
            raise RuntimeError(f"the simavr force board did not start: {line!r} {err}")
        self.port = line.split(maxsplit=1)[1].strip()
        self.send(f"noise {self.noise_counts}")
        self.set_forces(np.zeros(3))
        return self

    def _first_line(self) -> str:
        out: list[str] = []
        reader = threading.Thread(target=lambda: out.append(self._proc.stdout.readline()), daemon=True)
        reader.start()
        reader.join(START_TIMEOUT_S)
        return out[0] if out else ""

    def send(self, line: str) -> None:
        """One command to the harness (`simavr/hx711_sim.c`'s `command`): also the faults `dead`, `stuck` (DOUT held
        low), `hang` and `alive` of one chip, by index, and `reset` (the ATmega's reset pin)."""
        with self._lock:
            if self._proc is None or self._proc.poll() is not None:
                raise RuntimeError("the simavr force board is not running")
            self._proc.stdin.write(line + "\n")
            self._proc.stdin.flush()

    def counts_for(self, forces_n) -> np.ndarray:
        return self.offset + np.asarray(forces_n, dtype=np.float64) / self.scale

    def set_counts(self, counts) -> None:
        """The raw counts each cell's bridge produces (channel A, gain 128), before the chip's noise."""
        self.send("counts " + " ".join(str(int(round(c))) for c in counts))

    def set_forces(self, forces_n) -> None:
        self.set_counts(self.counts_for(forces_n))

    def stop(self) -> None:
        proc, self._proc = self._proc, None
        if proc is not None:
            try:
                proc.stdin.write("quit\n")
                proc.stdin.flush()
                _, self.log = proc.communicate(timeout=5)
            except (OSError, ValueError, subprocess.TimeoutExpired):
                proc.kill()
                _, self.log = proc.communicate()
        if self._tmp is not None:
            self._tmp.cleanup()
            self._tmp = None

    def __enter__(self) -> SimulatedForceBoard:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()


@dataclass
class SimConfig:
    # Run the firmware in simavr for this long and report what the real reader received (frames/s, forces).
    seconds: float = 5.0
    # Conversion rate of the emulated HX711s: 80 (RATE high) or 10 (RATE low).
    sps: float = 80.0
    # Force on each pad while it runs (N), ff, mf, th.
    forces_n: list[float] = field(default_factory=lambda: [1.0, 2.0, 3.0])
    # Where the firmware and the harness are built (the build command's --out_dir; reused when up to date).
    build_dir: Path = Path("build/force_board")


def _newest_frame_ages_ms(reader, seconds: float) -> list[float]:
    """The newest frame's age at reads spread over every phase of the board's period, for `seconds`: what a control
    loop reading at its own times sees (half a period on average when frames are handed on as they arrive)."""
    ages, k, deadline = [], 0, time.monotonic() + seconds
    while time.monotonic() < deadline:
        time.sleep(0.003 + 0.0013 * (k % 7))
        ages.append(reader.latest()[1] * 1e3)
        k += 1
    return ages


def _report(reader, board: SimulatedForceBoard, cfg: SimConfig) -> None:
    """Rate and latency first (they need no tare), then forces in newtons; raises the reader's error when it
    refuses the stream (a slow board cannot be tared)."""
    time.sleep(0.3)
    frames0, t1 = reader.frames, time.monotonic()
    ages_ms = _newest_frame_ages_ms(reader, cfg.seconds)
    rate = (reader.frames - frames0) / (time.monotonic() - t1)
    print(
        f"port {board.port}: {rate:.1f} frames/s, {reader.dropped_frames} dropped, "
        f"{reader.parser.crc_errors} CRC errors, stream rate estimate {reader.rate_hz():.0f}/s"
    )
    print(f"newest frame's age when read: mean {np.mean(ages_ms):.1f} ms, max {np.max(ages_ms):.1f} ms "
          f"({len(ages_ms)} reads)")  # fmt: skip
    reader.tare(0.5)
    board.set_forces(cfg.forces_n)
    reader.wait_frames(4, 1.0)  # past any conversion made before the change (read() says if none came)
    print(f"forces given {cfg.forces_n} N, read {np.round(reader.read(), 3).tolist()} N")


def main(argv: list[str] | None = None) -> None:
    """`python -m lerobot_blindgrasp.emulators.force_board_simavr`: the board without hardware, read by the gripper's
    force reader with its config's defaults. Exits 1 when the reader refuses the stream (e.g. `--sps=10`)."""
    from lerobot_blindgrasp.cli import parse_config
    from lerobot_blindgrasp.hardware.force_board.config_force_board import ForceSensorConfig
    from lerobot_blindgrasp.hardware.force_board.reader import ForceStreamError

    cfg = parse_config(SimConfig, argv)
    refused = None
    with SimulatedForceBoard(sps=cfg.sps, build_dir=cfg.build_dir) as board:
        reader = ForceSensorConfig(port=board.port).reader(board.scale.tolist())
        reader.connect()
        try:
            _report(reader, board, cfg)
        except ForceStreamError as e:
            refused = e
        finally:
            reader.disconnect()
    print(board.log.strip())
    if refused is not None:
        sys.exit(f"the robot's reader refuses this stream: {refused}")


if __name__ == "__main__":
    main()
