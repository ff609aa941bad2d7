"""Servo health as ROS 2 diagnostics report it: OK / WARN / ERROR per joint and item, before the firmware acts.

The XM430 firmware protects itself late: it drops the torque (and the object) at Temperature_Limit or after an
overload, and never for a sagging supply, so the host acts first, at the levels of `xm430.py` (temperatures relative
to each servo's Temperature_Limit(31)). The health block is a 3.1 ms sync read, so it runs every `health_every_n`
periods: temperature moves in seconds, a stall is judged over seconds, a sag over half a second.
"""

from __future__ import annotations

import logging
import time
from collections import deque
from dataclasses import dataclass

import numpy as np

from lerobot_blindgrasp.hardware import xm430

logger = logging.getLogger(__name__)

OK, WARN, ERROR = 0, 1, 2  # diagnostic_msgs/DiagnosticStatus levels
LEVEL_NAMES = {OK: "OK", WARN: "WARN", ERROR: "ERROR"}

BLOCK = ("Present_Current", "Present_Temperature")  # first and last register of the health read (21 bytes)
READ = ("Present_Current", "Present_Input_Voltage", "Present_Temperature")
SLOPE_MIN_SPAN_S = 3.0  # a temperature trend is judged over at least this much history (whole-degree readings)


class ServoHealthError(RuntimeError):
    """A health item reached its ERROR level, or was too close to its limit to start."""


class ServoStallError(ServoHealthError):
    """Only the current item reached ERROR: a finger held at its current limit. The command squeezed too long; the
    servos themselves are within their limits, so a new trial may start after the stop."""


@dataclass(frozen=True)
class Diagnostic:
    level: int
    joint: str
    item: str
    value: float
    message: str

    def __str__(self) -> str:
        return f"{LEVEL_NAMES[self.level]} {self.joint} {self.item}: {self.message}"


class ServoHealth:
    """Judges the health block of every servo, keeping what a trend needs (temperature history, how long a servo
    has been at its current limit or below the voltage rating)."""

    def __init__(self, joints: list[str]):
        self.joints = list(joints)
        self.temperature_limit_c = dict.fromkeys(self.joints, float(xm430.TEMPERATURE_LIMIT_DEFAULT_C))
        self._history = {j: deque(maxlen=64) for j in self.joints}  # (t, degC)
        self._stall_since: dict[str, float] = {}
        self._sag_since: dict[str, float] = {}
        self._reported: dict[tuple[str, str], int] = {}
        self.latest: list[Diagnostic] = []

    def reset(self) -> None:
        for h in self._history.values():
            h.clear()
        self._stall_since.clear()
        self._sag_since.clear()

    def set_limits(self, eeprom: dict[str, dict[str, int]]) -> None:
        """The servos' own Temperature_Limit (`servo_registers.LIMITS_READ` per joint), which the temperature levels
        are relative to."""
        for j, regs in eeprom.items():
            self.temperature_limit_c[j] = regs["Temperature_Limit"] * xm430.TEMPERATURE_UNIT_C

    # --- the three items ---------------------------------------------------------------------------------------
    def _temperature(self, j: str, t: float, now: float) -> Diagnostic:
        limit = self.temperature_limit_c[j]
        hist = self._history[j]
        hist.append((now, t))
        stop = limit - xm430.TEMPERATURE_STOP_MARGIN_C
        text = f"{t:.0f} degC (Temperature_Limit {limit:.0f}, stop at {stop:.0f})"
        if t >= stop:
            return Diagnostic(ERROR, j, "temperature", t, f"{text}: too hot")
        if t < limit - xm430.TEMPERATURE_WARN_MARGIN_C:
            return Diagnostic(OK, j, "temperature", t, text)
        slope = _slope(hist)
        if slope > 0 and (eta := (limit - t) / slope) < xm430.TEMPERATURE_TREND_HORIZON_S:
            return Diagnostic(ERROR, j, "temperature", t, f"{text}: rising {slope * 60:.0f} degC/min, at the "
                              f"limit in {eta:.0f} s (over-temperature trend)")  # fmt: skip
        return Diagnostic(WARN, j, "temperature", t, f"{text}: nearing the limit")

    def _voltage(self, j: str, v: float, now: float) -> Diagnostic:
        text = f"{v:.1f} V (rated {xm430.RATED_VOLTAGE_V[0]:.1f}-{xm430.RATED_VOLTAGE_V[1]:.1f} V)"
        if v > xm430.VOLTAGE_HIGH_V:
            return Diagnostic(ERROR, j, "input voltage", v, f"{text}: over the rating")
        if v < xm430.VOLTAGE_STOP_LOW_V:
            since = self._sag_since.setdefault(j, now)
            if now - since >= xm430.VOLTAGE_STOP_HOLD_S:
                return Diagnostic(ERROR, j, "input voltage", v, f"{text}: below the rating for {now - since:.1f} s "
                                  "(supply sagging under load)")  # fmt: skip
        else:
            self._sag_since.pop(j, None)
        if v < xm430.VOLTAGE_WARN_LOW_V:
            return Diagnostic(WARN, j, "input voltage", v, f"{text}: low")
        return Diagnostic(OK, j, "input voltage", v, text)

    def _current(self, j: str, units: int, limit_units: int | None, now: float) -> Diagnostic:
        amps = xm430.current_units_to_amps(abs(units))
        if not limit_units:
            return Diagnostic(OK, j, "current", amps, f"{amps:.2f} A (torque off)")
        limit = xm430.current_units_to_amps(limit_units)
        text = f"{amps:.2f} A (limit {limit:.2f} A)"
        if abs(units) < xm430.STALL_FRACTION * limit_units:
            self._stall_since.pop(j, None)
            return Diagnostic(OK, j, "current", amps, text)
        held = now - self._stall_since.setdefault(j, now)
        if held >= xm430.STALL_STOP_S:
            return Diagnostic(
                ERROR, j, "current", amps, f"{text}: at the current limit for {held:.1f} s (stalled)"
            )
        if held >= xm430.STALL_WARN_S:
            return Diagnostic(WARN, j, "current", amps, f"{text}: at the current limit for {held:.1f} s")
        return Diagnostic(OK, j, "current", amps, text)

    # --- judging -------------------------------------------------------------------------------------------------
    def assess(self, block: dict[str, dict[str, int]], limit_units: int | None, now: float) -> list[Diagnostic]:
        """Every item of every joint; warnings are logged when an item's level changes (not every read)."""
        out = []
        for j in self.joints:
            regs = block[j]
            out.append(self._temperature(j, regs["Present_Temperature"] * xm430.TEMPERATURE_UNIT_C, now))
            out.append(self._voltage(j, xm430.voltage_v(regs["Present_Input_Voltage"]), now))
            out.append(self._current(j, signed16(regs["Present_Current"]), limit_units, now))
        for d in out:
            key = (d.joint, d.item)
            if d.level != self._reported.get(key, OK) and d.level >= WARN:
                logger.warning("Servo health %s", d)
            self._reported[key] = d.level
        self.latest = out
        return out

    def check(self, bus, limit_units: int | None, *, start: bool = False) -> list[int]:
        """One sync read of the health block on `bus`; ERROR raises `ServoHealthError`, and at a start anything too
        close to its limit does. Returns each joint's signed Present_Current (register units)."""
        block = bus.read_block(*BLOCK, READ)
        currents = [signed16(block[j]["Present_Current"]) for j in self.joints]
        found = self.assess(block, limit_units, time.monotonic())
        errors = [str(d) for d in found if d.level == ERROR]
        if start and (close := self.start_problems(block) + errors):
            raise ServoHealthError(f"Refused to start: {'; '.join(close)}.")
        if errors:
            stall = all(d.item == "current" for d in found if d.level == ERROR)
            raise (ServoStallError if stall else ServoHealthError)(
                f"Servo health: {'; '.join(errors)}. Stopped before the firmware's own shutdown would drop the object."
            )
        return currents

    def start_problems(self, block: dict[str, dict[str, int]]) -> list[str]:
        """What is too close to a limit to start a trial or an episode (the servos at rest)."""
        bad = []
        for j in self.joints:
            t = block[j]["Present_Temperature"] * xm430.TEMPERATURE_UNIT_C
            limit = self.temperature_limit_c[j]
            if t >= limit - xm430.TEMPERATURE_START_MARGIN_C:
                bad.append(
                    f"{j} temperature {t:.0f} degC (start needs < {limit - xm430.TEMPERATURE_START_MARGIN_C:.0f}"
                    f", Temperature_Limit {limit:.0f}): let it cool"
                )
            v = xm430.voltage_v(block[j]["Present_Input_Voltage"])
            if not xm430.VOLTAGE_START_LOW_V <= v <= xm430.VOLTAGE_HIGH_V:
                bad.append(
                    f"{j} input voltage {v:.1f} V (start needs {xm430.VOLTAGE_START_LOW_V:.1f}-"
                    f"{xm430.VOLTAGE_HIGH_V:.1f} V at rest): check the supply"
                )
        return bad


