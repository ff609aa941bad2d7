"""The real gripper: nine XM430-W350 on one Dynamixel bus plus three fingertip load cells, in lifecycle order like
LeRobot's `koch_follower`; observation and action are `spec`'s (names, order, rad and N), as in the sim demos. It
holds the objects that check it (`hardware/`), each given what it needs, and the safety `latch` (`latch.py`).
"""

from __future__ import annotations

import logging
import time
from contextlib import contextmanager
from functools import cached_property
from operator import itemgetter

import numpy as np
from lerobot.motors import Motor, MotorNormMode
from lerobot.motors.dynamixel import OperatingMode
from lerobot.robots.robot import Robot
from lerobot.utils.decorators import check_if_already_connected, check_if_not_connected
from lerobot.utils.errors import DeviceNotConnectedError

from lerobot_blindgrasp import policy_contract, spec
from lerobot_blindgrasp.hardware import realtime, xm430
from lerobot_blindgrasp.hardware.consistency import ConsistencyMonitor
from lerobot_blindgrasp.hardware.dynamixel import RetryingDynamixelBus, latency_timer
from lerobot_blindgrasp.hardware.force import force_bias_warning
from lerobot_blindgrasp.hardware.force_board import ForceTareError, force_calibration
from lerobot_blindgrasp.hardware.loop_timing import PeriodMonitor, SampleSpacing
from lerobot_blindgrasp.hardware.period_checks import PeriodChecks
from lerobot_blindgrasp.hardware.plausibility import PositionGate
from lerobot_blindgrasp.hardware.servo_diagnostics import ServoHealth
from lerobot_blindgrasp.hardware.servo_registers import ServoRegisters
from lerobot_blindgrasp.policy_contract import PolicyMismatchError

from . import interactive
from . import servo_calibration as calib
from .config_blindgrasp_gripper import BlindgraspGripperConfig
from .errors import ForceOverloadError, GripperBusError, GripperSafetyStop
from .keepalive import feeding_the_bus
from .latch import SafetyLatch
from .recording_space import RecordingSpace
from .servo_calibration import rad_to_ticks, ticks_to_rad
from .starts import EpisodeStarts, Starts

logger = logging.getLogger(__name__)


