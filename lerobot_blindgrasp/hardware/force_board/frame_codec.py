"""The force board's frames (docs/force_board.md, "Frame protocol"): the encoder (for the emulators and tests) and the
host's incremental decoder, which resynchronises on the next SYNC after any bad length or CRC, so garbage on the
line costs frames, never wrong values.

    SYNC a5 5a | LEN u8 | SEQ u16 | COUNTS i32 x N | STATUS u8 | RESET u8 (boot frame only) | CRC-16/CCITT-FALSE u16
"""

from __future__ import annotations

import binascii
import struct
from dataclasses import dataclass, field

SYNC = b"\xa5\x5a"
MAX_CHANNELS = 8
RESET_CAUSES = ("power-on", "reset pin", "brown-out", "watchdog")  # MCUSR bits 0..3 (PORF, EXTRF, BORF, WDRF)


def crc16_ccitt_false(data: bytes) -> int:
    return binascii.crc_hqx(data, 0xFFFF)


def encode_frame(seq: int, counts, status: int = 0, reset_cause: int | None = None) -> bytes:
    """One frame as the firmware sends it; with `reset_cause`, the boot frame."""
    n = len(counts)
    boot = reset_cause is not None
    body = struct.pack(f"<BH{n}iB", 2 + 4 * n + 1 + boot, seq & 0xFFFF, *[int(c) for c in counts], status)
    if boot:
        body += bytes([reset_cause & 0xFF])
    return SYNC + body + struct.pack("<H", crc16_ccitt_false(body))


def reset_cause_text(cause: int | None) -> str:
    """The MCUSR bits a boot frame carries, in words ("" for an ordinary frame)."""
    if cause is None:
        return ""
    names = [name for bit, name in enumerate(RESET_CAUSES) if cause >> bit & 1]
    return " + ".join(names) or f"unknown (MCUSR {cause:#04x})"


@dataclass(frozen=True)
class Frame:
    seq: int
    counts: tuple[int, ...]
    status: int
    reset_cause: int | None = None  # set on the boot frame only


@dataclass
class FrameParser:
    """Incremental decoder: feed bytes, get whole valid frames; counts what it had to throw away."""

    buffer: bytearray = field(default_factory=bytearray)
    crc_errors: int = 0
    bad_lengths: int = 0
    garbage_bytes: int = 0

    def wanted(self) -> int:
        """Bytes that would complete the frame at the head of the buffer (the header first when it is not in yet):
        what a read may wait for without ever waiting past a frame's end."""
        if len(self.buffer) < 3 or self.buffer[:2] != SYNC:
            return max(1, 3 - len(self.buffer))
        return max(1, 3 + self.buffer[2] + 2 - len(self.buffer))

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
            n, extra = divmod(length - 3, 4)
            if extra > 1 or not 1 <= n <= MAX_CHANNELS:
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
            _, seq, *rest = struct.unpack_from(f"<BH{n}iB", body)
            cause = body[-1] if extra else None
            frames.append(Frame(seq=seq, counts=tuple(rest[:n]), status=rest[n], reset_cause=cause))
            del self.buffer[:total]
