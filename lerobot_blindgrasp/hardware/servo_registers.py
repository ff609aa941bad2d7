"""What the servos' control tables must hold besides positions and health: checked at connect (`check_setup`),
restored at configure (`restore`), and read every period (`check_state`): a reset drops the torque and restores RAM
defaults without an error bit, so what configure set must still read back. EEPROM needs no per-period read: the
firmware refuses EEPROM writes while the torque is on.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass

from lerobot_blindgrasp.hardware import xm430

logger = logging.getLogger(__name__)

CHECKED = (
    "Torque_Enable",
    "Position_P_Gain",
    "Position_I_Gain",
    "Position_D_Gain",
    "Bus_Watchdog",
    "Goal_Current",
)
BLOCK = ("Torque_Enable", "Goal_Current")  # first and last register of the block read (40 bytes per servo)
READ = (*CHECKED, "Hardware_Error_Status")
LIMITS_BLOCK = ("Temperature_Limit", "Shutdown")  # EEPROM 31..63, read once at connect
LIMITS_READ = (
    "Temperature_Limit",
    "Max_Voltage_Limit",
    "Min_Voltage_Limit",
    "PWM_Limit",
    "Current_Limit",
    "Startup_Configuration",
    "Shutdown",
)


class FirmwareTooOldError(RuntimeError):
    """A servo's firmware is older than a defence needs."""


class ProtectionNotKeptError(RuntimeError):
    """A no-host protection register did not keep its configured value."""


class ServoFaultError(RuntimeError):
    """A servo reported Hardware_Error_Status bits, confirmed by a second read."""


class ServoStateChangedError(RuntimeError):
    """A servo no longer holds what was configured: it was reset."""


@dataclass(frozen=True)
class ServoReport:
    hardware_error: dict[str, int]  # joint -> Hardware_Error_Status bits
    changed: dict[str, list[str]]  # joint -> "register value (set expected)" for every register that moved
    watchdog_tripped: list[str]  # joints whose bus watchdog stopped them (torque still on, goals refused)


def compare_registers(state: dict[str, dict[str, int]], expected: dict[str, int]) -> ServoReport:
    """What the block read (`read_block(*BLOCK, READ)`) says against what was set."""
    hw = {j: s["Hardware_Error_Status"] for j, s in state.items() if s["Hardware_Error_Status"]}
    changed: dict[str, list[str]] = {}
    tripped = []
    for j, s in state.items():
        for name, want in expected.items():
            got = s[name]
            if name == "Bus_Watchdog" and want and got == xm430.WATCHDOG_TRIPPED and s["Torque_Enable"] == 1:
                tripped.append(j)
            elif got != want:
                changed.setdefault(j, []).append(f"{name} {got} (set {want})")
    return ServoReport(hw, changed, tripped)


