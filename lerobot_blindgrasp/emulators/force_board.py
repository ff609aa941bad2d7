"""The fingertip force board, emulated on a pseudo-terminal: `frame_codec` frames at `rate_hz` (80, the shipped
board's), one per fresh sample, with counts = offset + force / scale + noise saturating at 24 bits (a
saturated channel sets its STATUS bit, as the firmware does). The faults only tests inject are
`tests/emulators/faults.py`'s; the firmware itself runs in simavr (`force_board_simavr.py`).
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
        self.paused = False  # stream stalled (unplugged sensor, crashed firmware)
        self.sent = 0

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
        seq, self.seq = self.seq, (self.seq + 1) % 65536
        counts, saturated = self._convert(self.force_fn() if self.force_fn is not None else self.forces_n)
        if self.write(encode_frame(seq, counts, saturated)):
            self.sent += 1

    def _convert(self, forces) -> tuple[list[int], int]:
        """One conversion of the three cells: (counts with the ADC's noise, saturating at 24 bits; the STATUS bits
        of the saturated channels)."""
        counts = self.counts_for(forces) + np.array([self.rng.gauss(0.0, self.noise) for _ in range(3)])
        counts = np.clip(np.round(counts), -ADC_FULL_SCALE, ADC_FULL_SCALE - 1)
        saturated = sum(1 << c for c, v in enumerate(counts) if abs(v + 0.5) >= ADC_FULL_SCALE - 0.5)
        return counts.astype(np.int64).tolist(), saturated
