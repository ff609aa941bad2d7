"""Fingertip force sensors: a microcontroller streams raw load-cell counts over a serial port.

Wire protocol (microcontroller -> host only, little-endian; full description in `docs/hardware.md`):

    offset size  field
    0      2     SYNC    0xA5 0x5A
    2      1     LEN     bytes from SEQ to STATUS = 2 + 4 * N + 1 (15 for N = 3 channels)
    3      2     SEQ     uint16 frame counter, +1 per frame, wraps at 65535
    5      4*N   COUNTS  int32 raw ADC counts per channel (24-bit ADCs sign-extended), ff, mf, th order
    5+4N   1     STATUS  bit i set: channel i not ready or saturated
    6+4N   2     CRC     CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, no reflection) over LEN..STATUS

CRC-16/CCITT-FALSE of b"123456789" is 0x29B1 (check value for firmware authors). The host resynchronises on the
next SYNC after any bad length or CRC, so garbage bytes on the line cost frames, never wrong values. SEQ gaps count
dropped frames; the age of the newest good frame detects a stalled or unplugged stream.

Host side: counts -> newtons with a tare (mean counts over `tare_s` at connect, fingers in free air) and a
per-channel scale in N/count from the robot config, then the sensor pipeline the sim uses too
(`lerobot_blindgrasp.force.reading`: the measured newtons already hold the sensor's noise; |f| < 0.1 N reads 0).
"""

from __future__ import annotations

import binascii
import struct
import time
from dataclasses import dataclass, field

import numpy as np

from lerobot_blindgrasp import force, spec
from lerobot_blindgrasp.streams import LatestFrameStream, StreamError

SYNC = b"\xa5\x5a"
MAX_CHANNELS = 8


def crc16_ccitt_false(data: bytes) -> int:
    return binascii.crc_hqx(data, 0xFFFF)


def encode_frame(seq: int, counts, status: int = 0) -> bytes:
    """One frame as the firmware sends it (used by the emulator and by firmware tests)."""
    n = len(counts)
    body = struct.pack(f"<BH{n}iB", 2 + 4 * n + 1, seq & 0xFFFF, *[int(c) for c in counts], status)
    return SYNC + body + struct.pack("<H", crc16_ccitt_false(body))


@dataclass(frozen=True)
class Frame:
    seq: int
    counts: tuple[int, ...]
    status: int


@dataclass
class FrameParser:
    """Incremental decoder: feed bytes, get whole valid frames; counts what it had to throw away."""

    buffer: bytearray = field(default_factory=bytearray)
    crc_errors: int = 0
    bad_lengths: int = 0
    garbage_bytes: int = 0

    def feed(self, data: bytes) -> list[Frame]:
        self.buffer += data
        frames = []
        while True:
            start = self.buffer.find(SYNC)
            if start < 0:
                keep = 1 if self.buffer[-1:] == SYNC[:1] else 0
                self.garbage_bytes += len(self.buffer) - keep
                del self.buffer[: len(self.buffer) - keep]
                return frames
            self.garbage_bytes += start
            del self.buffer[:start]
            if len(self.buffer) < 3:
                return frames
            length = self.buffer[2]
            n = (length - 3) // 4
            if (length - 3) % 4 or not 1 <= n <= MAX_CHANNELS:
                self.bad_lengths += 1
                del self.buffer[:1]  # not a frame start; look for the next SYNC
                continue
            total = 3 + length + 2
            if len(self.buffer) < total:
                return frames
            body = bytes(self.buffer[2 : 3 + length])
            (crc,) = struct.unpack_from("<H", self.buffer, 3 + length)
            if crc != crc16_ccitt_false(body):
                self.crc_errors += 1
                del self.buffer[:1]
                continue
            _, seq, *rest = struct.unpack(f"<BH{n}iB", body)
            frames.append(Frame(seq=seq, counts=tuple(rest[:n]), status=rest[n]))
            del self.buffer[:total]


class ForceStreamError(StreamError):
    """No fresh valid frame, or the microcontroller flags a channel fault."""


