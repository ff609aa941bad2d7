"""What the gripper reads from its servos besides positions: their setup at connect, their state every control
period, and their health at a rate that fits the bus budget, with a stricter check at every start.

- At connect, before anything is written: Firmware_Version(6) (Drive_Mode and Bus_Watchdog need v38), the EEPROM
  limits Temperature_Limit(31)..Shutdown(63) (`health.set_limits`), Startup_Configuration(60) (v45+: a servo set
  to turn its torque on at power-up is set back at configure, so a reset still shows as a dropped torque), then
  the start check of `health.py`. The registers that protect a servo when no host watches it
  (`xm430.NO_HOST_PROTECTION` and Current_Limit) are restored at configure, with the torque off, and read back: one
  that does not keep its value refuses the connect (`GripperProtectionError`), naming it.
- Every control period: the state block of `servo_state.py` (hardware errors, a reset, a tripped watchdog).
- Every `health_every_n` periods, whoever calls (get_observation, or send_action alone as in a replay script): the
  health block, judged by `health.py`. A start (connect, a trial, an announced recording episode, a loop resuming after a
  pause, `episodes.py`) is judged at the start levels at once: too close to a limit refuses it.
"""

from __future__ import annotations

import logging
import time

from lerobot.utils.decorators import check_if_not_connected

from lerobot_blindgrasp.hardware import xm430

from . import health, servo_state
from .calibration import ticks_to_rad
from .consistency import ConsistencyError, ConsistencyMonitor
from .errors import (
    GripperConsistencyError,
    GripperFirmwareError,
    GripperHardwareError,
    GripperHealthError,
    GripperProtectionError,
    GripperStateError,
)

logger = logging.getLogger(__name__)


