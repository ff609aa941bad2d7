"""The real gripper: nine XM430-W350 on one Dynamixel bus plus three fingertip load cells.

Observation and action follow `spec` exactly (names, order, rad and N), so datasets recorded here have the sim
demos' schema. Every bus transaction goes through LeRobot's `DynamixelMotorsBus`, subclassed in `bus.py` for
retries, clean retries and raw registers: the calibration lives in the servos (Drive_Mode, Homing_Offset), so
rad = (ticks - 2048) * 2pi/4096 needs no LeRobot normalization mode. The rest reads like LeRobot's `koch_follower`
plus the safety latch (`_safety`).

No reading is used unchecked: every position reading passes one plausibility gate (`plausibility.py`) before
it is returned or used to bound a goal, the force stream is checked for liveness by content (`force_sensor.py`),
get_observation measures the loop's period (`timing.py`), and both ports are opened for exclusive use (`ports.py`).

Safety is latched: any failure while connected (bus error after the retries, a lost port, servo hardware error, a
servo that reset or lost its settings, an implausible reading, force overload, stale or frozen force data, a
sustained loop overrun, an exception, Ctrl-C or SIGTERM/SIGHUP inside a call) turns the torque off on every servo that answers, closes the ports and raises one error that says
so. Reconnecting is an explicit decision of the operator. The servos' bus watchdog stops them on their own when the
host goes quiet (`bus_watchdog_ms`), and SIGTERM/SIGHUP unwind the LeRobot scripts like Ctrl-C (`signals.py`).

Why this module is over 300 lines: LeRobot's `Robot` interface puts connect, the interactive calibrate, configure,
setup_motors, get_observation, send_action and disconnect on one class. The safety latch (about 100 lines) wraps
all of them, so splitting it out would scatter the one place that decides when the torque goes off.
"""

from __future__ import annotations

import atexit
import dataclasses
import logging
import time
import weakref
from contextlib import contextmanager
from functools import cached_property

import draccus
import numpy as np
from lerobot.motors import Motor, MotorNormMode
from lerobot.motors.dynamixel import OperatingMode
from lerobot.robots.robot import Robot
from lerobot.utils.decorators import check_if_already_connected, check_if_not_connected

from lerobot_blindgrasp import durable, spec
from lerobot_blindgrasp.hardware.force import force_bias_warning
from lerobot_blindgrasp.hardware.xm430 import (
    MODEL,
    RAD_PER_TICK,
    WATCHDOG_UNIT_MS,
    amps_to_current_units,
    decode_hardware_error,
)

from . import calibration as calib
from . import connect_checks, force_calibration, health, latency_timer, policy_check, servo_state, signals
from .bus import PortLostError, RetryingDynamixelBus
from .calibration import rad_to_ticks, ticks_to_rad
from .config_blindgrasp_gripper import BlindgraspGripperConfig
from .errors import (
    ForceOverloadError,
    ForceSensorError,
    ForceTareError,
    GripperBusError,
    GripperHardwareError,
    GripperHealthError,
    GripperPortBusyError,
    GripperReadingError,
    GripperSafetyStop,
    GripperStateError,
    GripperTimingError,
)
from .force_sensor import ForceSensorReader, ForceStreamError
from .plausibility import ImplausibleReadingError, PositionGate
from .ports import PortInUseError
from .timing import LoopOverrunError, PeriodMonitor, SampleSpacing

logger = logging.getLogger(__name__)

REFERENCE_POSE_HELP = (
    "REFERENCE pose (q = 0 on all 9 joints): every finger hangs straight down from the plate, proximal and distal "
    "links in line, each finger in its own vertical plane through the claw axis (see robot_configs/README.md)."
)
POSITIVE_POSE_HELP = (
    "POSITIVE pose: from the reference pose, move EVERY joint by hand by at least ~10-15 degrees in its positive "
    "direction: J*0 turns the fingertip counter-clockwise seen from above; J*1 and J*2 swing the fingertip away "
    "from the claw axis (opening the claw)."
)


