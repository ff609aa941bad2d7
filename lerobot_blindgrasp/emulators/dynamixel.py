"""A Dynamixel Protocol 2.0 bus of XM430-W350 servos, emulated on a pseudo-terminal (ROBOTIS e-Manual). A servo
answers only when the port's termios speed matches its Baud_Rate, as on a real bus. What it speaks, and the faults
the tests inject (`tests/emulators/faults.py`): docs/hardware.md, "Emulators and tests".
"""

from __future__ import annotations

import termios
import time

from dynamixel_sdk import protocol2_packet_handler as p2
from dynamixel_sdk import robotis_def as dx

from lerobot_blindgrasp.emulators.control_table import BAUD_REGISTER, CONTROL_TABLE, TABLE_SIZE, write_error
from lerobot_blindgrasp.emulators.dynamixel_servo import EmulatedServo
from lerobot_blindgrasp.emulators.dynamixel_wire import crc_ok, make_packet, unstuff
from lerobot_blindgrasp.emulators.pty_device import PtyDevice
from lerobot_blindgrasp.emulators.servo_health import Supply

_TERMIOS_SPEED = {getattr(termios, f"B{b}"): b for b in BAUD_REGISTER if hasattr(termios, f"B{b}")}


class DynamixelBusEmulator(PtyDevice):
    """Nine (by default) XM430-W350 servos on one emulated bus. `port` is the path a client opens."""

    # Dynamics are also advanced on every packet, so the idle tick can be slow (keeps the GIL free for the client).
    tick_s = 0.01

    def __init__(self, ids, *, baudrate: int = 1_000_000, initial_shaft: dict[int, float] | None = None):
        super().__init__()
        self.supply = Supply()  # one supply for the bus (`servo_health.py`): fault injection sags it
        self.servos: dict[int, EmulatedServo] = {}
        for i in ids:
            servo = EmulatedServo(i, shaft=(initial_shaft or {}).get(i, 2048.0))
            servo.set("Baud_Rate", BAUD_REGISTER[baudrate])
            servo.reboot()
            servo.health.supply = self.supply
            self.servos[i] = servo
        self._buf = bytearray()
        self._pending_ids: list[EmulatedServo] = []
        self._last = time.monotonic()

    def any_torque(self) -> bool:
        return any(s.get("Torque_Enable") for s in self.servos.values())

    def _on_the_line(self) -> list[EmulatedServo]:
        """Every servo on the cable, each stepped and fed by the bus (the tests' `FaultyBus` adds more)."""
        return list(self.servos.values())

    # -- pty loop --
    def _tick(self) -> None:
        now = time.monotonic()
        dt, self._last = max(now - self._last, 0.0), now
        for servo in self._on_the_line():
            servo.step(dt)
            servo.check_watchdog(now)

    def _port_baudrate(self) -> int | None:
        try:
            return _TERMIOS_SPEED.get(termios.tcgetattr(self._slave_fd)[4])
        except termios.error:
            return None

    def _on_bytes(self, data: bytes) -> None:
        self._buf += data
        while True:
            start = self._buf.find(b"\xff\xff\xfd\x00")
            if start < 0:
                del self._buf[: max(0, len(self._buf) - 3)]
                return
            del self._buf[:start]
            if len(self._buf) < 7:
                return
            length = self._buf[5] | (self._buf[6] << 8)
            total = 7 + length
            if len(self._buf) < total:
                return
            pkt = bytes(self._buf[:total])
            del self._buf[:total]
            self._handle(pkt)

    # -- protocol --
    def _alive(self, dxl_id: int) -> EmulatedServo | None:
        servo = self.servos.get(dxl_id)
        if servo is None:
            return None
        baud = self._port_baudrate()
        if baud is not None and BAUD_REGISTER.get(baud) != servo.get("Baud_Rate"):
            return None
        return servo

    def _status(self, servo: EmulatedServo, error: int = 0, params: bytes = b"") -> None:
        alert = p2.ERRBIT_ALERT if servo.get("Hardware_Error_Status") else 0
        self.write(make_packet(servo.id, dx.INST_STATUS, bytes([error | alert]) + params))

    def _handle(self, pkt: bytes) -> None:
        self._tick()  # registers reflect the shaft at the moment the packet arrives (tests move shafts directly)
        self._handle_packet(pkt)
        for servo in self._pending_ids:
            self.servos = {s.get("ID"): s for s in self.servos.values()}
            servo.id = servo.get("ID")
        self._pending_ids.clear()

    def _handle_packet(self, pkt: bytes) -> None:
        dxl_id, inst = pkt[4], pkt[7]
        if not crc_ok(pkt):
            servo = self._alive(dxl_id)
            if servo is not None:
                self._status(servo, p2.ERRNUM_CRC)
            return
        params = unstuff(pkt[8:-2])
        broadcast = dxl_id == dx.BROADCAST_ID
        now = time.monotonic()
        for servo in self._on_the_line():  # what feeds the bus watchdog
            if broadcast or servo.id == dxl_id:
                servo.last_instruction = now
        handler = self._HANDLERS.get((inst, broadcast))
        if handler is not None:
            getattr(self, handler)(dxl_id, params)
        elif not broadcast and (servo := self._alive(dxl_id)) is not None:
            self._status(servo, p2.ERRNUM_INSTRUCTION)

    def _ping(self, dxl_id: int, params: bytes) -> None:
        for i in sorted(self.servos) if dxl_id == dx.BROADCAST_ID else [dxl_id]:
            servo = self._alive(i)
            if servo is not None:  # PING answers at every Status_Return_Level
                model = servo.get("Model_Number")
                self._status(servo, 0, bytes([model & 0xFF, model >> 8, servo.get("Firmware_Version")]))

    def _read(self, dxl_id: int, params: bytes) -> None:
        servo = self._alive(dxl_id)
        if servo is not None and servo.get("Status_Return_Level") >= 1:
            self._reply_read(servo, params[0] | params[1] << 8, params[2] | params[3] << 8)

    def _write_inst(self, dxl_id: int, params: bytes) -> None:
        addr, data = params[0] | params[1] << 8, params[2:]
        broadcast = dxl_id == dx.BROADCAST_ID
        for i in sorted(self.servos) if broadcast else [dxl_id]:
            servo = self._alive(i)
            if servo is None:
                continue
            error = self._write(servo, addr, data)
            if not broadcast and servo.get("Status_Return_Level") >= 2:
                self._status(servo, error)

    def _sync_read(self, dxl_id: int, params: bytes) -> None:
        addr, size = params[0] | params[1] << 8, params[2] | params[3] << 8
        for i in params[4:]:
            servo = self._alive(i)
            if servo is not None:
                self._reply_read(servo, addr, size)

    def _sync_write(self, dxl_id: int, params: bytes) -> None:
        addr, size = params[0] | params[1] << 8, params[2] | params[3] << 8
        body = params[4:]
        for k in range(0, len(body) - size, size + 1):
            servo = self._alive(body[k])
            if servo is not None:
                self._write(servo, addr, body[k + 1 : k + 1 + size])

    def _reboot(self, dxl_id: int, params: bytes) -> None:
        servo = self._alive(dxl_id)
        if servo is not None:
            self._status(servo, 0)
            servo.reboot()

    _HANDLERS = {  # (instruction, broadcast) -> method, by name so that a subclass's override handles it
        (dx.INST_PING, False): "_ping",
        (dx.INST_PING, True): "_ping",
        (dx.INST_READ, False): "_read",
        (dx.INST_WRITE, False): "_write_inst",
        (dx.INST_WRITE, True): "_write_inst",
        (dx.INST_SYNC_READ, True): "_sync_read",
        (dx.INST_SYNC_WRITE, True): "_sync_write",
        (dx.INST_REBOOT, False): "_reboot",
    }

    def _reply_read(self, servo: EmulatedServo, addr: int, size: int) -> None:
        if addr + size > TABLE_SIZE:
            self._status(servo, p2.ERRNUM_ACCESS)
            return
        self._status(servo, 0, bytes(servo.regs[addr : addr + size]))

    def _write(self, servo: EmulatedServo, addr: int, data: bytes) -> int:
        """Apply a write like the firmware does; returns the status error code (0 = ok, nothing written else)."""
        end = addr + len(data)
        if not data or end > TABLE_SIZE:
            return p2.ERRNUM_ACCESS
        touched = [(n, spec) for n, spec in CONTROL_TABLE.items() if spec[0] < end and addr < spec[0] + spec[1]]
        if not touched:
            return p2.ERRNUM_ACCESS
        for _name, (a, size, _, access) in touched:
            if access == "ro" or a < addr or a + size > end:
                return p2.ERRNUM_ACCESS  # read-only, or a partial register write
            if access == "eeprom" and servo.get("Torque_Enable"):
                return p2.ERRNUM_ACCESS  # EEPROM is locked while torque is on
        staged = EmulatedServo.__new__(EmulatedServo)
        staged.regs = bytearray(servo.regs)
        staged.regs[addr:end] = data
        error = write_error(servo, staged, [n for n, _ in touched])
        if error:
            return error
        for name, _ in touched:
            if name == "Torque_Enable" and staged.get(name) == 1 and servo.get("Hardware_Error_Status"):
                continue  # the firmware refuses torque until a reboot clears the error
            if name in servo.unwritable:
                continue
            servo.set(name, staged.get(name))
            if name == "Torque_Enable" and staged.get(name) == 1:
                servo.velocity = 0.0
        if any(name == "ID" for name, _ in touched):
            self._pending_ids.append(servo)  # answers under the new ID from the next packet on
        return 0
