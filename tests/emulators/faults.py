"""The emulators with the faults and bring-up steps only tests inject, on top of the package's emulators (which the
physics twin runs without them). docs/hardware.md, "Emulators and tests", lists every fault.
"""

from __future__ import annotations

import time

import numpy as np

from lerobot_blindgrasp.emulators.control_table import BAUD_REGISTER
from lerobot_blindgrasp.emulators.dynamixel import DynamixelBusEmulator, EmulatedServo
from lerobot_blindgrasp.emulators.force_board import ForceSensorEmulator
from lerobot_blindgrasp.hardware.force_board.frame_codec import encode_frame


class FaultyBus(DynamixelBusEmulator):
    """The servo bus emulator with the faults and bring-up steps only tests inject."""

    def set_hardware_error(self, dxl_id: int, bits: int) -> None:
        servo = self.servos[dxl_id]
        servo.set("Hardware_Error_Status", bits)
        if bits & servo.get("Shutdown"):
            servo.set("Torque_Enable", 0)

    def reset_servo(self, dxl_id: int) -> None:
        """A brown-out or watchdog reset of one servo's MCU: what `reboot` does, with no status packet and no error
        bit, so only the registers tell."""
        self.servos[dxl_id].reboot()

    def add_twin(self, dxl_id: int, shaft: float = 2048.0) -> EmulatedServo:
        """A tenth servo on the bus, set to an ID already in use (set up twice, or swapped in with its factory ID
        changed to the one it replaces): both hear every instruction and both answer, over each other."""
        twin = EmulatedServo(dxl_id, shaft=shaft)
        twin.set("Baud_Rate", self.servos[dxl_id].get("Baud_Rate"))
        twin.reboot()
        twin.health.supply = self.supply
        self.twins[dxl_id] = twin
        return twin

    @staticmethod
    def factory_servo(shaft: float = 2048.0) -> EmulatedServo:
        """A servo as it leaves ROBOTIS (e-Manual, factory values): ID 1, Baud_Rate 1 = 57 600 bps."""
        servo = EmulatedServo(1, shaft=shaft)
        servo.set("Baud_Rate", BAUD_REGISTER[57_600])
        servo.reboot()
        return servo

    def plug(self, *servos: EmulatedServo) -> None:
        """The cable now carries exactly `servos` (each answers at its own ID and baud rate), as when the operator
        unplugs one servo and plugs in the next; an ID a servo is given over the bus takes effect as on the wire."""
        self.servos = {s.get("ID"): s for s in servos}
        for servo in servos:
            servo.id = servo.get("ID")
            servo.health.supply = self.supply


class FaultyForceBoard(ForceSensorEmulator):
    def __init__(self, **kwargs):
        super().__init__(**kwargs)
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

    def reset(self, boot_s: float = 0.5, cause: int | None = 0x08, unsettled_frames: int = 0) -> None:
        """The board resets: silent for `boot_s`, then frames from SEQ 0, the first a boot frame with the MCUSR `cause`
        (None: no boot frame, as older firmware); the first `unsettled_frames` carry unloaded counts whatever the
        load, as a firmware that does not wait for its HX711s to settle would send."""
        self.seq = 0
        self._next = time.monotonic() + boot_s
        self._boot_cause, self._unsettled = cause, unsettled_frames

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
        counts, saturated = self._convert(forces)
        counts = (counts + [0] * self.channels)[: self.channels]
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
