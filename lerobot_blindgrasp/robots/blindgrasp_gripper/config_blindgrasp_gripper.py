"""Configuration of the real gripper (`--robot.type=blindgrasp_gripper`): the paper's D'Claw-derived build by default,
a site's file in `robot_configs/`. Parsing also keeps what the script's command line says and LeRobot never hands the
robot (`command_line`: the policy, the loop's rate, the dataset), which the robot checks at connect.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from lerobot.robots.config import RobotConfig

from lerobot_blindgrasp import compat, spec
from lerobot_blindgrasp.hardware.force_board import ForceSensorConfig
from lerobot_blindgrasp.hardware.xm430 import (
    CURRENT_LIMIT_MAX_UNITS,
    CURRENT_UNIT_A,
    NO_LOAD_SPEED_RAD_S,
    STALL_CURRENT_A,
    amps_to_current_units,
)

# Baud rates an XM430 can be set to (its Baud_Rate register), bps.
DYNAMIXEL_BAUDRATES = (9600, 57_600, 115_200, 1_000_000, 2_000_000, 3_000_000, 4_000_000, 4_500_000)


@RobotConfig.register_subclass("blindgrasp_gripper")
@dataclass
class BlindgraspGripperConfig(RobotConfig):
    port: str = "/dev/ttyUSB0"  # the Dynamixel bus's serial port (a U2D2 or any USB-RS485/TTL adapter)
    # Must equal the servos' Baud_Rate register; D'Claw/ROBEL use 1 Mbps (factory default is 57 600).
    baudrate: int = 1_000_000
    # Servo ID per joint, in `spec.JOINT_NAMES` order (D'Claw convention 10, 11, 12 / 20, 21, 22 / 30, 31, 32).
    servo_ids: list[int] = field(default_factory=lambda: list(spec.SERVO_IDS))
    # Allowed joint range (rad) in `spec.JOINT_NAMES` order. Defaults to the sim's; a narrower range is allowed,
    # a wider one is refused (the policy never saw it).
    joint_lower: list[float] = field(default_factory=lambda: spec.JOINT_LOWER.tolist())
    joint_upper: list[float] = field(default_factory=lambda: spec.JOINT_UPPER.tolist())
    max_relative_target: float = spec.ACTION_BOUND_RAD  # |target - q_now| per step (rad): the paper's clip, again
    # CURRENT_POSITION (5) makes the current limit act as a torque limit, like the sim's actuator forcerange.
    # POSITION (3) would enforce the position limits in firmware instead but ignore Goal_Current.
    operating_mode: str = "CURRENT_POSITION"
    # Current limit (A). 2.3 A is the XM430-W350 stall current at 12 V (4.1 N m), the sim's torque limit.
    current_limit_a: float = STALL_CURRENT_A
    # Position loop gains (register units). 800/0/0 is the XM430 default, modelled by the sim's kp = 15 N m/rad.
    position_p_gain: int = 800
    position_i_gain: int = 0
    position_d_gain: int = 0
    profile_velocity: int = 0  # Profile_Velocity (0.229 rpm units); 0 = no profile, as in the sim
    bus_num_retry: int = 2  # extra tries of a failed bus transaction before a GripperBusError stop
    # The servos' own Bus_Watchdog (20 ms units): a servo that hears no instruction for this long stops where it is
    # until the robot re-arms it, which bounds how long the gripper moves after the host dies. 0 disables it.
    bus_watchdog_ms: int = 200
    # USB adapter latency timer (ms; FTDI/U2D2 default 16). dynamixel-sdk waits 2 x this + 2 ms for a reply, so
    # raise it on a loaded host or a slow USB hub instead of seeing timeouts.
    latency_timer_ms: int = 16
    # Plausibility of every position reading (`hardware/plausibility.py`): at most max_joint_speed_rad_s plus
    # plausibility_margin_rad between two readings, else read again up to plausibility_rereads times, then a stop.
    max_joint_speed_rad_s: float = NO_LOAD_SPEED_RAD_S
    plausibility_margin_rad: float = 0.1
    plausibility_rereads: int = 2
    # How far a load may push a torqued joint back past its goal: stall torque / kp = 4.1 / 15 = 0.27 rad at P gain
    # 800; a softer loop yields more.
    plausibility_backdrive_rad: float = 0.3
    # The control loop's rate (lerobot-record --dataset.fps, rollout --fps), which get_observation measures. An
    # overrun streak of max_overrun_s (the success rule's 1 s hold) stops the gripper; 0: never stop.
    loop_hz: float = spec.CONTROL_HZ
    max_overrun_s: float = spec.SUCCESS_HOLD_S
    # The control thread (`hardware/realtime.py`, set at connect): > 0 runs it SCHED_FIFO at this priority (1-99);
    # lock_memory keeps the process in RAM (mlockall). A refusal is a warning (docs/hardware.md, "The host PC").
    realtime_priority: int = 0
    lock_memory: bool = False
    health_every_n: int = 4  # control periods between reads of the servo health block (`servo_diagnostics.py`)
    calibration_min_motion_rad: float = 0.15  # how far (rad) a joint must move in the "positive" calibration pose
    disable_torque_on_disconnect: bool = True
    # A policy on the command line whose fit no file states is refused before any torque (`policy_contract.py`);
    # true runs it with a warning.
    allow_unverified_policy: bool = False
    force_sensor: ForceSensorConfig = field(default_factory=ForceSensorConfig)

    def __post_init__(self):
        super().__post_init__()
        self.command_line = compat.read_command_line()  # not a field: what the script's own flags say
        n = spec.NUM_JOINTS
        if len(self.servo_ids) != n or len(set(self.servo_ids)) != n:
            raise ValueError(f"servo_ids must be {n} distinct IDs in spec.JOINT_NAMES order, got {self.servo_ids}")
        for name, values in (("joint_lower", self.joint_lower), ("joint_upper", self.joint_upper)):
            if len(values) != n:
                raise ValueError(f"{name} needs {n} values, got {len(values)}")
        for k, (j, lo, hi) in enumerate(zip(spec.JOINT_NAMES, self.joint_lower, self.joint_upper, strict=True)):
            if not spec.JOINT_LOWER[k] <= lo < hi <= spec.JOINT_UPPER[k]:
                raise ValueError(f"{j}: limits [{lo}, {hi}] must lie inside the sim's [{spec.JOINT_LOWER[k]}, "
                                 f"{spec.JOINT_UPPER[k]}]")  # fmt: skip
        if self.baudrate not in DYNAMIXEL_BAUDRATES:
            raise ValueError(f"baudrate {self.baudrate} is not a Dynamixel rate {DYNAMIXEL_BAUDRATES}")
        if not self.port or not self.force_sensor.port:
            raise ValueError("port and force_sensor.port must name the serial devices")
        if self.plausibility_backdrive_rad < 0:
            raise ValueError("plausibility_backdrive_rad must be >= 0")
        if not (
            self.max_joint_speed_rad_s > 0 and self.plausibility_margin_rad > 0 and self.plausibility_rereads > 0
        ):
            raise ValueError(
                "need max_joint_speed_rad_s > 0, plausibility_margin_rad > 0, plausibility_rereads >= 1"
            )
        if not 1 <= self.health_every_n <= 100:
            raise ValueError("health_every_n must be in [1, 100] control periods")
        if not (self.loop_hz > 0 and self.max_overrun_s >= 0):
            raise ValueError("need loop_hz > 0 and max_overrun_s >= 0")
        if not 0 <= self.realtime_priority <= 99:
            raise ValueError("realtime_priority must be in [0, 99] (0: normal scheduling)")
        if self.bus_watchdog_ms % 20 or not 0 <= self.bus_watchdog_ms <= 127 * 20:
            raise ValueError("bus_watchdog_ms must be a multiple of 20 in [0, 2540] (0 disables the watchdog)")
        if not 1 <= self.latency_timer_ms <= 500:
            raise ValueError("latency_timer_ms must be in [1, 500]")
        if not 0 < self.max_relative_target <= spec.ACTION_BOUND_RAD:
            raise ValueError(f"max_relative_target must be in (0, {spec.ACTION_BOUND_RAD}] rad")
        if self.operating_mode not in ("CURRENT_POSITION", "POSITION"):
            raise ValueError("operating_mode must be CURRENT_POSITION or POSITION")
        if not 0 < amps_to_current_units(self.current_limit_a) <= CURRENT_LIMIT_MAX_UNITS:
            raise ValueError(f"current_limit_a must be in (0, {CURRENT_LIMIT_MAX_UNITS * CURRENT_UNIT_A:.2f}] A")
        fs = self.force_sensor
        if len(fs.scale_n_per_count) != spec.NUM_FORCES or len(fs.channel_map) != spec.NUM_FORCES:
            raise ValueError(f"force_sensor needs {spec.NUM_FORCES} scales and channel_map entries")
        if not all(math.isfinite(x) and x != 0 for x in fs.scale_n_per_count):
            raise ValueError(
                f"force_sensor.scale_n_per_count must be finite and non-zero, not {fs.scale_n_per_count}"
            )
        positive = ("tare_s", "stale_timeout_s", "connect_timeout_s", "overload_n", "tare_max_std_n",
                    "tare_max_shift_n", "negative_fault_n")  # fmt: skip
        if bad := [n for n in positive if not getattr(fs, n) > 0]:
            raise ValueError(f"force_sensor.{bad} must be > 0")
        if not fs.min_rate_hz >= 0:
            raise ValueError("force_sensor.min_rate_hz must be >= 0 (0: the rate is not checked)")
        if fs.frozen_frames < 0 or fs.frozen_frames == 1:
            raise ValueError("force_sensor.frozen_frames must be 0 (off) or >= 2")
        if len(set(fs.channel_map)) != spec.NUM_FORCES or not all(0 <= c < 8 for c in fs.channel_map):
            raise ValueError(f"force_sensor.channel_map needs distinct channels 0..7, not {fs.channel_map}")
