"""The XM430's health items, emulated (e-Manual, control table and "Shutdown(63)"): the temperature heats with the
current (I^2 R) and cools to ambient (first order); the input voltage sags under every servo's current on the one
shared `Supply`; the firmware sets its overheating, input-voltage and overload bits and turns the torque off for
those in Shutdown. Faults: `Supply.open_v` / `r_ohm`, a servo's `extra_heating_c_per_s` or `temperature_c`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from lerobot_blindgrasp.emulators.control_table import HW_INPUT_VOLTAGE, HW_OVERHEATING, HW_OVERLOAD
from lerobot_blindgrasp.hardware.xm430 import CURRENT_UNIT_A


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
