"""A Dynamixel Protocol 2.0 bus of XM430-W350 servos, emulated on a pseudo-terminal.

What it implements (ROBOTIS e-Manual, "DYNAMIXEL Protocol 2.0" and the XM430-W350 control table):
- packets `FF FF FD 00 | ID | LEN_L LEN_H | INST | PARAMS | CRC_L CRC_H`, CRC-16 (poly 0x8005), byte stuffing;
- PING (unicast and broadcast), READ, WRITE, SYNC READ, SYNC WRITE, REBOOT; status packets (INST 0x55) with the
  error byte (instruction error codes 1..7 and the 0x80 hardware-alert bit);
- the control table with EEPROM write protection while torque is on, read-only registers, data range and limit
  checks, Status Return Level, and the bus baud rate (a servo answers only when the port's termios speed matches
  its Baud_Rate register, like a real bus at the wrong speed);
- Homing_Offset and Drive_Mode (reverse) as the firmware applies them: Present = sign * shaft + Homing_Offset;
- first-order servo dynamics (or any `ShaftDynamics` plugged in, e.g. the physics twin's MuJoCo joint): the shaft slews toward the goal at the no-load speed (46 rpm) or Profile_Velocity,
  Present_Current follows the position error times the P gain and saturates at Goal_Current/Current_Limit in
  current-based position mode; an optional rigid obstacle per servo (`obstacle`) stalls the shaft.

- the Bus Watchdog (98): with the torque on and 1..127 (x 20 ms) set, a servo that receives no instruction packet for
  that long stops where it is (torque stays on), reads -1 (255) there, and refuses goal writes with a data range
  error until 0 is written (e-Manual, "Bus Watchdog").

Fault injection (what the tests use): a missing ID, dropped status packets (timeouts), corrupted status CRCs,
wrong positions with a valid CRC (`position_glitch`), stray late status packets (`stray_replies`), slow replies
(`reply_delay_s`),
hardware-error status bits (the firmware then drops torque per the Shutdown register and raises the alert bit),
a servo reset (brown-out: RAM back to factory values, torque off, no error bit), from `PtyDevice`, an unplugged
USB adapter, and (`servo_health.py`, one model per servo and one `supply` per bus) a hot servo, a heating servo, a
weak or sagging supply and the firmware's overheating, voltage and overload errors.
"""

from __future__ import annotations

import math
import termios
import time
from dataclasses import dataclass, field
from typing import Protocol

from dynamixel_sdk import protocol2_packet_handler as p2
from dynamixel_sdk import robotis_def as dx

from lerobot_blindgrasp.hardware.emulators.pty_device import PtyDevice
from lerobot_blindgrasp.hardware.emulators.servo_health import ServoHealthModel, Supply