def levels_table() -> str:
    """The levels of `hardware/xm430.py` as the markdown table of docs/hardware.md."""
    x = xm430
    limit = x.TEMPERATURE_LIMIT_DEFAULT_C

    def temp(margin: float) -> str:
        return f"limit - {margin:g} degC ({limit - margin:g})"

    rows = [
        ("item", "WARN", "refuse a start (connect, every trial and recording episode)", "ERROR: named stop, torque off"),
        ("---", "---", "---", "---"),
        ("Present_Temperature", f">= {temp(x.TEMPERATURE_WARN_MARGIN_C)}", f">= {temp(x.TEMPERATURE_START_MARGIN_C)}",
         f">= {temp(x.TEMPERATURE_STOP_MARGIN_C)}, or rising to the limit within {x.TEMPERATURE_TREND_HORIZON_S:g} s "
         f"(a least-squares slope over >= {SLOPE_MIN_SPAN_S:g} s)"),
        ("Present_Input_Voltage", f"< {x.VOLTAGE_WARN_LOW_V:.1f} V",
         f"< {x.VOLTAGE_START_LOW_V:.1f} V or > {x.VOLTAGE_HIGH_V:.1f} V",
         f"< {x.VOLTAGE_STOP_LOW_V:.1f} V (the rating) for {x.VOLTAGE_STOP_HOLD_S:g} s, or > {x.VOLTAGE_HIGH_V:.1f} V"),
        ("Present_Current vs the current limit (Goal_Current in mode 5)",
         f">= {x.STALL_FRACTION:.0%} for {x.STALL_WARN_S:g} s", "-",
         f">= {x.STALL_FRACTION:.0%} for {x.STALL_STOP_S:g} s (a stall)"),
    ]  # fmt: skip
    return "\n".join("| " + " | ".join(r) + " |" for r in rows)


def signed16(value: int) -> int:
    """Present_Current is a signed 2-byte register; LeRobot's raw reads return it unsigned."""
    return value - 0x10000 if value >= 0x8000 else value


def _slope(history: deque) -> float:
    """Least-squares degC/s over the history (>= SLOPE_MIN_SPAN_S of it), 0 when too short: readings come in whole
    degrees."""
    if len(history) < 5 or history[-1][0] - history[0][0] < SLOPE_MIN_SPAN_S:
        return 0.0
    t, y = np.array(history, dtype=np.float64).T
    return float(np.polyfit(t - t[0], y, 1)[0])
