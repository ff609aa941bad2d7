"""The real gripper: nine XM430-W350 on one Dynamixel bus plus three fingertip load cells.

Observation and action follow `spec` exactly (names, order, rad and N), so datasets recorded here have the sim
demos' schema. Every bus transaction goes through LeRobot's `DynamixelMotorsBus`, subclassed in `bus.py` for
retries, clean retries and raw registers: the calibration lives in the servos (Drive_Mode, Homing_Offset), so
rad = (ticks - 2048) * 2pi/4096 needs no LeRobot normalization mode. The rest reads like LeRobot's `koch_follower`.

No reading is used unchecked: every position reading passes one plausibility gate (`plausibility.py`) before
it is returned or used to bound a goal, the force stream is checked for liveness by content (`force_sensor.py`),
the servos' state and health are read as `servo_checks.py` says, get_observation measures the loop's period and
spaces its samples (`timing.py`), and both ports are opened for exclusive use (`ports.py`).

Safety is latched (`latch.py`): any failure while connected turns the torque off on every servo that answers,
closes the ports and raises one error that says so. The servos' bus watchdog stops them on their own when the host
goes quiet (`bus_watchdog_ms`; `keepalive.py` feeds it while a trial waits), and SIGTERM/SIGHUP unwind the LeRobot
scripts like Ctrl-C (`signals.py`). The interactive calibration and motor setup are in `interactive.py`.
"""

from __future__ import annotations

import logging
import time
from contextlib import contextmanager
from functools import cached_property

import numpy as np
from lerobot.motors import Motor, MotorNormMode
from lerobot.motors.dynamixel import OperatingMode
from lerobot.robots.robot import Robot
from lerobot.utils.decorators import check_if_already_connected, check_if_not_connected

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.hardware.dynamixel import RetryingDynamixelBus, latency_timer
from lerobot_blindgrasp.hardware.force import force_bias_warning
from lerobot_blindgrasp.hardware.force_board import ForceSensorReader, ForceTareError, force_calibration
from lerobot_blindgrasp.hardware.xm430 import MODEL, RAD_PER_TICK, WATCHDOG_UNIT_MS, amps_to_current_units

from . import calibration as calib
from . import connect_checks, health, interactive, policy_check, signals
from .calibration import rad_to_ticks, ticks_to_rad
from .config_blindgrasp_gripper import BlindgraspGripperConfig
from .episodes import EpisodeStarts
from .errors import ForceOverloadError, GripperBusError, GripperSafetyStop
from .keepalive import BusKeepAlive
from .latch import SafetyLatch
from .plausibility import PositionGate
from .recording_space import recording_from_command_line
from .servo_checks import ServoChecks
from .timing import PeriodMonitor, SampleSpacing

logger = logging.getLogger(__name__)