class BlindgraspGripper(Robot):
    """D'Claw-derived three-finger gripper (`--robot.type=blindgrasp_gripper`)."""

    config_class = BlindgraspGripperConfig
    name = "blindgrasp_gripper"

    def __init__(self, config: BlindgraspGripperConfig):
        self.config = config
        self.joints = list(spec.JOINT_NAMES)
        self.calibration_error: calib.CalibrationFileError | None = None
        super().__init__(config)  # loads and checks the calibration file through _load_calibration
        self.bus = RetryingDynamixelBus(
            port=config.port,
            motors={
                j: Motor(i, xm430.MODEL, MotorNormMode.DEGREES) for j, i in zip(self.joints, config.servo_ids)
            },
            calibration=self.calibration,
            baudrate=config.baudrate,
            num_retry=config.bus_num_retry,
            latency_timer_ms=config.latency_timer_ms,
        )
        self.force = config.force_sensor.reader()
        self.gate = PositionGate(
            speed_ticks_s=config.max_joint_speed_rad_s / xm430.RAD_PER_TICK,
            margin_ticks=config.plausibility_margin_rad / xm430.RAD_PER_TICK,
            backdrive_ticks=config.plausibility_backdrive_rad / xm430.RAD_PER_TICK,
            rereads=config.plausibility_rereads,
        )
        current = xm430.amps_to_current_units(config.current_limit_a)
        protection = {**xm430.NO_HOST_PROTECTION, "Current_Limit": current}
        self.registers = ServoRegisters(self.bus, self.joints, protection)
        self.health = ServoHealth(self.joints)  # OK / WARN / ERROR per servo item
        self.consistency = ConsistencyMonitor.at_p_gain(config.position_p_gain)  # tip forces against the servos
        self.checks = PeriodChecks(self.registers, self.health, self.consistency, self.gate, config.health_every_n,
                                   to_rad=ticks_to_rad)  # fmt: skip
        self.timing = PeriodMonitor(1.0 / config.loop_hz, config.max_overrun_s, what=f"{self.name} control loop")
        self.spacing = SampleSpacing(1.0 / config.loop_hz)  # no two samples closer than the contract allows
        self.episodes = EpisodeStarts()  # lerobot-record's episode announcements
        self.latch = SafetyLatch(str(self), self.bus, self.force, config.servo_ids,
                                 on_torque_off=self._forget_goals, on_close=self.episodes.uninstall,
                                 report=self.consistency.report)  # fmt: skip
        self.lower, self.upper = np.asarray([config.joint_lower, config.joint_upper], dtype=np.float64)
        self.starts = Starts(self.episodes, self.timing.pause_s)  # when health is judged at the start levels
        self.cameras: dict = {}  # vision-free by design; lerobot-record and lerobot-rollout still read it

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
        self._check_policy()  # a policy named on the script's command line must fit, before any port opens
        features = (self.action_features, self.observation_features)
        self.starts.recording = RecordingSpace.of(self.config.command_line, *features)  # room on disk, each start
        if self.calibration_error is not None and calibrate:
            raise self.calibration_error  # before the port is even opened: nothing can move on a wrong frame
        if calibrate:
            calib.refuse_unattended(self.calibration, self.calibration_fpath, self.id)  # nobody to answer prompts
        latency_timer.ensure_low_latency(self.config.port, self.config.force_sensor.port)  # USB adapters at 1 ms
        self.host_setup = realtime.prepare_host(self.config)  # before any thread starts: threads inherit it
        with self.latch.guard("connecting"):
            self._forget_goals()
            force_calibration.apply(self.force, self.calibration_dir, self.id)  # <id>.force.json, if measured
            self.force.start()  # both ports exclusive before the first byte goes out: a second owner is refused
            self.bus.connect()  # pings all nine, with retries; names a Status_Return_Level that hides replies
            self.latch.arm()
            self.episodes.install()
            self.checks.at_connect(self._trusted_ticks)  # state, setup; health at the start levels, before torque
            self.starts.restart()
            if not self._bring_up(calibrate):
                return
        self.timing.restart()
        self.spacing.restart()
        logger.info("%s connected (force tare %s counts).", self, np.round(self.force.offset).tolist())

    def _check_policy(self) -> None:
        """The checkpoint the script runs (`command_line.policy_path`), at the rate its own flags give."""
        cl, loop_hz = self.config.command_line, float(self.config.loop_hz)
        fps, source = (cl.fps, f"--{cl.fps_flag}") if cl.fps is not None else (loop_hz, "the robot's loop_hz")
        allow = self.config.allow_unverified_policy
        checked = policy_contract.check_named(cl.policy_path, self.name, fps, source, allow_unverified=allow)
        if checked and fps != loop_hz:
            raise PolicyMismatchError(f"{source}={fps:g} but the robot's loop_hz is {self.config.loop_hz:g}: set "
                                      "--robot.loop_hz to the loop's rate (it measures the loop against it).")  # fmt: skip

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

    def _load_calibration(self, fpath=None) -> None:
        ids = dict(zip(self.joints, self.config.servo_ids, strict=True))
        fix = f"lerobot-calibrate --robot.type={self.name} --robot.id={self.id}"
        self.calibration, self.calibration_error = calib.load_checked(
            fpath or self.calibration_fpath, ids, self.config.joint_lower, self.config.joint_upper, fix
        )

    def _save_calibration(self, fpath=None) -> None:
        calib.save_atomic(self.calibration, fpath or self.calibration_fpath)

    def calibrate(self) -> None:
        with self.latch.guard("calibrating"):
            self._forget_goals()  # readings change frame with Drive_Mode and Homing_Offset
            self.bus.disable_torque()
            interactive.calibrate_servos(self)  # the file to the servos, or two poses by hand

    def configure(self) -> None:
        mode = OperatingMode[self.config.operating_mode].value
        current = xm430.amps_to_current_units(self.config.current_limit_a)
        with self.latch.guard("configuring the servos"):
            self.registers.expected = {}
            self.bus.disable_torque()
            self.bus.configure_motors()  # Return_Delay_Time 0: status packets come back without the 500 us delay
            self.checks.restore()  # startup torque, no-host protection
            gains = {f"Position_{k}_Gain": getattr(self.config, f"position_{k.lower()}_gain") for k in "PID"}
            settings = {"Operating_Mode": mode, "Current_Limit": current, "Goal_Current": current, **gains}
            self.registers.write_settings({**settings, "Profile_Velocity": self.config.profile_velocity})
            self._enable_torque_holding_pose()
            watchdog = self.config.bus_watchdog_ms // xm430.WATCHDOG_UNIT_MS
            expected = {"Torque_Enable": 1, **gains, "Bus_Watchdog": watchdog, "Goal_Current": current}
            self.registers.expected = expected

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
        self.registers.torque_on_holding(present, self.config.bus_watchdog_ms // xm430.WATCHDOG_UNIT_MS)
        self.gate.goal = ticks

    def setup_motors(self) -> None:
        interactive.setup_motors(self)

    # --- between trials ------------------------------------------------------------------------------------------
    @contextmanager
    def torque_disabled(self):
        """Torque off for the block (e.g. to move the fingers by hand), then on again holding the new pose. The
        per-period state check knows the torque is off on purpose."""
        expected = self.registers.expected
        with self.latch.guard("turning the torque off"):
            self.registers.expected = {}
            self.gate.goal = None  # free: a hand may move the joints faster than the servos
            self.bus.disable_torque()
        yield
        if self.is_connected:  # a fault inside the block already stopped the gripper
            with self.latch.guard("turning the torque back on"):
                self._enable_torque_holding_pose()
                self.registers.expected = expected
            self.timing.restart()

    @check_if_not_connected
    def tare_forces(self) -> None:
        """Re-zero the fingertip sensors (fingertips touching nothing), e.g. between evaluation trials: load cells
        drift with temperature and use. The tare outlasts the bus watchdog: the servos hear from us meanwhile."""
        refused = None
        with self.latch.guard("taring the force sensors"):
            try:
                feeding_the_bus(lambda: self.force.tare(self.config.force_sensor.tare_s), self._check_servo_state)
            except ForceTareError as e:  # a refusal stops nothing: the old zero stays, the pose is held
                refused = e
        self.timing.restart()  # the tare window is not a loop period
        if refused is not None:
            raise refused

    @check_if_not_connected
    def keep_alive(self) -> None:
        """One servo state check in a wait outside the loop, every `KEEPALIVE_S`: the bus watchdog stays fed."""
        with self.latch.guard("keeping the bus alive while waiting"):
            self._check_servo_state()

    @check_if_not_connected
    def check_health_before_start(self) -> None:
        """Before a trial or an episode: refuse (torque off, named error) when a servo is too close to a limit."""
        with self.latch.guard("checking servo health before a start"):
            self.checks.check_health(start=True)

    # --- control loop --------------------------------------------------------------------------------------------
    @check_if_not_connected
    def get_observation(self) -> dict[str, float]:
        self.spacing.before_read()  # after a slow read, the next sample waits its turn (`SampleSpacing`)
        with self.latch.guard("reading the gripper state"):
            started = time.monotonic()
            self.timing.tick(started)
            self._check_servo_state()  # first: a reset servo is named as such, not as an odd position
            self.checks.poll_health(start=self.starts.pending(started))
            q = self._read_q()
            forces = self.force.read()
            self.spacing.after_read(started, time.monotonic())
            self.checks.consistency_after(q, forces)
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
        """Absolute joint targets (rad), clipped to the joint limits, then to +-max_relative_target around the present
        position (last, so a joint outside its limits comes back at that rate, never in one jump), sent with one
        sync write; returns the targets sent (after tick rounding)."""
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
        with self.latch.guard("sending joint targets"):
            now = time.monotonic()
            if now - self.registers.last_check > spec.CONTROL_DT:  # no get_observation this period: stand in
                self._check_servo_state()
                self.checks.poll_health(start=self.starts.pending(now))  # for action-only loops too
            q = self._read_q()  # the trusted estimate: the bound is never centred on an unchecked reading
            bound = self.config.max_relative_target
            target = np.clip(np.clip(target, self.lower, self.upper), q - bound, q + bound)
            ticks = {j: rad_to_ticks(t) for j, t in zip(self.joints, target)}
            self.bus.sync_write("Goal_Position", ticks)
            self.gate.goal = np.array([ticks[j] for j in self.joints], dtype=np.float64)
        return {f"{j}.pos": ticks_to_rad(ticks[j]) for j in self.joints}

    def disconnect(self) -> None:
        if not self.is_connected:
            if self.latch.stopped_while is not None:
                # The latch stopped and closed it. LeRobot's scripts disconnect in a `finally` (and __exit__): an
                # error here would end the traceback on "not connected" instead of on the fault that stopped it.
                return
            raise DeviceNotConnectedError(f"{type(self).__name__} is not connected. Run `.connect()` first.")
        if not self.config.disable_torque_on_disconnect:
            self.latch.close()
            return
        unconfirmed = self.latch.stop()
        if unconfirmed:
            msg = f"Disconnected, but servo IDs {unconfirmed} did not confirm torque off: cut the power."
            raise GripperBusError(msg)
        logger.info("%s disconnected, torque off.", self)

    # --- shared by the calls above -------------------------------------------------------------------------------
    def _forget_goals(self) -> None:  # torque off: nothing is expected, no reading trusted without a second
        self.registers.expected = {}
        self.gate.forget()

    def _trusted_ticks(self, *, free: bool | None = None) -> np.ndarray:
        """Present_Position of all nine through the plausibility gate (free: the torque is off)."""
        in_order = itemgetter(*self.joints)  # the gate's readings are in joint order
        read = lambda: np.array(in_order(self.bus.sync_read("Present_Position")), dtype=np.float64)  # noqa: E731
        return self.gate.read(read, self.joints, free=not self.registers.expected if free is None else free)

    def _read_q(self) -> np.ndarray:
        return np.array([ticks_to_rad(t) for t in self._trusted_ticks()])

    def _check_servo_state(self) -> None:
        self.checks.state(self._trusted_ticks)