# name: (address, size, signed, writable-access) ; access "ro" | "eeprom" | "ram"
CONTROL_TABLE: dict[str, tuple[int, int, bool, str]] = {
    "Model_Number": (0, 2, False, "ro"),
    "Model_Information": (2, 4, False, "ro"),
    "Firmware_Version": (6, 1, False, "ro"),
    "ID": (7, 1, False, "eeprom"),
    "Baud_Rate": (8, 1, False, "eeprom"),
    "Return_Delay_Time": (9, 1, False, "eeprom"),
    "Drive_Mode": (10, 1, False, "eeprom"),
    "Operating_Mode": (11, 1, False, "eeprom"),
    "Secondary_ID": (12, 1, False, "eeprom"),
    "Protocol_Type": (13, 1, False, "eeprom"),
    "Homing_Offset": (20, 4, True, "eeprom"),
    "Moving_Threshold": (24, 4, False, "eeprom"),
    "Temperature_Limit": (31, 1, False, "eeprom"),
    "Max_Voltage_Limit": (32, 2, False, "eeprom"),
    "Min_Voltage_Limit": (34, 2, False, "eeprom"),
    "PWM_Limit": (36, 2, False, "eeprom"),
    "Current_Limit": (38, 2, False, "eeprom"),
    "Acceleration_Limit": (40, 4, False, "eeprom"),
    "Velocity_Limit": (44, 4, False, "eeprom"),
    "Max_Position_Limit": (48, 4, False, "eeprom"),
    "Min_Position_Limit": (52, 4, False, "eeprom"),
    "Shutdown": (63, 1, False, "eeprom"),
    "Torque_Enable": (64, 1, False, "ram"),
    "LED": (65, 1, False, "ram"),
    "Status_Return_Level": (68, 1, False, "ram"),
    "Registered_Instruction": (69, 1, False, "ro"),
    "Hardware_Error_Status": (70, 1, False, "ro"),
    "Velocity_I_Gain": (76, 2, False, "ram"),
    "Velocity_P_Gain": (78, 2, False, "ram"),
    "Position_D_Gain": (80, 2, False, "ram"),
    "Position_I_Gain": (82, 2, False, "ram"),
    "Position_P_Gain": (84, 2, False, "ram"),
    "Feedforward_2nd_Gain": (88, 2, False, "ram"),
    "Feedforward_1st_Gain": (90, 2, False, "ram"),
    "Bus_Watchdog": (98, 1, False, "ram"),
    "Goal_PWM": (100, 2, True, "ram"),
    "Goal_Current": (102, 2, True, "ram"),
    "Goal_Velocity": (104, 4, True, "ram"),
    "Profile_Acceleration": (108, 4, False, "ram"),
    "Profile_Velocity": (112, 4, False, "ram"),
    "Goal_Position": (116, 4, True, "ram"),
    "Realtime_Tick": (120, 2, False, "ro"),
    "Moving": (122, 1, False, "ro"),
    "Moving_Status": (123, 1, False, "ro"),
    "Present_PWM": (124, 2, True, "ro"),
    "Present_Current": (126, 2, True, "ro"),
    "Present_Velocity": (128, 4, True, "ro"),
    "Present_Position": (132, 4, True, "ro"),
    "Velocity_Trajectory": (136, 4, True, "ro"),
    "Position_Trajectory": (140, 4, True, "ro"),
    "Present_Input_Voltage": (144, 2, False, "ro"),
    "Present_Temperature": (146, 1, False, "ro"),
}
TABLE_SIZE = 147
XM430_W350_MODEL = 1020
BAUD_REGISTER = {9600: 0, 57600: 1, 115200: 2, 1_000_000: 3, 2_000_000: 4, 3_000_000: 5, 4_000_000: 6}
_TERMIOS_SPEED = {getattr(termios, f"B{b}"): b for b in BAUD_REGISTER if hasattr(termios, f"B{b}")}

# Hardware_Error_Status bits (e-Manual, XM430 "Hardware Error Status(70)").
HW_INPUT_VOLTAGE, HW_OVERHEATING, HW_ENCODER, HW_ELECTRICAL_SHOCK, HW_OVERLOAD = 0x01, 0x04, 0x08, 0x10, 0x20

NO_LOAD_SPEED_TICKS_S = 46.0 / 60.0 * 4096  # 46 rpm at 12 V
VELOCITY_UNIT_RPM = 0.229
SLEW_TAU_S = 0.03  # time constant of the emulated position loop

_DEFAULTS = {
    "Model_Number": XM430_W350_MODEL,
    "Firmware_Version": 46,
    "Baud_Rate": 3,
    "Return_Delay_Time": 250,
    "Operating_Mode": 3,
    "Secondary_ID": 255,
    "Protocol_Type": 2,
    "Moving_Threshold": 10,
    "Temperature_Limit": 80,
    "Max_Voltage_Limit": 160,
    "Min_Voltage_Limit": 95,
    "PWM_Limit": 885,
    "Current_Limit": 1193,
    "Acceleration_Limit": 32767,
    "Velocity_Limit": 200,
    "Max_Position_Limit": 4095,
    "Min_Position_Limit": 0,
    "Shutdown": 52,
    "Status_Return_Level": 2,
    "Velocity_I_Gain": 1920,
    "Velocity_P_Gain": 100,
    "Position_P_Gain": 800,
    "Goal_PWM": 885,
    "Goal_Current": 1193,
    "Present_Input_Voltage": 120,
    "Present_Temperature": 35,
}


