"""The emulators with the faults and bring-up steps only tests inject, on top of the package's emulators (which the
physics twin runs without them). docs/hardware.md, "Emulators and tests", lists every fault.
"""

from __future__ import annotations

import time

import numpy as np
from dynamixel_sdk import protocol2_packet_handler as p2
from dynamixel_sdk import robotis_def as dx

from lerobot_blindgrasp.emulators.control_table import BAUD_REGISTER, CONTROL_TABLE, TABLE_SIZE
from lerobot_blindgrasp.emulators.dynamixel import DynamixelBusEmulator, EmulatedServo
from lerobot_blindgrasp.emulators.dynamixel_wire import crc_ok, make_packet
from lerobot_blindgrasp.emulators.force_board import ForceSensorEmulator
from lerobot_blindgrasp.hardware.force_board.frame_codec import encode_frame


def collide(*packets: bytes) -> bytes:
    """What the line carries when several servos answer at once (two servos on one ID): their drivers fight, and
    the line reads low wherever any of them pulls it low (a bitwise AND, as on an open-drain bus). Identical replies
    survive intact; different ones fail their CRC."""
    out = bytearray(max(len(p) for p in packets))
    for i in range(len(out)):
        byte = 0xFF
        for p in packets:
            byte &= p[i] if i < len(p) else 0xFF
        out[i] = byte
    return bytes(out)


class FaultyBus(DynamixelBusEmulator):
    def __init__(self, ids, **kwargs):
        super().__init__(ids, **kwargs)
        self.twins: dict[int, EmulatedServo] = {}  # a second servo set to the same ID (`add_twin`): both answer
        self.missing_ids: set[int] = set()
        self.drop_responses: dict[int, int] = {}  # id -> number of status packets to swallow (timeouts)
        self.corrupt_responses: dict[int, int] = {}  # id -> number of status packets sent with a bad CRC
        self.reply_gap_s = 0.0  # between the replies of a sync-read burst: the line empty mid-burst
        self.reply_delay_s = 0.0  # before every reply (a slow USB hub): the host loop slows down
        # Wrong values with a valid CRC and no error bit: id -> [ticks added to Present_Position, replies left].
        self.position_glitch: dict[int, list[int]] = {}
        # Late replies of an earlier transaction: (id, n data bytes from Torque_Enable on), sent before the next sync
        # read's replies.
        self.stray_replies: list[tuple[int, int]] = []
        self.instruction_counts: dict[int, int] = {}
        self._twin_params: bytes | None = None  # what the twin reads back, for the read being answered

    def torque_enabled(self, dxl_id: int) -> bool:
        return self.servos[dxl_id].get("Torque_Enable") == 1

    def _on_the_line(self) -> list[EmulatedServo]:
        return [*self.servos.values(), *self.twins.values()]

    def _alive(self, dxl_id: int) -> EmulatedServo | None:
        return None if dxl_id in self.missing_ids else super()._alive(dxl_id)

    def _handle(self, pkt: bytes) -> None:
        if self.reply_delay_s:
            time.sleep(self.reply_delay_s)
        super()._handle(pkt)

    def _handle_packet(self, pkt: bytes) -> None:
        if crc_ok(pkt):
            self.instruction_counts[pkt[7]] = self.instruction_counts.get(pkt[7], 0) + 1
        super()._handle_packet(pkt)

    def _status(self, servo: EmulatedServo, error: int = 0, params: bytes = b"") -> None:
        if self.drop_responses.get(servo.id, 0) > 0:
            self.drop_responses[servo.id] -= 1
            return
        bad = self.corrupt_responses.get(servo.id, 0) > 0
        if bad:
            self.corrupt_responses[servo.id] -= 1
        alert = p2.ERRBIT_ALERT if servo.get("Hardware_Error_Status") else 0
        packet = make_packet(servo.id, dx.INST_STATUS, bytes([error | alert]) + params, bad_crc=bad)
        twin = self.twins.get(servo.id)
        if twin is not None:  # the twin answers at the same moment: the two replies collide on the line
            twin_error = p2.ERRBIT_ALERT if twin.get("Hardware_Error_Status") else 0
            twin_body = params if self._twin_params is None else self._twin_params
            packet = collide(packet, make_packet(servo.id, dx.INST_STATUS, bytes([twin_error]) + twin_body))
        self.write(packet)

    def _sync_read(self, dxl_id: int, params: bytes) -> None:
        addr, size = params[0] | params[1] << 8, params[2] | params[3] << 8
        while self.stray_replies:
            i, n = self.stray_replies.pop(0)
            regs = self.servos[i].regs
            self.write(make_packet(i, dx.INST_STATUS, bytes([0]) + bytes(regs[64 : 64 + n])))
        for k, i in enumerate(params[4:]):
            servo = self._alive(i)
            if servo is not None:
                if k and self.reply_gap_s:
                    time.sleep(self.reply_gap_s)
                self._reply_read(servo, addr, size)

    def _reply_read(self, servo: EmulatedServo, addr: int, size: int) -> None:
        if addr + size > TABLE_SIZE:
            self._status(servo, p2.ERRNUM_ACCESS)
            return
        data = bytearray(servo.regs[addr : addr + size])
        pos = CONTROL_TABLE["Present_Position"][0]
        glitch = self.position_glitch.get(servo.id)
        if glitch and glitch[1] > 0 and addr <= pos and pos + 4 <= addr + size:
            glitch[1] -= 1
            value = (servo.get("Present_Position") + glitch[0]) & 0xFFFFFFFF
            data[pos - addr : pos - addr + 4] = value.to_bytes(4, "little")
        twin = self.twins.get(servo.id)
        self._twin_params = None if twin is None else bytes(twin.regs[addr : addr + size])
        try:
            self._status(servo, 0, bytes(data))
        finally:
            self._twin_params = None

    def _write(self, servo: EmulatedServo, addr: int, data: bytes) -> int:
        twin = self.twins.get(servo.id)
        if twin is not None and twin is not servo:  # the twin hears every write too
            super()._write(twin, addr, data)
        return super()._write(servo, addr, data)

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