class BlindgraspGripper(SafetyLatch, ServoChecks, BusKeepAlive, calib.CheckedCalibrationFile, Robot):
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
        self._startup_torque_on: dict[str, int] = {}
        self.force = self._make_force_reader(config.force_sensor)
        self.gate = PositionGate(
            speed_ticks_s=config.max_joint_speed_rad_s / RAD_PER_TICK,
            margin_ticks=config.plausibility_margin_rad / RAD_PER_TICK,
            backdrive_ticks=config.plausibility_backdrive_rad / RAD_PER_TICK,
            rereads=config.plausibility_rereads,
        )
        self.timing = PeriodMonitor(1.0 / config.loop_hz, config.max_overrun_s, what=f"{self.name} control loop")
        self.spacing = SampleSpacing(1.0 / config.loop_hz)  # no two samples closer than the contract allows
        self.health = health.ServoHealth(self.joints)  # OK / WARN / ERROR per servo item (`health.py`)
        self.episodes = EpisodeStarts()  # lerobot-record's episode announcements (`episodes.py`)
        self.lower, self.upper = np.asarray([config.joint_lower, config.joint_upper], dtype=np.float64)
        self._atexit = None
        self.cameras: dict = {}  # vision-free by design; lerobot-record and lerobot-rollout still read it

    @staticmethod
    def _make_force_reader(fs) -> ForceSensorReader:
        return ForceSensorReader(
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
        self.recording = recording_from_command_line(self)  # disk space checked at each start (`recording_space`)
        if self.calibration_error is not None and calibrate:
            raise self.calibration_error  # before the port is even opened: nothing can move on a wrong frame
        if calibrate:
            connect_checks.refuse_unattended_calibration(self)  # no file and nobody to answer the prompts
        latency_timer.ensure_low_latency(self.config.port, self.config.force_sensor.port)  # USB adapters at 1 ms
        self.host_setup = connect_checks.prepare_host(self)  # before any thread starts: threads inherit it
        with self._safety("connecting"):
            self.expected = {}
            self.gate.forget()
            # Both ports are taken (exclusively) before the first byte goes out: a second owner is refused here.
            force_calibration.apply(self.force, self.calibration_dir, self.id)  # <id>.force.json, if measured
            self.force.open()
            self.bus.connect()  # pings all nine, with retries; names a Status_Return_Level that hides replies
            self._guard_process()
            signals.install(self)
            self.episodes.install()
            self._check_servo_state()
            self._check_servo_setup()  # firmware, EEPROM limits, the start check of the servos' health
            if not self._bring_up(calibrate):
                return
        self.timing.restart()
        self.spacing.restart()
        logger.info("%s connected (force tare %s counts).", self, np.round(self.force.offset).tolist())

    def _bring_up(self, calibrate: bool) -> bool:
        """Calibration to the servos, the force tare, configure; False when left uncalibrated (lerobot-calibrate)."""
        if self.calibration and not self.bus.is_calibrated:
            logger.info("Writing the calibration file %s to the servos.", self.calibration_fpath)
            self.bus.write_calibration(self.calibration)
            self.gate.forget()  # the readings change frame
        if not self.bus.is_calibrated:
            if not calibrate:
                logger.warning("%s is not calibrated: run lerobot-calibrate before using it.", self)
                self.force.wait_first_frame()
                return False
            self.calibrate()
        self.force.wait_first_frame()
        self.force.tare(self.config.force_sensor.tare_s)
        self.configure()
        if warning := force_bias_warning(self.force.read()):  # at rest, holding the start pose
            logger.warning(warning)
        return True

    def configure(self) -> None:
        mode = OperatingMode[self.config.operating_mode].value
        current = amps_to_current_units(self.config.current_limit_a)
        with self._safety("configuring the servos"):
            self.expected = {}
            self.bus.disable_torque()
            self.bus.configure_motors()  # Return_Delay_Time 0: status packets come back without the 500 us delay
            self._clear_startup_torque()
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
                "Bus_Watchdog": self.config.bus_watchdog_ms // WATCHDOG_UNIT_MS,
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
            interactive.calibrate_by_hand(self)

    def setup_motors(self) -> None:
        interactive.setup_motors(self)

    @check_if_not_connected
    def tare_forces(self) -> None:
        """Re-zero the fingertip sensors (fingertips touching nothing), e.g. between evaluation trials: load cells
        drift with temperature and use."""
        refused = None
        with self._safety("taring the force sensors"):
            try:
                self._tare_keeping_bus_alive()  # longer than the bus watchdog: the servos hear from us meanwhile
            except ForceTareError as e:  # a refusal stops nothing: the old zero stays, the pose is held
                refused = e
        self.timing.restart()  # the tare window is not a loop period
        if refused is not None:
            raise refused

    # --- control loop --------------------------------------------------------------------------------------------
    @check_if_not_connected
    def get_observation(self) -> dict[str, float]:
        self.spacing.before_read()  # after a slow read, the next sample waits its turn (`timing.SampleSpacing`)
        with self._safety("reading the gripper state"):
            started = time.monotonic()
            self.timing.tick(started)
            self._check_servo_state()  # first: a reset servo is named as such, not as an odd position
            self._poll_health(started)
            q = self._read_q()
            forces = self.force.read()
            self.spacing.after_read(started, time.monotonic())
            self._check_consistency(q, forces)
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
            now = time.monotonic()
            if now - self._last_state_check > spec.CONTROL_DT:  # no get_observation this period: stand in for it
                self._check_servo_state()
                self._poll_health(now)  # health and a pending start are judged for action-only loops too
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
