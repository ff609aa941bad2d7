"""One emulated XM430-W350: its registers (`control_table.py`), how the firmware applies Drive_Mode and
Homing_Offset (Present = sign * shaft + Homing_Offset), first-order shaft dynamics (or any `ShaftDynamics`
plugged in, e.g. the physics twin's MuJoCo joint), the Bus Watchdog and a reboot."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Protocol

from lerobot_blindgrasp.emulators.control_table import (
    CONTROL_TABLE,
    DEFAULTS,
    EEPROM_END,
    STARTUP_TORQUE_ON,
    TABLE_SIZE,
)
from lerobot_blindgrasp.emulators.servo_health import ServoHealthModel

NO_LOAD_SPEED_TICKS_S = 46.0 / 60.0 * 4096  # 46 rpm at 12 V
VELOCITY_UNIT_RPM = 0.229
SLEW_TAU_S = 0.03  # time constant of the emulated position loop
NO_LOAD_CURRENT_UNITS = 45  # 0.12 A at 12 V, 2.69 mA per unit


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
    dynamics: ShaftDynamics | None = None  # what moves the shaft: None, the first-order model below
    health: ServoHealthModel = field(default_factory=ServoHealthModel)  # temperature, voltage, their shutdowns
    # Drive faults: a stripped gear (the motor spins, the output shaft stays), a current reported with its sign
    # flipped, and a Present_Position that stays at one value while the shaft moves.
    stripped: bool = False
    current_sign: int = 1
    frozen_position: int | None = None
    # Registers that acknowledge a write but keep their old value (a worn EEPROM cell).
    unwritable: set = field(default_factory=set)

    def __post_init__(self) -> None:
        for name, value in DEFAULTS.items():
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
        if self.stripped:
            current = self._spinning_free()
        else:
            current = self._first_order(dt) if self.dynamics is None else self.dynamics.advance(self, dt)
        self._publish(self.current_sign * current)
        self.health.step(self, dt)

    def _publish(self, current: float) -> None:
        """Present_* registers from the shaft state, as the firmware reports them (Drive_Mode, Homing_Offset)."""
        self.set("Present_Current", int(current))
        rpm = self.velocity * self.direction / 4096 * 60.0
        self.set("Present_Velocity", int(rpm / VELOCITY_UNIT_RPM))
        frozen = self.frozen_position
        self.set("Present_Position", self.present_position() if frozen is None else frozen)
        self.set("Moving", int(abs(self.velocity) > 1.0))

    def _spinning_free(self) -> float:
        """A stripped gear: the output shaft (and its encoder) stays; the motor behind it spins at its no-load
        current (0.12 A at 12 V) in the direction of the goal."""
        self.velocity = 0.0
        if self.get("Torque_Enable") != 1:
            return 0.0
        error = (self.position_for(self.get("Goal_Position")) - self.shaft) * self.direction
        return math.copysign(NO_LOAD_CURRENT_UNITS, error) if abs(error) > 1 else 0.0

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
        new = self._blocked(self.shaft + max(-vmax * dt, min(vmax * dt, step)))
        self.velocity = (new - self.shaft) / dt if dt > 0 else 0.0
        self.shaft = new
        # Current ~ P-gain x remaining error (the obstacle keeps the error, so the current saturates there).
        limit = self.get("Current_Limit")
        if mode == 5:
            limit = min(limit, abs(self.get("Goal_Current")))
        residual = (target - self.shaft) * self.direction
        return max(-limit, min(limit, residual * self.get("Position_P_Gain") / 128.0)) if torque else 0.0

    def _blocked(self, new: float) -> float:
        """Where the obstacle, if any, lets the shaft go on its way to `new`."""
        if self.obstacle is None:
            return new
        stop, side = self.obstacle
        if side > 0 and new > stop:
            return max(self.shaft, stop) if self.shaft <= stop else self.shaft
        if side < 0 and new < stop:
            return min(self.shaft, stop) if self.shaft >= stop else self.shaft
        return new

    def reboot(self) -> None:
        """A power cycle: RAM back to defaults (torque off, errors cleared), EEPROM kept; Startup Torque On (v45+) turns
        the torque back on by itself, holding the present position."""
        eeprom = bytes(self.regs[:EEPROM_END])
        self.regs = bytearray(TABLE_SIZE)
        for name, value in DEFAULTS.items():
            if CONTROL_TABLE[name][0] >= EEPROM_END:
                self.set(name, value)
        self.regs[:EEPROM_END] = eeprom
        self.set("Goal_Current", min(self.get("Goal_Current"), self.get("Current_Limit")))  # initialised within it
        self.set("Goal_Position", self.present_position())
        self.set("Present_Position", self.present_position())
        if self.get("Firmware_Version") >= 45 and self.get("Startup_Configuration") & STARTUP_TORQUE_ON:
            self.set("Torque_Enable", 1)
