"""The fingertip force board, emulated on a pseudo-terminal: `frame_codec` frames at `rate_hz` (80, the shipped
board's), one per fresh sample, with counts = offset + force / scale + noise saturating at 24 bits (a
saturated channel sets its STATUS bit, as the firmware does). Its faults, attributes below, are listed in
docs/hardware.md, "Emulators and tests"; the firmware itself runs in simavr (`force_board_simavr.py`).
"""

from __future__ import annotations

import random
import time

import numpy as np

from lerobot_blindgrasp.emulators.pty_device import PtyDevice
from lerobot_blindgrasp.hardware.force_board.frame_codec import encode_frame

ADC_FULL_SCALE = 1 << 23  # 24-bit signed counts (HX711-class ADC), sign-extended into the frame's int32


class ForceSensorEmulator(PtyDevice):
    tick_s = 0.005
    MAX_BURST = 8  # frames owed after a scheduling gap that still go out (100 ms at 80 Hz)

    def __init__(
        self,
        *,
        rate_hz: float = 80.0,
        scale_n_per_count=(2.5e-5, 2.5e-5, 2.5e-5),
        offset_counts=(81_000, -52_000, 12_000),
        noise_counts: float = 300.0,
        force_fn=None,
        seed: int = 0,
    ):
        super().__init__()
        self.period = 1.0 / rate_hz
        self.scale = np.asarray(scale_n_per_count, dtype=np.float64)
        self.offset = np.asarray(offset_counts, dtype=np.float64)
        self.noise = noise_counts
        self.forces_n = np.zeros(3)  # used when force_fn is None
        self.force_fn = force_fn  # () -> forces (N) per channel, e.g. a contact model on the servo emulator
        self.rng = random.Random(seed)
        self.seq = 0
        self._next = time.monotonic()
        # Fault injection.
        self.paused = False  # stream stalled (unplugged sensor, crashed firmware)
        self.drop_prob = 0.0  # probability to skip a frame (its sequence number is still consumed)
        self.garbage_prob = 0.0  # probability to emit 1-20 random bytes before a frame
        self.corrupt_next = 0  # send the next n frames with a wrong CRC
        self.status = 0  # channel fault bits
        # Channels per frame: firmware built for another number of load cells sends more or fewer.
        self.channels = 3
        # Dead data that still arrives: re-send the last frame bit for bit, step SEQ by this (-1: backwards), hold
        # these channels' counts at their last value (a hung ADC whose last conversion the firmware keeps sending).
        self.resend_last = False
        self.seq_step = 1
        self.frozen_channels: set[int] = set()
        self._last_frame = b""
        self._last_counts: list[int] = []
        self._boot_cause: int | None = None
        self._unsettled = 0
        self.sent = 0

    def reset(self, boot_s: float = 0.5, cause: int | None = 0x08, unsettled_frames: int = 0) -> None:
        """The board resets: silent for `boot_s`, then frames from SEQ 0, the first a boot frame with the MCUSR `cause`
        (None: no boot frame, as older firmware); the first `unsettled_frames` carry unloaded counts whatever the
        load, as a firmware that does not wait for its HX711s to settle would send."""
        self.seq = 0
        self._next = time.monotonic() + boot_s
        self._boot_cause, self._unsettled = cause, unsettled_frames

    def counts_for(self, forces) -> np.ndarray:
        return self.offset + np.asarray(forces, dtype=np.float64) / self.scale

    def _tick(self) -> None:
        # The board converts on its own clock, whatever the host does: when this thread was not scheduled for a
        # while, the frames it owes go out at once (as a real board's wait in the USB chip and the tty buffer), up
        # to MAX_BURST; beyond that they are lost. So a loaded test host does not turn into a slow board.
        now = time.monotonic()
        due = 0
        while now >= self._next and due < self.MAX_BURST:
            self._next += self.period
            due += 1
        if now >= self._next:
            self._next = now + self.period
        for _ in range(due):
            self._send_one()

    def _send_one(self) -> None:
        if self.paused:
            return
        if self.resend_last and self._last_frame:
            if self.write(self._last_frame):
                self.sent += 1
            return
        seq, self.seq = self.seq, (self.seq + self.seq_step) % 65536
        if self.drop_prob and self.rng.random() < self.drop_prob:
            return
        forces = self.force_fn() if self.force_fn is not None else self.forces_n
        if self._unsettled > 0:
            self._unsettled -= 1
            forces = np.zeros(3)
        counts = self.counts_for(forces) + np.array([self.rng.gauss(0.0, self.noise) for _ in range(3)])
        counts = np.clip(np.round(counts), -ADC_FULL_SCALE, ADC_FULL_SCALE - 1)  # a 24-bit ADC saturates
        saturated = sum(1 << c for c, v in enumerate(counts) if abs(v + 0.5) >= ADC_FULL_SCALE - 0.5)
        counts = (counts.astype(np.int64).tolist() + [0] * self.channels)[: self.channels]
        for c in self.frozen_channels:
            if c < len(self._last_counts):
                counts[c] = self._last_counts[c]
        self._last_counts = counts
        frame = encode_frame(seq, counts, self.status | saturated & ((1 << self.channels) - 1), self._boot_cause)
        self._boot_cause = None
        if self.corrupt_next > 0:
            self.corrupt_next -= 1
            frame = frame[:-1] + bytes([frame[-1] ^ 0xFF])
        if self.garbage_prob and self.rng.random() < self.garbage_prob:
            self.write(bytes(self.rng.randrange(256) for _ in range(self.rng.randrange(1, 21))))
        self._last_frame = frame
        if self.write(frame):
            self.sent += 1