class ForceSensorReader(LatestFrameStream[Frame]):
    """The serial stream (newest frame kept by `LatestFrameStream`'s thread); `read()` returns tared, scaled,
    deadbanded forces in N."""

    name = "Force-sensor"
    error_type = ForceStreamError
    lost_hint = "USB cable unplugged?"

    def __init__(
        self,
        port: str,
        baudrate: int,
        scale_n_per_count,
        *,
        channel_map=(0, 1, 2),
        stale_timeout_s: float = 0.15,
        connect_timeout_s: float = 1.0,
    ):
        super().__init__(port, stale_timeout_s)
        self.port = port
        self.baudrate = baudrate
        self.scale = np.asarray(scale_n_per_count, dtype=np.float64)
        self.channel_map = list(channel_map)
        self.connect_timeout_s = connect_timeout_s
        self.offset = np.zeros(len(self.channel_map))
        self.parser = FrameParser()
        self.dropped_frames = 0
        self._serial = None

    @property
    def is_connected(self) -> bool:
        return self._serial is not None

    def connect(self) -> None:
        self.start()
        if not self.wait_frames(1, self.connect_timeout_s):
            self.disconnect()
            raise ForceStreamError(
                f"No valid force-sensor frame on '{self.port}' within {self.connect_timeout_s:.1f} s "
                f"({self.parser.garbage_bytes} garbage bytes, {self.parser.crc_errors} CRC errors): "
                "check the cable, the baud rate and the firmware."
            )

    def disconnect(self) -> None:
        self.stop()

    def _open(self) -> None:
        import serial  # pyserial comes with lerobot[dynamixel]

        try:
            self._serial = serial.Serial(self.port, self.baudrate, timeout=0.02)
        except (OSError, serial.SerialException) as e:
            raise ForceStreamError(f"Could not open the force-sensor port '{self.port}': {e}") from e
        self._serial.reset_input_buffer()

    def _receive(self) -> list[Frame]:
        data = self._serial.read(256)
        return self.parser.feed(data) if data else []

    def _close(self) -> None:
        if self._serial is not None:
            try:
                self._serial.close()
            finally:
                self._serial = None

    def _keep(self, frame: Frame, now: float) -> bool:
        if self._latest is not None:  # SEQ gaps are frames lost on the way (or dropped by the firmware)
            self.dropped_frames += (frame.seq - self._latest.seq - 1) % 65536
        return True

    def _stale_detail(self) -> str:
        return f"; {self.dropped_frames} frames dropped so far"

    def _channels(self, frame: Frame) -> np.ndarray:
        if max(self.channel_map) >= len(frame.counts):
            raise ForceStreamError(
                f"Force-sensor frames carry {len(frame.counts)} channels, but force_sensor.channel_map "
                f"{self.channel_map} needs channel {max(self.channel_map)}: the firmware and the config disagree."
            )
        return np.array([frame.counts[c] for c in self.channel_map], dtype=np.float64)

    def tare(self, duration_s: float, min_frames: int = 5) -> np.ndarray:
        """Zero the sensors: mean counts over `duration_s`, with no fingertip touching anything."""
        samples = []
        deadline = time.monotonic() + duration_s
        while time.monotonic() < deadline or len(samples) < min_frames:
            if not self.wait_frames(1, self.stale_timeout_s * 4):
                raise ForceStreamError(f"Force-sensor stream stopped during tare ({len(samples)} frames).")
            frame, _ = self.latest()
            if frame.status:
                raise ForceStreamError(f"Force sensor channel fault during tare (status {frame.status}).")
            samples.append(self._channels(frame))
        self.offset = np.mean(samples, axis=0)
        return self.offset

    def read(self) -> np.ndarray:
        frame = self.fresh()
        counts = self._channels(frame)
        if frame.status:
            bad = [spec.FORCE_SENSOR_NAMES[i] for i, c in enumerate(self.channel_map) if frame.status >> c & 1]
            raise ForceStreamError(f"Force sensor reports a fault on {bad} (status {frame.status:#04x}).")
        return force.reading(force.counts_to_newtons(counts, self.offset, self.scale))