def crc16(data: bytes | bytearray) -> int:
    """Protocol 2.0 CRC-16 (polynomial 0x8005, no reflection, init 0), bitwise."""
    crc = 0
    for byte in data:
        crc ^= byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x8005) if crc & 0x8000 else (crc << 1)
            crc &= 0xFFFF
    return crc


def _stuff(body: bytes) -> bytes:
    """Insert 0xFD after every FF FF FD inside INST..PARAMS (the header itself is not stuffed)."""
    out = bytearray()
    for b in body:
        out.append(b)
        if len(out) >= 3 and out[-3:] == b"\xff\xff\xfd":
            out.append(0xFD)
    return bytes(out)


def _unstuff(body: bytes) -> bytes:
    out = bytearray()
    i = 0
    while i < len(body):
        out.append(body[i])
        if len(out) >= 3 and out[-3:] == b"\xff\xff\xfd" and i + 1 < len(body) and body[i + 1] == 0xFD:
            i += 1  # drop the stuffing byte
        i += 1
    return bytes(out)


def make_packet(dxl_id: int, instruction: int, params: bytes = b"", *, bad_crc: bool = False) -> bytes:
    body = _stuff(bytes([instruction]) + bytes(params))
    length = len(body) + 2
    pkt = bytes([0xFF, 0xFF, 0xFD, 0x00, dxl_id, length & 0xFF, length >> 8]) + body
    crc = crc16(pkt) ^ (0x5A5A if bad_crc else 0)
    return pkt + bytes([crc & 0xFF, crc >> 8])


class ShaftDynamics(Protocol):
    """A shaft model plugged into `EmulatedServo.dynamics`: it reads the servo's registers (goal, torque, mode,
    limits) as it likes, and over `dt` sets `servo.shaft` (ticks, before Drive_Mode/Homing_Offset) and
    `servo.velocity` (shaft ticks/s); it returns Present_Current in register units, in the servo's own frame."""

    def advance(self, servo: EmulatedServo, dt: float) -> float: ...