# What the latched stop raises for a failure below it: (cause, named error or None to keep the type, prefix).
_NAMED_STOPS = (
    (GripperSafetyStop, None, ""),
    (PortInUseError, GripperPortBusyError, ""),
    (ImplausibleReadingError, GripperReadingError, "Stopped while {what}: "),
    (LoopOverrunError, GripperTimingError, ""),
    (ForceTareError, None, ""),
    (PortLostError, GripperBusError, "Dynamixel port lost while {what}: "),
    (ForceStreamError, ForceSensorError, "Force sensor failure while {what}: "),
)


class BlindgraspGripper(Robot):
    """D'Claw-derived three-finger gripper (`--robot.type=blindgrasp_gripper`)."""

    config_class = BlindgraspGripperConfig
    name = "blindgrasp_gripper"

    def __init__(self, config: BlindgraspGripperConfig):
        self.config = config
        self.joints = list(spec.JOINT_NAMES)
        self.calibration_error: calib.CalibrationFileError | None = None
        super().__init__(config)  # loads and validates the calibration file through _load_calibration
        self.bus = RetryingDynamixelBus(
            port=config.port,
            motors={j: Motor(i, MODEL, MotorNormMode.DEGREES) for j, i in zip(self.joints, config.servo_ids)},
            calibration=self.calibration,
            baudrate=config.baudrate,
            num_retry=config.bus_num_retry,
            latency_timer_ms=config.latency_timer_ms,
        )
        # What configure() set, checked every control period (`servo_state.py`); empty while the torque is off.
        self.expected: dict[str, int] = {}
        self._last_state_check = 0.0
        fs = config.force_sensor
        self.force = ForceSensorReader(
            fs.port,
            fs.baudrate,
            fs.scale_n_per_count,
            channel_map=fs.channel_map,
            stale_timeout_s=fs.stale_timeout_s,
            connect_timeout_s=fs.connect_timeout_s,
            frozen_frames=fs.frozen_frames,
            min_rate_hz=fs.min_rate_hz,
            tare_max_std_n=fs.tare_max_std_n,
            tare_max_shift_n=fs.tare_max_shift_n,
            negative_fault_n=fs.negative_fault_n,
        )
        self.gate = PositionGate(
            speed_ticks_s=config.max_joint_speed_rad_s / RAD_PER_TICK,
            margin_ticks=config.plausibility_margin_rad / RAD_PER_TICK,
            backdrive_ticks=config.plausibility_backdrive_rad / RAD_PER_TICK,
            rereads=config.plausibility_rereads,
        )
        self.timing = PeriodMonitor(1.0 / config.loop_hz, config.max_overrun_s, what=f"{self.name} control loop")
        self.spacing = SampleSpacing(1.0 / config.loop_hz)  # no short step after a stalled observation
        self.health = health.ServoHealth(self.joints)  # OK / WARN / ERROR per servo item (`health.py`)
        self._health_countdown = 0
        self.lower = np.asarray(config.joint_lower, dtype=np.float64)
        self.upper = np.asarray(config.joint_upper, dtype=np.float64)
        self._atexit = None
        # Vision-free by design; lerobot-record and lerobot-rollout still read `robot.cameras`.
        self.cameras: dict = {}

    # --- features (valid while disconnected) ---------------------------------------------------------------------
    @cached_property
    def observation_features(self) -> dict[str, type]:
        return dict.fromkeys(spec.STATE_NAMES, float)

    @cached_property
    def action_features(self) -> dict[str, type]:
        return dict.fromkeys(spec.ACTION_NAMES, float)

    @property
    def is_connected(self) -> bool:
        return self.bus.is_connected

    @property
    def is_calibrated(self) -> bool:
        return self.bus.is_connected and self.bus.is_calibrated

    # --- connection ----------------------------------------------------------------------------------------------
    @check_if_already_connected
    def connect(self, calibrate: bool = True) -> None:
        policy_check.check_cli_policy(self)  # a policy named on the command line must fit, before any port opens
        if self.calibration_error is not None and calibrate:
            raise self.calibration_error  # before the port is even opened: nothing can move on a wrong frame
        if calibrate:
            connect_checks.refuse_unattended_calibration(self)  # no file and nobody to answer the prompts
        latency_timer.ensure_low_latency(self.config.port, self.config.force_sensor.port)  # USB adapters at 1 ms
        with self._safety("connecting"):
            self.expected = {}
            self.gate.forget()
            # Both ports are taken (exclusively) before the first byte goes out: a second owner is refused here.
            force_calibration.apply(self.force, self.calibration_dir, self.id)  # <id>.force.json, if measured
            self.force.open()
            self.bus.connect()  # pings all nine, with retries
            self._register_atexit()
            signals.install(self)
            self._check_servo_state()
            self._check_health_limits()  # before any torque: a hot servo or a weak supply refuses the start
            if self.calibration and not self.bus.is_calibrated:
                logger.info("Writing the calibration file %s to the servos.", self.calibration_fpath)
                self.bus.write_calibration(self.calibration)
                self.gate.forget()  # the readings change frame
            if not self.bus.is_calibrated:
                if not calibrate:
                    logger.warning("%s is not calibrated: run lerobot-calibrate before using it.", self)
                    self.force.wait_first_frame()
                    return
                self.calibrate()
            self.force.wait_first_frame()
            self.force.tare(self.config.force_sensor.tare_s)
            self.configure()
            if warning := force_bias_warning(self.force.read()):  # at rest, holding the start pose
                logger.warning(warning)
        self.timing.restart()
        self.spacing.restart()
        logger.info("%s connected (force tare %s counts).", self, np.round(self.force.offset).tolist())

    def configure(self) -> None:
        mode = OperatingMode[self.config.operating_mode].value
        current = amps_to_current_units(self.config.current_limit_a)
        watchdog = self.config.bus_watchdog_ms // WATCHDOG_UNIT_MS
        with self._safety("configuring the servos"):
            self.expected = {}
            self.bus.disable_torque()
            self.bus.configure_motors()  # Return_Delay_Time 0: status packets come back without the 500 us delay
            for j in self.joints:
                # A watchdog stop from the last session (the host went quiet before its stop, e.g. while a servo
                # was losing power) outlives the torque-off and makes Goal_Current read-only: clear it first.
                self.bus.write("Bus_Watchdog", j, 0)
            for j in self.joints:
                self.bus.write("Operating_Mode", j, mode)
                self.bus.write("Current_Limit", j, current)
                self.bus.write("Goal_Current", j, current)
                self.bus.write("Position_P_Gain", j, self.config.position_p_gain)
                self.bus.write("Position_I_Gain", j, self.config.position_i_gain)
                self.bus.write("Position_D_Gain", j, self.config.position_d_gain)
                self.bus.write("Profile_Velocity", j, self.config.profile_velocity)
            self._enable_torque_holding_pose()
            self.expected = {
                "Torque_Enable": 1,
                "Position_P_Gain": self.config.position_p_gain,
                "Position_I_Gain": self.config.position_i_gain,
                "Position_D_Gain": self.config.position_d_gain,
                "Bus_Watchdog": watchdog,
                "Goal_Current": current,
            }

    def _enable_torque_holding_pose(self) -> None:
        """Torque on with Goal_Position = the present pose, so nothing moves when the torque comes on."""
        ticks = self._trusted_ticks(free=True)  # the goal the torque comes on with: a confirmed reading only
        present = {j: int(t) for j, t in zip(self.joints, ticks)}
        q = np.array([ticks_to_rad(present[j]) for j in self.joints])
        outside = [j for j, v, lo, hi in zip(self.joints, q, self.lower, self.upper) if not lo <= v <= hi]
        if outside and self.config.operating_mode == "POSITION":
            # The firmware refuses goals outside its position limits, so holding the pose is impossible and a goal
            # at the limit would jump there at full speed: refuse instead.
            raise GripperSafetyStop(
                f"Joints {outside} start outside their limits; in POSITION mode the firmware would jump them to the "
                "limit. Move them inside by hand (torque is off) and connect again."
            )
        if outside:
            logger.warning("Joints %s start outside their limits; actions bring them back at <= %.2f rad per step.",
                           outside, self.config.max_relative_target)  # fmt: skip
        for j in self.joints:
            # A watchdog error outlives the torque-off (the register keeps reading -1) and makes the goal registers
            # read-only: clear it first, arm it once the torque is on (it only watches while the torque is on).
            self.bus.write("Bus_Watchdog", j, 0)
            self.bus.write("Goal_Position", j, present[j])
        self.bus.enable_torque()
        self.gate.goal = ticks
        for j in self.joints:
            self.bus.write("Bus_Watchdog", j, self.config.bus_watchdog_ms // WATCHDOG_UNIT_MS)

    @contextmanager
    def torque_disabled(self):
        """Torque off for the block (e.g. to move the fingers by hand), then on again holding the new pose. The
        per-period state check knows the torque is off on purpose."""
        expected = self.expected
        with self._safety("turning the torque off"):
            self.expected = {}
            self.gate.goal = None  # free: a hand may move the joints faster than the servos
            self.bus.disable_torque()
        yield
        if self.is_connected:  # a fault inside the block already stopped the gripper
            with self._safety("turning the torque back on"):
                self._enable_torque_holding_pose()
                self.expected = expected
            self.timing.restart()

    def calibrate(self) -> None:
        with self._safety("calibrating"):
            self.expected = {}
            self.gate.forget()  # readings change frame with Drive_Mode and Homing_Offset
            self.bus.disable_torque()
            if self.calibration:
                answer = input(
                    f"Press ENTER to write the calibration file of '{self.id}' to the servos, "
                    "or type 'c' and press ENTER to calibrate again: "
                )
                if answer.strip().lower() != "c":
                    self.bus.write_calibration(self.calibration)
                    return
            self._calibrate_interactively()

    def _calibrate_interactively(self) -> None:
        for j in self.joints:
            # Multi-turn mode so that readings never wrap at 0/4095 while the fingers are moved by hand.
            self.bus.write("Operating_Mode", j, OperatingMode.EXTENDED_POSITION.value)
            self.bus.write("Drive_Mode", j, 0)
            self.bus.write("Homing_Offset", j, 0)
        input(f"\nTorque is off. Hold the gripper in the {REFERENCE_POSE_HELP}\nPress ENTER when it is there: ")
        reference = self.bus.sync_read("Present_Position")
        input(f"\nNow the {POSITIVE_POSE_HELP}\nPress ENTER while holding it: ")
        positive = self.bus.sync_read("Present_Position")
        modes = calib.directions(reference, positive, self.config.calibration_min_motion_rad)
        for j in self.joints:
            self.bus.write("Drive_Mode", j, modes[j])
        present = self.bus.sync_read("Present_Position")
        homings = calib.homing_offsets(reference, positive, present)
        ids = {j: m.id for j, m in self.bus.motors.items()}
        self.calibration = calib.build(ids, modes, homings, self.lower, self.upper)
        self.bus.write_calibration(self.calibration)
        self._save_calibration()
        check = self.bus.sync_read("Present_Position")
        print("\nCalibrated joint angles in the positive pose (all should be > 0):")
        for j in self.joints:
            print(f"  {j:7s} id {ids[j]:2d}  drive_mode {modes[j]}  q = {ticks_to_rad(check[j]):+.3f} rad")
        logger.info("Calibration saved to %s", self.calibration_fpath)

    def setup_motors(self) -> None:
        """`lerobot-setup-motors`: give factory-fresh servos (ID 1, 57 600 bps) their D'Claw ID and the bus baud rate,
        one servo on the cable at a time, through LeRobot's `setup_motor`. Baud rates are tried factory rate first:
        a broadcast ping waits its full window at each rate (4 s at 9600 bps, LeRobot's first guess)."""
        self.bus.use_latency_timer()
        self.bus.default_baudrate = self.config.baudrate  # the rate setup_motor writes into each servo
        rates = [57_600, self.config.baudrate, *self.bus.model_baudrate_table[MODEL]]
        rates = list(dict.fromkeys(rates))
        try:
            for j in reversed(self.joints):
                input(f"Connect the controller board to the '{j}' servo (ID {self.bus.motors[j].id}) only, "
                      "then press ENTER: ")  # fmt: skip
                for k, rate in enumerate(rates):
                    try:
                        self.bus.setup_motor(j, initial_baudrate=rate)
                        break
                    except RuntimeError:
                        if k == len(rates) - 1:
                            raise
                print(f"'{j}' servo: ID {self.bus.motors[j].id} at {self.config.baudrate} bps")
        finally:
            if self.bus.is_connected:
                self.bus.disconnect(disable_torque=False)

    @check_if_not_connected
    def tare_forces(self) -> None:
        """Re-zero the fingertip sensors (fingertips touching nothing), e.g. between evaluation trials: load cells
        drift with temperature and use."""
        refused = None
        with self._safety("taring the force sensors"):
            try:
                self.force.tare(self.config.force_sensor.tare_s)
            except ForceTareError as e:  # a refusal stops nothing: the old zero stays, the pose is held
                refused = e
        self.timing.restart()  # the tare window is not a loop period
        if refused is not None:
            raise refused

    # --- control loop --------------------------------------------------------------------------------------------
    @check_if_not_connected
    def get_observation(self) -> dict[str, float]:
        self.spacing.before_read()
        with self._safety("reading the gripper state"):
            started = time.monotonic()
            self.timing.tick()
            self._check_servo_state()  # first: a reset servo is named as such, not as an odd position
            self._health_every_n()
            q = self._read_q()
            forces = self.force.read()
            self.spacing.after_read(started, time.monotonic())
            over = np.abs(forces) > self.config.force_sensor.overload_n
            if over.any():
                tips = {spec.FORCE_SENSOR_NAMES[i]: round(float(forces[i]), 2) for i in np.flatnonzero(over)}
                limit = self.config.force_sensor.overload_n
                raise ForceOverloadError(f"Fingertip force overload {tips} N > {limit} N")
        obs = {f"{j}.pos": float(v) for j, v in zip(self.joints, q)}
        obs.update({f"{s}.force": float(f) for s, f in zip(spec.FORCE_SENSOR_NAMES, forces)})
        return obs

    @check_if_not_connected
    def send_action(self, action: dict[str, float]) -> dict[str, float]:
        """Absolute joint targets (rad), clipped to the joint limits and then to +-max_relative_target around the
        present position, sent with one sync write. Returns the targets actually sent (after tick rounding).

        The step bound comes last so it holds from the first step whatever the start pose: a joint that starts
        outside its limits is brought back at <= max_relative_target per call, never in one jump."""
        missing = [k for k in spec.ACTION_NAMES if k not in action]
        unknown = [k for k in action if k not in spec.ACTION_NAMES]
        if missing or unknown:  # an extra key is a policy or teleop trained for other joints: nothing is sent
            raise KeyError(
                f"Action lacks {missing} and has unknown keys {unknown}; expected exactly "
                f"{list(spec.ACTION_NAMES)}. Nothing was sent."
            )
        target = np.array([float(action[k]) for k in spec.ACTION_NAMES])
        if not np.all(np.isfinite(target)):
            raise ValueError(f"Non-finite joint target {target.tolist()}; nothing was sent.")
        with self._safety("sending joint targets"):
            if time.monotonic() - self._last_state_check > spec.CONTROL_DT:  # no get_observation this period
                self._check_servo_state()
            q = self._read_q()  # the trusted estimate: the bound is never centred on an unchecked reading
            bound = self.config.max_relative_target
            target = np.clip(np.clip(target, self.lower, self.upper), q - bound, q + bound)
            ticks = {j: rad_to_ticks(t) for j, t in zip(self.joints, target)}
            self.bus.sync_write("Goal_Position", ticks)
            self.gate.goal = np.array([ticks[j] for j in self.joints], dtype=np.float64)
        return {f"{j}.pos": ticks_to_rad(ticks[j]) for j in self.joints}

    def _trusted_ticks(self, *, free: bool | None = None) -> np.ndarray:
        """Present_Position of all nine through the plausibility gate (`plausibility.py`)."""

        def read() -> np.ndarray:
            raw = self.bus.sync_read("Present_Position")
            return np.array([raw[j] for j in self.joints], dtype=np.float64)

        return self.gate.read(read, self.joints, free=not self.expected if free is None else free)

    def _read_q(self) -> np.ndarray:
        return np.array([ticks_to_rad(t) for t in self._trusted_ticks()])

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
                f"{j} (ID {self.bus.motors[j].id}): {decode_hardware_error(v)}" for j, v in bad.items()
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

    def _check_health_limits(self) -> None:
        """At connect: the servos' own limits (EEPROM), then the start check (`health.py`)."""
        self.health.reset()
        for note in self.health.set_limits(self.bus.read_block(*health.LIMITS_BLOCK, health.LIMITS_READ)):
            logger.warning("%s", note)
        self._check_health(start=True)

    def _health_every_n(self) -> None:
        self._health_countdown -= 1
        if self._health_countdown <= 0:
            self._health_countdown = self.config.health_every_n
            self._check_health()

    def _check_health(self, *, start: bool = False) -> None:
        """One sync read of the health block; ERROR stops (torque off by the latch), and at a start anything too
        close to its limit refuses it."""
        block = self.bus.read_block(*health.BLOCK, health.READ)
        found = self.health.assess(block, self.expected.get("Goal_Current"), time.monotonic())
        errors = [str(d) for d in found if d.level == health.ERROR]
        if start and (close := self.health.start_problems(block) + errors):
            raise GripperHealthError(f"Refused to start: {'; '.join(close)}.")
        if errors:
            raise GripperHealthError(f"Servo health: {'; '.join(errors)}. Stopped before the firmware's own "
                                     "shutdown would drop the object.")  # fmt: skip

    @check_if_not_connected
    def check_health_before_start(self) -> None:
        """Before a trial or an episode: refuse (torque off, named error) when a servo is too close to a limit."""
        with self._safety("checking servo health before a start"):
            self._check_health(start=True)

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

    def _confirm_hardware_error(self, joint: str) -> bool:
        """Re-read one servo's Hardware_Error_Status (unicast, alert bit allowed): a corrupted or stale sync-read
        reply must not stop the gripper, a real error reads the same twice."""
        value = self.bus.read_despite_alert(joint, "Hardware_Error_Status")
        if value is None:
            return True  # cannot confirm either way: treat as an error
        if not value:
            logger.warning("Spurious Hardware_Error_Status on %s (not confirmed by a second read).", joint)
        return bool(value)

    # --- safety --------------------------------------------------------------------------------------------------
    @contextmanager
    def _safety(self, what: str):
        try:
            yield
        except BaseException as e:
            if getattr(e, "torque_off_handled", False):
                raise  # an inner _safety already stopped the gripper and wrote the message
            was_open = self.bus.is_connected
            unconfirmed = self._stop()
            if not was_open:
                note = "The bus port was not open, so no torque was enabled by this process."
            elif unconfirmed:
                note = f"Torque-off NOT confirmed by servo IDs {unconfirmed}: cut the servo power."
            else:
                note = "Torque is off on all servos."
            named = next(((stop, prefix) for cause, stop, prefix in _NAMED_STOPS if isinstance(e, cause)), None)
            if named is not None:
                stop, prefix = named
                err = (stop or type(e))(f"{prefix.format(what=what)}{e} {note}")
            elif isinstance(e, (ConnectionError, RuntimeError, OSError)):
                tries = self.bus.tries
                err = GripperBusError(
                    f"Dynamixel bus failure while {what} (each transaction tried {tries} times): {e} {note}"
                )
            else:  # KeyboardInterrupt, programming errors: keep the original exception, the torque is off anyway
                logger.error("%s while %s. %s", type(e).__name__, what, note)
                e.torque_off_handled = True
                raise
            err.torque_off_handled = True
            raise err from e

    def _torque_off_all(self) -> list[int]:
        """Torque off on every servo; returns the IDs that did not confirm it."""
        self.expected = {}
        self.gate.forget()
        return self.bus.torque_off_everywhere()

    def _stop(self) -> list[int]:
        """Latched stop: torque off, then close both ports."""
        unconfirmed = list(self.config.servo_ids)
        with signals.deferred():  # a second Ctrl-C or SIGTERM must not cut the torque-off short
            if self.bus.is_connected:
                try:
                    unconfirmed = self._torque_off_all()
                finally:
                    self._close()
            else:
                self._close()
        return unconfirmed

    def _close(self) -> None:
        if self.bus.is_connected:
            self.bus.disconnect(disable_torque=False)  # the torque-off, when wanted, was _stop's
        self.force.disconnect()
        signals.uninstall(self)
        if self._atexit is not None:
            atexit.unregister(self._atexit)
            self._atexit = None

    def _register_atexit(self) -> None:
        ref = weakref.ref(self)

        def _at_exit():
            robot = ref()
            if robot is not None and robot.is_connected:
                robot._stop()

        self._atexit = _at_exit
        atexit.register(_at_exit)

    def __exit__(self, exc_type, exc_value, traceback) -> None:
        # After a latched safety stop the robot is already disconnected: LeRobot's __exit__ would raise
        # DeviceNotConnectedError and hide the fault that stopped it. Let that fault propagate instead.
        if self.is_connected:
            self.disconnect()

    def _load_calibration(self, fpath=None) -> None:
        """Load and check the file by the rules `calibrate()` follows. A bad file is kept out of `self.calibration`
        and refused by `connect()` (lerobot-calibrate still works: it connects with calibrate=False)."""
        fpath = fpath or self.calibration_fpath
        try:
            bad = calib.schema_problems(calib.read_raw(fpath))
            if not bad:
                super()._load_calibration(fpath)
                bad = calib.problems(self.calibration, dict(zip(self.joints, self.config.servo_ids, strict=True)))
        except Exception as e:  # unreadable: empty, truncated, not JSON, not UTF-8
            bad = [f"unreadable ({type(e).__name__}: {e})"]
        if bad:
            self.calibration = {}
            self.calibration_error = calib.CalibrationFileError(
                f"Calibration file {fpath} is invalid: {'; '.join(bad)}. Nothing was moved. Run "
                f"lerobot-calibrate --robot.type={self.name} --robot.id={self.id} to replace it."
            )
            logger.error("%s", self.calibration_error)
            return
        self.calibration_error = None
        # The position range is derived data: the config's joint limits are its authority (calibrate() builds it so).
        cfg = self.config
        self.calibration = {
            j: dataclasses.replace(self.calibration[j], range_min=rad_to_ticks(lo), range_max=rad_to_ticks(hi))
            for j, lo, hi in zip(self.joints, cfg.joint_lower, cfg.joint_upper, strict=True)
        }

    def _save_calibration(self, fpath=None) -> None:
        """LeRobot's base class writes the file in place, so a full disk truncates the previous calibration. Written
        atomically instead: on failure the old file is unchanged, and `durable.WriteError` (not an OSError, so the
        safety latch does not call it a bus failure) names the file and the cause."""
        with durable.atomic_open(fpath or self.calibration_fpath) as f, draccus.config_type("json"):
            draccus.dump(self.calibration, f, indent=4)

    @check_if_not_connected
    def disconnect(self) -> None:
        if not self.config.disable_torque_on_disconnect:
            self._close()
            return
        unconfirmed = self._stop()
        if unconfirmed:
            msg = f"Disconnected, but servo IDs {unconfirmed} did not confirm torque off: cut the power."
            raise GripperBusError(msg)
        logger.info("%s disconnected, torque off.", self)