class ServoChecks:
    """Mixin of `BlindgraspGripper` (it holds `bus`, `joints`, `expected`, `gate`, `health`, `config`, `timing`,
    `episodes` and `_safety`)."""

    _startup_torque_on: dict[str, int]  # joint -> its Startup_Configuration, for those with Startup Torque On
    _health_countdown = 0
    _last_call: float | None = None
    _fresh_currents: list[int] | None = None  # Present_Current of the health read of this period, not yet judged
    recording = None  # `recording_space.RecordingSpace` of the dataset being recorded, set at connect
    _consistency: ConsistencyMonitor | None = None

    @property
    def consistency(self) -> ConsistencyMonitor:
        """Tip forces against the servos, commands against motion (`consistency.py`); kp follows the P gain."""
        if self._consistency is None:
            self._consistency = ConsistencyMonitor.at_p_gain(self.config.position_p_gain)
        return self._consistency

    # --- at connect ----------------------------------------------------------------------------------------------
    def _check_servo_setup(self) -> None:
        versions = self.bus.sync_read("Firmware_Version")
        old = {f"{j} (ID {self.bus.motors[j].id})": v for j, v in versions.items() if v < xm430.FIRMWARE_MIN}
        if old:
            raise GripperFirmwareError(
                f"Servo firmware {old} is older than v{xm430.FIRMWARE_MIN}, which Drive_Mode (the calibration's "
                "direction) and Bus_Watchdog (the stop when this host goes quiet) need. Update it with DYNAMIXEL "
                "Wizard 2.0 (Firmware Update) before using the gripper."
            )
        eeprom = self.bus.read_block(*health.LIMITS_BLOCK, health.LIMITS_READ)
        self.health.reset()
        self.health.set_limits(eeprom)
        self._startup_torque_on = {
            j: eeprom[j]["Startup_Configuration"]
            for j in self.joints
            if versions[j] >= xm430.FIRMWARE_STARTUP_CONFIGURATION
            and eeprom[j]["Startup_Configuration"] & xm430.STARTUP_TORQUE_ON
        }
        self._check_health(start=True)  # before any torque: a hot servo or a weak supply refuses the start
        self._last_call = None

    def _clear_startup_torque(self) -> None:
        """At configure (torque off, EEPROM writable): Startup Torque On cleared, the rest of the register kept."""
        for j, value in self._startup_torque_on.items():
            self.bus.write("Startup_Configuration", j, value & ~xm430.STARTUP_TORQUE_ON)
        if self._startup_torque_on:
            logger.warning(
                "Startup_Configuration(60) of %s had Startup Torque On: such a servo turns its torque on by itself "
                "after a power cycle or a brown-out, so a reset would not show as a dropped torque, and an unattended "
                "gripper would stiffen at power-up. Cleared it (EEPROM).", sorted(self._startup_torque_on)
            )  # fmt: skip
        self._startup_torque_on = {}
        self._restore_protection()

    def _protection(self) -> dict[str, int]:
        current = xm430.amps_to_current_units(self.config.current_limit_a)
        return {**xm430.NO_HOST_PROTECTION, "Current_Limit": current}

    def _restore_protection(self) -> None:
        """The no-host protection registers to their configured values (torque off, EEPROM writable), then read back:
        what a servo does not keep refuses the connect."""
        want = self._protection()
        eeprom = self.bus.read_block(*health.LIMITS_BLOCK, health.LIMITS_READ)
        wrong = [(j, r, eeprom[j][r]) for j in self.joints for r in want if eeprom[j][r] != want[r]]
        for j, reg, _ in wrong:
            self.bus.write(reg, j, want[reg])
        if wrong:
            logger.warning("Restored the servos' no-host protection (EEPROM): %s. A tool or a previous session changed "
                           "it; with no host running, the firmware is the only protection.",
                           "; ".join(f"{j} {r} {have} -> {want[r]}" for j, r, have in wrong))  # fmt: skip
            eeprom = self.bus.read_block(*health.LIMITS_BLOCK, health.LIMITS_READ)
            self.health.set_limits(eeprom)
        kept = [f"{j} (ID {self.bus.motors[j].id}) {r} = {eeprom[j][r]} (configured {want[r]})"
                for j in self.joints for r in want if eeprom[j][r] != want[r]]  # fmt: skip
        if kept:
            raise GripperProtectionError(
                f"Servo registers that protect the gripper when no host is running did not keep their configured "
                f"value: {'; '.join(kept)}. Check them with DYNAMIXEL Wizard 2.0 (a failing EEPROM, a servo of "
                "another model); the gripper is not used without them."
            )

    # --- every period --------------------------------------------------------------------------------------------
    def _check_servo_state(self) -> None:
        """One sync read per control period (`servo_state.py`): hardware errors, then anything `configure()` set
        that changed (a reset), then a watchdog that stopped servos during a pause of this process."""
        report = servo_state.compare(self.bus.read_block(*servo_state.BLOCK, servo_state.READ), self.expected)
        if report.changed:  # read again before stopping: one corrupt reply with a valid CRC must not stop it
            report = servo_state.compare(self.bus.read_block(*servo_state.BLOCK, servo_state.READ), self.expected)
        self._last_state_check = time.monotonic()
        bad = {j: v for j, v in report.hardware_error.items() if self._confirm_hardware_error(j)}
        if bad:
            detail = "; ".join(
                f"{j} (ID {self.bus.motors[j].id}): {xm430.decode_hardware_error(v)}" for j, v in bad.items()
            )
            raise GripperHardwareError(
                f"Servo hardware error: {detail}. The firmware keeps torque off until the servo is rebooted or "
                "power-cycled; inspect the finger first."
            )
        if report.changed:
            detail = "; ".join(
                f"{j} (ID {self.bus.motors[j].id}): {', '.join(c)}" for j, c in report.changed.items()
            )
            raise GripperStateError(
                f"Servo state changed without a command: {detail}. A servo reset (brown-out, loose power cable) "
                "drops its torque and restores factory RAM settings; check the supply and cabling, then reconnect."
            )
        if report.watchdog_tripped:
            self._rearm_watchdog(report.watchdog_tripped)

    def _confirm_hardware_error(self, joint: str) -> bool:
        """Re-read one servo's Hardware_Error_Status (unicast, alert bit allowed): a corrupted or stale sync-read
        reply must not stop the gripper, a real error reads the same twice."""
        value = self.bus.read_despite_alert(joint, "Hardware_Error_Status")
        if value is None:
            return True  # cannot confirm either way: treat as an error
        if not value:
            logger.warning("Spurious Hardware_Error_Status on %s (not confirmed by a second read).", joint)
        return bool(value)

    def _rearm_watchdog(self, joints: list[str]) -> None:
        """The servos' bus watchdog stopped them because this process sent nothing for `bus_watchdog_ms` (a slow
        save between episodes, an operator prompt). The host is evidently alive again: clear the error (goal
        registers are read-only until then), hold the pose the servos stopped in, and arm the watchdog again."""
        logger.warning("Bus watchdog stopped %s after more than %d ms without bus traffic; re-arming it.",
                       joints, self.config.bus_watchdog_ms)  # fmt: skip
        ticks = self._trusted_ticks()
        present = {j: int(t) for j, t in zip(self.joints, ticks)}
        for j in joints:
            self.bus.write("Bus_Watchdog", j, 0)
            self.bus.write("Goal_Position", j, present[j])
            self.bus.write("Bus_Watchdog", j, self.expected["Bus_Watchdog"])
            if self.gate.goal is not None:
                self.gate.goal[self.joints.index(j)] = ticks[self.joints.index(j)]

    # --- health --------------------------------------------------------------------------------------------------
    def _poll_health(self, now: float) -> None:
        """Once per control period (get_observation, or send_action when it stands alone): the health block every
        `health_every_n` periods, and at once, at the start levels, when a start is pending."""
        start = self._starting(now)
        self._health_countdown -= 1
        if start or self._health_countdown <= 0:
            self._health_countdown = self.config.health_every_n
            self._check_health(start=start)

    def _starting(self, now: float) -> bool:
        """A recording episode announced since the last call, or the first call after a pause of the loop."""
        resumed = self._last_call is not None and now - self._last_call >= self.timing.pause_s
        self._last_call = now
        started = self.episodes.take() or resumed
        if started and self.recording is not None:
            self.recording.check()  # room on disk for the episode (`recording_space.py`)
        return started

    def _check_health(self, *, start: bool = False) -> None:
        """One sync read of the health block; ERROR stops (torque off by the latch), and at a start anything too
        close to its limit refuses it."""
        block = self.bus.read_block(*health.BLOCK, health.READ)
        self._fresh_currents = [health.signed16(block[j]["Present_Current"]) for j in self.joints]
        found = self.health.assess(block, self.expected.get("Goal_Current"), time.monotonic())
        errors = [str(d) for d in found if d.level == health.ERROR]
        if start and (close := self.health.start_problems(block) + errors):
            raise GripperHealthError(f"Refused to start: {'; '.join(close)}.")
        if errors:
            raise GripperHealthError(f"Servo health: {'; '.join(errors)}. Stopped before the firmware's own "
                                     "shutdown would drop the object.")  # fmt: skip

    def _check_consistency(self, q, forces) -> None:
        """After a period's readings, when its health read brought currents: the force and the motion checks of
        `consistency.py` (ConsistencyError becomes a named stop, torque off by the latch)."""
        currents, self._fresh_currents = self._fresh_currents, None
        if currents is None:
            return
        goal = None if self.gate.goal is None or not self.expected else [ticks_to_rad(t) for t in self.gate.goal]
        try:
            self.consistency.assess(time.monotonic(), q, goal, forces, currents, self.expected.get("Goal_Current"))
        except ConsistencyError as e:
            raise GripperConsistencyError(f"Inputs disagree: {e}") from e

    @check_if_not_connected
    def check_health_before_start(self) -> None:
        """Before a trial or an episode: refuse (torque off, named error) when a servo is too close to a limit."""
        with self._safety("checking servo health before a start"):
            self._check_health(start=True)