class ServoRegisters:
    """The control-table checks of the servos on `bus` (one per joint); `protection` is what the no-host
    protection registers must hold. `expected` is what configure set, checked every period; empty while the torque
    is off."""

    def __init__(self, bus, joints: list[str], protection: dict[str, int]):
        self.bus, self.joints, self.protection = bus, list(joints), dict(protection)
        self.expected: dict[str, int] = {}
        self.last_check = 0.0  # time.monotonic() of the last state check
        self._startup_torque_on: dict[str, int] = {}  # joint -> its Startup_Configuration, if Startup Torque On

    def _name(self, j: str) -> str:
        return f"{j} (ID {self.bus.motors[j].id})"

    def check_setup(self) -> dict[str, dict[str, int]]:
        """At connect, before any write: the firmware versions and Startup_Configuration; returns the EEPROM limits."""
        versions = self.bus.sync_read("Firmware_Version")
        old = {self._name(j): v for j, v in versions.items() if v < xm430.FIRMWARE_MIN}
        if old:
            raise FirmwareTooOldError(
                f"Servo firmware {old} is older than v{xm430.FIRMWARE_MIN}, which Drive_Mode (the calibration's "
                "direction) and Bus_Watchdog (the stop when this host goes quiet) need. Update it with DYNAMIXEL "
                "Wizard 2.0 (Firmware Update) before using the gripper."
            )
        eeprom = self.bus.read_block(*LIMITS_BLOCK, LIMITS_READ)
        self._startup_torque_on = {
            j: eeprom[j]["Startup_Configuration"]
            for j in self.joints
            if versions[j] >= xm430.FIRMWARE_STARTUP_CONFIGURATION
            and eeprom[j]["Startup_Configuration"] & xm430.STARTUP_TORQUE_ON
        }
        return eeprom

    def restore(self) -> dict[str, dict[str, int]] | None:
        """At configure (torque off, EEPROM writable): Startup Torque On cleared, the rest of the register kept; the
        no-host protection registers to their configured values, read back. Returns the EEPROM limits when they
        were rewritten (None when they were right)."""
        for j, value in self._startup_torque_on.items():
            self.bus.write("Startup_Configuration", j, value & ~xm430.STARTUP_TORQUE_ON)
        if self._startup_torque_on:
            logger.warning(
                "Startup_Configuration(60) of %s had Startup Torque On: such a servo turns its torque on by itself "
                "after a power cycle or a brown-out, so a reset would not show as a dropped torque, and an unattended "
                "gripper would stiffen at power-up. Cleared it (EEPROM).", sorted(self._startup_torque_on)
            )  # fmt: skip
        self._startup_torque_on = {}
        return self._restore_protection()

    def _restore_protection(self) -> dict[str, dict[str, int]] | None:
        want = self.protection
        eeprom = self.bus.read_block(*LIMITS_BLOCK, LIMITS_READ)
        wrong = [(j, r, eeprom[j][r]) for j in self.joints for r in want if eeprom[j][r] != want[r]]
        for j, reg, _ in wrong:
            self.bus.write(reg, j, want[reg])
        if not wrong:
            return None
        logger.warning("Restored the servos' no-host protection (EEPROM): %s. A tool or a previous session changed "
                       "it; with no host running, the firmware is the only protection.",
                       "; ".join(f"{j} {r} {have} -> {want[r]}" for j, r, have in wrong))  # fmt: skip
        eeprom = self.bus.read_block(*LIMITS_BLOCK, LIMITS_READ)
        kept = [f"{self._name(j)} {r} = {eeprom[j][r]} (configured {want[r]})"
                for j in self.joints for r in want if eeprom[j][r] != want[r]]  # fmt: skip
        if kept:
            raise ProtectionNotKeptError(
                f"Servo registers that protect the gripper when no host is running did not keep their configured "
                f"value: {'; '.join(kept)}. Check them with DYNAMIXEL Wizard 2.0 (a failing EEPROM, a servo of "
                "another model); the gripper is not used without them."
            )
        return eeprom

    def write_settings(self, settings: dict[str, int]) -> None:
        """At configure (torque off): `settings` (register -> value, written in order) on every servo. Bus_Watchdog
        is cleared on all of them first: a watchdog stop from the last session (the host went quiet before its
        stop, e.g. while a servo was losing power) outlives the torque-off and makes Goal_Current read-only."""
        for j in self.joints:
            self.bus.write("Bus_Watchdog", j, 0)
        for j in self.joints:
            for register, value in settings.items():
                self.bus.write(register, j, value)

    def torque_on_holding(self, present: dict[str, int], watchdog_units: int) -> None:
        """Torque on with Goal_Position = `present` (trusted ticks), so nothing moves. A watchdog error outlives the
        torque-off and makes the goals read-only: cleared first, armed once the torque is on."""
        for j in self.joints:
            self.bus.write("Bus_Watchdog", j, 0)
            self.bus.write("Goal_Position", j, present[j])
        self.bus.enable_torque()
        for j in self.joints:
            self.bus.write("Bus_Watchdog", j, watchdog_units)

    def check_state(self) -> list[str]:
        """One sync read of the state block: hardware errors, then anything configure set that changed (a reset);
        returns the joints whose watchdog stopped them during a pause of this process."""
        report = compare_registers(self.bus.read_block(*BLOCK, READ), self.expected)
        if report.changed:  # read again before stopping: one corrupt reply with a valid CRC must not stop it
            report = compare_registers(self.bus.read_block(*BLOCK, READ), self.expected)
        self.last_check = time.monotonic()
        bad = {j: v for j, v in report.hardware_error.items() if self._confirm_hardware_error(j)}
        if bad:
            detail = "; ".join(f"{self._name(j)}: {xm430.decode_hardware_error(v)}" for j, v in bad.items())
            raise ServoFaultError(
                f"Servo hardware error: {detail}. The firmware keeps torque off until the servo is rebooted or "
                "power-cycled; inspect the finger first."
            )
        if report.changed:
            detail = "; ".join(f"{self._name(j)}: {', '.join(c)}" for j, c in report.changed.items())
            raise ServoStateChangedError(
                f"Servo state changed without a command: {detail}. A servo reset (brown-out, loose power cable) "
                "drops its torque and restores factory RAM settings; check the supply and cabling, then reconnect."
            )
        return report.watchdog_tripped

    def _confirm_hardware_error(self, joint: str) -> bool:
        """Re-read one servo's Hardware_Error_Status (unicast, alert bit allowed): a corrupted or stale sync-read
        reply must not stop the gripper, a real error reads the same twice."""
        value = self.bus.read_despite_alert(joint, "Hardware_Error_Status")
        if value is None:
            return True  # cannot confirm either way: treat as an error
        if not value:
            logger.warning("Spurious Hardware_Error_Status on %s (not confirmed by a second read).", joint)
        return bool(value)

    def rearm_watchdog(self, joints: list[str], present: dict[str, int]) -> None:
        """The bus watchdog stopped `joints` during a pause of this process, which is evidently alive again: clear the
        error (the goals are read-only until then), hold the pose they stopped in (`present`, ticks), re-arm."""
        units = self.expected["Bus_Watchdog"]
        logger.warning("Bus watchdog stopped %s after more than %d ms without bus traffic; re-arming it.",
                       joints, units * xm430.WATCHDOG_UNIT_MS)  # fmt: skip
        for j in joints:
            self.bus.write("Bus_Watchdog", j, 0)
            self.bus.write("Goal_Position", j, present[j])
            self.bus.write("Bus_Watchdog", j, units)