@dataclass
class EmulatedServo:
    id: int
    shaft: float = 2048.0  # actual encoder position in ticks, before Drive_Mode and Homing_Offset
    regs: bytearray = field(default_factory=lambda: bytearray(TABLE_SIZE))
    velocity: float = 0.0  # ticks/s
    # A rigid obstacle, in shaft ticks, and the side it blocks from (+1: blocks motion above it).
    obstacle: tuple[float, int] | None = None
    last_instruction: float = 0.0  # monotonic time of the last instruction packet addressed to this servo
    watchdog_tripped_at: float | None = None  # when its bus watchdog last stopped it
    # What moves the shaft: None is the first-order model below; the physics twin plugs in MuJoCo
    # (`ShaftDynamics`). The registers, the protocol and the faults stay this emulator's either way.
    dynamics: ShaftDynamics | None = None
    # Temperature, input voltage and the firmware's shutdowns for them (`servo_health.py`); faults injected there.
    health: ServoHealthModel = field(default_factory=ServoHealthModel)

    def __post_init__(self) -> None:
        for name, value in _DEFAULTS.items():
            self.set(name, value)
        self.set("ID", self.id)
        self.set("Goal_Position", self.present_position())
        self.set("Present_Position", self.present_position())

    # -- registers --
    def get(self, name: str) -> int:
        addr, size, signed, _ = CONTROL_TABLE[name]
        return int.from_bytes(self.regs[addr : addr + size], "little", signed=signed)

    def set(self, name: str, value: int) -> None:
        addr, size, signed, _ = CONTROL_TABLE[name]
        self.regs[addr : addr + size] = int(value).to_bytes(size, "little", signed=signed)

    @property
    def direction(self) -> int:
        return -1 if self.get("Drive_Mode") & 0x01 else 1

    def present_position(self) -> int:
        return int(round(self.direction * self.shaft)) + self.get("Homing_Offset")

    def position_for(self, present: float) -> float:
        """Shaft ticks at which the servo reads `present`."""
        return self.direction * (present - self.get("Homing_Offset"))

    # -- dynamics --
    def check_watchdog(self, now: float) -> None:
        limit = self.get("Bus_Watchdog")
        if self.get("Torque_Enable") and 1 <= limit <= 127 and now - self.last_instruction > limit * 0.020:
            self.set("Bus_Watchdog", 255)
            self.set("Goal_Position", self.present_position())  # stops where it is, torque on
            self.watchdog_tripped_at = now

    def step(self, dt: float) -> None:
        current = self._first_order(dt) if self.dynamics is None else self.dynamics.advance(self, dt)
        self._publish(current)
        self.health.step(self, dt)

    def _publish(self, current: float) -> None:
        """Present_* registers from the shaft state, as the firmware reports them (Drive_Mode, Homing_Offset)."""
        self.set("Present_Current", int(current))
        rpm = self.velocity * self.direction / 4096 * 60.0
        self.set("Present_Velocity", int(rpm / VELOCITY_UNIT_RPM))
        self.set("Present_Position", self.present_position())
        self.set("Moving", int(abs(self.velocity) > 1.0))

    def _first_order(self, dt: float) -> float:
        """Slew the shaft toward the goal over dt; returns Present_Current (units, servo frame)."""
        mode = self.get("Operating_Mode")
        torque = self.get("Torque_Enable") == 1
        target = self.position_for(self.get("Goal_Position")) if torque and mode in (3, 4, 5) else self.shaft
        error = target - self.shaft
        vmax = NO_LOAD_SPEED_TICKS_S
        profile = self.get("Profile_Velocity")
        if profile > 0:
            vmax = min(vmax, profile * VELOCITY_UNIT_RPM / 60.0 * 4096)
        # Exact first-order response over dt (stable for any dt), capped at the slew rate.
        step = error * (1.0 - math.exp(-dt / SLEW_TAU_S)) if torque and dt > 0 else 0.0
        new = self.shaft + max(-vmax * dt, min(vmax * dt, step))
        if self.obstacle is not None:
            stop, side = self.obstacle
            if side > 0 and new > stop:
                new = max(self.shaft, stop) if self.shaft <= stop else self.shaft
            elif side < 0 and new < stop:
                new = min(self.shaft, stop) if self.shaft >= stop else self.shaft
        self.velocity = (new - self.shaft) / dt if dt > 0 else 0.0
        self.shaft = new
        # Current ~ P-gain x remaining error (the obstacle keeps the error, so the current saturates there).
        limit = self.get("Current_Limit")
        if mode == 5:
            limit = min(limit, abs(self.get("Goal_Current")))
        residual = (target - self.shaft) * self.direction
        return max(-limit, min(limit, residual * self.get("Position_P_Gain") / 128.0)) if torque else 0.0

    def reboot(self) -> None:
        """Power-cycle semantics: RAM back to defaults (torque off, errors cleared), EEPROM kept."""
        eeprom = bytes(self.regs[:64])
        self.regs = bytearray(TABLE_SIZE)
        for name, value in _DEFAULTS.items():
            if CONTROL_TABLE[name][0] >= 64:
                self.set(name, value)
        self.regs[:64] = eeprom
        self.set("Goal_Current", min(self.get("Goal_Current"), self.get("Current_Limit")))  # initialised within it
        self.set("Goal_Position", self.present_position())
        self.set("Present_Position", self.present_position())


