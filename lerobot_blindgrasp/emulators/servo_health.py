"""The XM430's health items, emulated: winding temperature, input voltage under load, and the firmware's reaction.

What a real servo does that the tests need (XM430-W350 e-Manual, control table and "Shutdown(63)"):
- Present_Temperature(146, 1 degC) heats with the current (I^2 R losses) and cools to ambient (first order);
- Present_Input_Voltage(144, 0.1 V) is the supply minus the drop of its cable and supply under the current of every
  servo on it (one shared supply: a stalled finger sags its neighbours too);
- the firmware sets Hardware_Error_Status: overheating (0x04) at Temperature_Limit(31), input voltage (0x01) outside
  Min/Max_Voltage_Limit(34/32), overload (0x20) after `overload_s` at the current limit, and turns the torque off for
  the bits that are in Shutdown(63) (factory 0x34: overheating, electrical shock, overload; not the voltage).

Fault injection: `Supply.open_v` / `Supply.r_ohm` (a weak or sagging supply, a thin cable), a servo's
`extra_heating_c_per_s` (a blocked fan, a bad winding) or `temperature_c` (a servo already hot at connect).
Kept apart from the shaft dynamics: `EmulatedServo.step` calls `ServoHealthModel.step` after it has set the current.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

CURRENT_UNIT_A = 0.00269
HW_INPUT_VOLTAGE, HW_OVERHEATING, HW_OVERLOAD = 0x01, 0x04, 0x20


@dataclass
class Supply:
    """The one power supply of the bus: open-circuit voltage and the resistance of supply plus cable."""

    open_v: float = 12.0
    r_ohm: float = 0.05
    load_a: dict[int, float] = field(default_factory=dict)  # servo id -> its current at its last step

    def voltage(self) -> float:
        return self.open_v - self.r_ohm * sum(self.load_a.values())


@dataclass
class ServoHealthModel:
    supply: Supply = field(default_factory=Supply)
    ambient_c: float = 35.0
    temperature_c: float = 35.0
    thermal_tau_s: float = 300.0
    # Stalled at 2.3 A this heats about 0.2 degC/s and would settle ~60 degC above ambient, past the 80 degC limit.
    heating_c_per_s_per_a2: float = 0.038
    extra_heating_c_per_s: float = 0.0
    overload_s: float = 8.0  # ROBOTIS does not publish it; the host's stall stop must come first
    at_limit_s: float = 0.0

    def step(self, servo, dt: float) -> None:
        amps = abs(servo.get("Present_Current")) * CURRENT_UNIT_A
        self.supply.load_a[servo.id] = amps
        if dt > 0:
            settle = self.ambient_c + self.thermal_tau_s * (self.heating_c_per_s_per_a2 * amps**2
                                                            + self.extra_heating_c_per_s)  # fmt: skip
            self.temperature_c = settle + (self.temperature_c - settle) * math.exp(-dt / self.thermal_tau_s)
        servo.set("Present_Temperature", max(0, min(255, round(self.temperature_c))))
        volts = self.supply.voltage()
        servo.set("Present_Input_Voltage", max(0, min(65535, round(volts * 10))))
        self._firmware(servo, dt)

    def _firmware(self, servo, dt: float) -> None:
        bits = 0
        if servo.get("Present_Temperature") >= servo.get("Temperature_Limit"):
            bits |= HW_OVERHEATING
        if (
            not servo.get("Min_Voltage_Limit")
            <= servo.get("Present_Input_Voltage")
            <= servo.get("Max_Voltage_Limit")
        ):
            bits |= HW_INPUT_VOLTAGE
        limit = servo.get("Current_Limit")
        if servo.get("Operating_Mode") == 5:
            limit = min(limit, abs(servo.get("Goal_Current")))
        at_limit = servo.get("Torque_Enable") == 1 and limit > 0 and abs(servo.get("Present_Current")) >= limit - 1
        self.at_limit_s = self.at_limit_s + dt if at_limit else 0.0
        if self.at_limit_s >= self.overload_s:
            bits |= HW_OVERLOAD
        if bits:
            status = servo.get("Hardware_Error_Status") | bits
            servo.set("Hardware_Error_Status", status)
            if status & servo.get("Shutdown"):
                servo.set("Torque_Enable", 0)