class DynamixelBusEmulator(PtyDevice):
    """Nine (by default) XM430-W350 servos on one emulated bus. `port` is the path a client opens."""

    # Dynamics are also advanced on every packet, so the idle tick can be slow (keeps the GIL free for the client).
    tick_s = 0.01

    def __init__(self, ids, *, baudrate: int = 1_000_000, initial_shaft: dict[int, float] | None = None):
        super().__init__()
        self.servos: dict[int, EmulatedServo] = {}
        for i in ids:
            servo = EmulatedServo(i, shaft=(initial_shaft or {}).get(i, 2048.0))
            servo.set("Baud_Rate", BAUD_REGISTER[baudrate])
            servo.reboot()
            self.servos[i] = servo
        self.supply = Supply()  # one supply for the bus (`servo_health.py`): fault injection sags it
        for servo in self.servos.values():
            servo.health.supply = self.supply
        self._buf = bytearray()
        self._pending_ids: list[EmulatedServo] = []
        self._last = time.monotonic()
        # Fault injection.
        self.missing_ids: set[int] = set()
        self.drop_responses: dict[int, int] = {}  # id -> number of status packets to swallow (timeouts)
        self.corrupt_responses: dict[int, int] = {}  # id -> number of status packets sent with a bad CRC
        # Seconds between the replies of a sync-read burst (real servos answer in turn, each after its
        # Return_Delay_Time): long gaps leave the line empty for a while in the middle of a burst.
        self.reply_gap_s = 0.0
        # Every packet is answered this much later (a slow USB hub, a saturated adapter): the host loop slows down.
        self.reply_delay_s = 0.0
        # Wrong values with a valid CRC and no error bit: id -> [ticks added to Present_Position, replies left].
        self.position_glitch: dict[int, list[int]] = {}
        # Stray late status packets: (id, n data bytes) sent, with that servo's registers from Torque_Enable on,
        # right before the replies to the next sync read (a reply of an earlier transaction arriving late).
        self.stray_replies: list[tuple[int, int]] = []
        # Observability for tests.
        self.instruction_counts: dict[int, int] = {}
        self.rx_crc_errors = 0

    # -- fault injection --
    def set_hardware_error(self, dxl_id: int, bits: int) -> None:
        servo = self.servos[dxl_id]
        servo.set("Hardware_Error_Status", bits)
        if bits & servo.get("Shutdown"):
            servo.set("Torque_Enable", 0)

    def reset_servo(self, dxl_id: int) -> None:
        """A brown-out or watchdog reset of one servo's MCU: what `reboot` does, with no status packet and no error
        bit, so only the registers tell."""
        self.servos[dxl_id].reboot()

    def torque_enabled(self, dxl_id: int) -> bool:
        return self.servos[dxl_id].get("Torque_Enable") == 1

    def any_torque(self) -> bool:
        return any(s.get("Torque_Enable") for s in self.servos.values())

    # -- pty loop --
    def _tick(self) -> None:
        now = time.monotonic()
        dt, self._last = now - self._last, now
        if dt <= 0:
            dt = 0.0
        for servo in self.servos.values():
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
        if servo is None or dxl_id in self.missing_ids:
            return None
        baud = self._port_baudrate()
        if baud is not None and BAUD_REGISTER.get(baud) != servo.get("Baud_Rate"):
            return None
        return servo

    def _status(self, servo: EmulatedServo, error: int = 0, params: bytes = b"", *, force: bool = False) -> None:
        if servo.get("Hardware_Error_Status"):
            error |= p2.ERRBIT_ALERT
        if self.drop_responses.get(servo.id, 0) > 0:
            self.drop_responses[servo.id] -= 1
            return
        bad = self.corrupt_responses.get(servo.id, 0) > 0
        if bad:
            self.corrupt_responses[servo.id] -= 1
        self.write(make_packet(servo.id, dx.INST_STATUS, bytes([error]) + params, bad_crc=bad))

    def _handle(self, pkt: bytes) -> None:
        if self.reply_delay_s:
            time.sleep(self.reply_delay_s)
        self._tick()  # registers reflect the shaft at the moment the packet arrives (tests move shafts directly)
        self._handle_packet(pkt)
        for servo in self._pending_ids:
            self.servos = {s.get("ID"): s for s in self.servos.values()}
            servo.id = servo.get("ID")
        self._pending_ids.clear()

    def _handle_packet(self, pkt: bytes) -> None:
        dxl_id, inst = pkt[4], pkt[7]
        if crc16(pkt[:-2]) != (pkt[-2] | (pkt[-1] << 8)):
            self.rx_crc_errors += 1
            servo = self._alive(dxl_id)
            if servo is not None:
                self._status(servo, p2.ERRNUM_CRC)
            return
        params = _unstuff(pkt[8:-2])
        self.instruction_counts[inst] = self.instruction_counts.get(inst, 0) + 1
        broadcast = dxl_id == dx.BROADCAST_ID
        now = time.monotonic()
        for servo in self.servos.values():  # what feeds the bus watchdog: any valid instruction packet for it
            if broadcast or servo.id == dxl_id:
                servo.last_instruction = now
        if inst == dx.INST_PING:
            targets = sorted(self.servos) if broadcast else [dxl_id]
            for i in targets:
                servo = self._alive(i)
                if servo is not None:
                    model = servo.get("Model_Number")
                    self._status(servo, 0, bytes([model & 0xFF, model >> 8, servo.get("Firmware_Version")]))
        elif inst == dx.INST_READ and not broadcast:
            servo = self._alive(dxl_id)
            if servo is not None and servo.get("Status_Return_Level") >= 1:
                self._reply_read(servo, params[0] | params[1] << 8, params[2] | params[3] << 8)
        elif inst == dx.INST_WRITE:
            addr, data = params[0] | params[1] << 8, params[2:]
            targets = sorted(self.servos) if broadcast else [dxl_id]
            for i in targets:
                servo = self._alive(i)
                if servo is None:
                    continue
                error = self._write(servo, addr, data)
                if not broadcast and servo.get("Status_Return_Level") >= 2:
                    self._status(servo, error)
        elif inst == dx.INST_SYNC_READ and broadcast:
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
        elif inst == dx.INST_SYNC_WRITE and broadcast:
            addr, size = params[0] | params[1] << 8, params[2] | params[3] << 8
            body = params[4:]
            for k in range(0, len(body) - size, size + 1):
                servo = self._alive(body[k])
                if servo is not None:
                    self._write(servo, addr, body[k + 1 : k + 1 + size])
        elif inst == dx.INST_REBOOT and not broadcast:
            servo = self._alive(dxl_id)
            if servo is not None:
                self._status(servo, 0)
                servo.reboot()
        elif not broadcast:
            servo = self._alive(dxl_id)
            if servo is not None:
                self._status(servo, p2.ERRNUM_INSTRUCTION)

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
        self._status(servo, 0, bytes(data))

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
        error = self._check(servo, staged, [n for n, _ in touched])
        if error:
            return error
        for name, _ in touched:
            if name == "Torque_Enable" and staged.get(name) == 1 and servo.get("Hardware_Error_Status"):
                continue  # the firmware refuses torque until a reboot clears the error
            servo.set(name, staged.get(name))
            if name == "Torque_Enable" and staged.get(name) == 1:
                servo.velocity = 0.0
        if any(name == "ID" for name, _ in touched):
            self._pending_ids.append(servo)  # answers under the new ID from the next packet on
        return 0

    @staticmethod
    def _check(servo: EmulatedServo, staged: EmulatedServo, names: list[str]) -> int:
        for name in names:
            value = staged.get(name)
            if name == "Operating_Mode" and value not in (0, 1, 3, 4, 5, 16):
                return p2.ERRNUM_DATA_RANGE
            if name == "Torque_Enable" and value not in (0, 1):
                return p2.ERRNUM_DATA_RANGE
            if name == "Bus_Watchdog" and not 0 <= value <= 127:
                return p2.ERRNUM_DATA_RANGE
            if name.startswith("Goal_") and servo.get("Bus_Watchdog") == 255:
                return p2.ERRNUM_DATA_RANGE  # goal registers are read-only after a watchdog stop
            if name == "Current_Limit" and not 0 <= value <= 1193:
                return p2.ERRNUM_DATA_RANGE
            if name == "Goal_Current" and abs(value) > servo.get("Current_Limit"):
                return p2.ERRNUM_DATA_LIMIT
            if name in ("Min_Position_Limit", "Max_Position_Limit") and not 0 <= value <= 4095:
                return p2.ERRNUM_DATA_RANGE
            if name == "Homing_Offset" and abs(value) > 1_044_479:
                return p2.ERRNUM_DATA_RANGE
            if name == "Goal_Position" and servo.get("Operating_Mode") == 3:
                if not servo.get("Min_Position_Limit") <= value <= servo.get("Max_Position_Limit"):
                    return p2.ERRNUM_DATA_LIMIT
        return 0


def rad_to_shaft(q: float, zero: float = 2048.0, sign: int = 1) -> float:
    """Shaft ticks of a joint at angle q for a servo mounted with `zero` ticks at q = 0 and direction `sign`."""
    return zero + sign * q * 4096 / (2 * math.pi)
