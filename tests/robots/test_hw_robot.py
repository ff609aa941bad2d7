"""The real-gripper robot against the emulated Dynamixel bus and force-sensor stream (no mocks of our classes).

Round trips are checked in physical units against the emulator's ground truth (shaft positions and how each servo
is mounted), and every fault must end with torque off in the emulator's registers and a clear error.
"""

from __future__ import annotations

import math
import random
import time
from pathlib import Path

import draccus
import numpy as np
import pytest
from emulators.loop import as_q, settle
from emulators.rig import MOUNT_SIGN
from lerobot.datasets.pipeline_features import aggregate_pipeline_dataset_features, create_initial_features
from lerobot.processor import make_default_processors
from lerobot.robots.config import RobotConfig
from lerobot.utils.feature_utils import combine_feature_dicts

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.emulators.control_table import HW_OVERHEATING, HW_OVERLOAD
from lerobot_blindgrasp.hardware.xm430 import (
    CURRENT_UNIT_A,
    RAD_PER_TICK,
    amps_to_current_units,
    torque_at_current_nm,
)
from lerobot_blindgrasp.robots.blindgrasp_gripper import BlindgraspGripper, BlindgraspGripperConfig
from lerobot_blindgrasp.robots.blindgrasp_gripper.errors import (
    ForceOverloadError,
    ForceSensorError,
    GripperBusError,
    GripperHardwareError,
)
from lerobot_blindgrasp.robots.blindgrasp_gripper.servo_calibration import rad_to_ticks

ROOT = Path(__file__).resolve().parents[2]
TICK = RAD_PER_TICK


def _zero_action() -> dict[str, float]:
    return dict.fromkeys(spec.ACTION_NAMES, 0.0)


# --- contracts that need no hardware -----------------------------------------------------------------------------
def test_features_give_the_sim_dataset_schema(tmp_path):
    robot = BlindgraspGripper(BlindgraspGripperConfig(id="x", calibration_dir=tmp_path))
    assert list(robot.observation_features) == list(spec.STATE_NAMES)
    assert list(robot.action_features) == list(spec.ACTION_NAMES)
    assert set(robot.observation_features.values()) == {float}
    # Exactly what lerobot-record does with them (identity processors from the CLI).
    teleop_p, _, obs_p = make_default_processors()
    features = combine_feature_dicts(
        aggregate_pipeline_dataset_features(teleop_p, create_initial_features(action=robot.action_features),
                                            use_videos=False),
        aggregate_pipeline_dataset_features(obs_p, create_initial_features(observation=robot.observation_features),
                                            use_videos=False),
    )  # fmt: skip
    assert features == spec.dataset_features()


def test_current_limit_is_the_sims_torque_limit():
    from lerobot_blindgrasp.sim.gripper import PhysicsOptions

    cfg = BlindgraspGripperConfig()
    units = amps_to_current_units(cfg.current_limit_a)
    assert units == 855  # 2.3 A / 2.69 mA
    assert torque_at_current_nm(units * CURRENT_UNIT_A) == pytest.approx(PhysicsOptions().torque_limit, rel=0.01)


def test_robot_config_file_parses_to_the_defaults():
    with open(ROOT / "robot_configs" / "blindgrasp_gripper.yaml") as f, draccus.config_type("yaml"):
        cfg = draccus.load(RobotConfig, f)
    assert isinstance(cfg, BlindgraspGripperConfig)
    default = BlindgraspGripperConfig()
    for name in ("servo_ids", "joint_lower", "joint_upper", "max_relative_target", "current_limit_a", "baudrate",
                 "position_p_gain", "operating_mode"):  # fmt: skip
        assert getattr(cfg, name) == pytest.approx(getattr(default, name)), name
    assert cfg.servo_ids == list(spec.SERVO_IDS)


def test_config_refuses_limits_wider_than_the_sim():
    lower = spec.JOINT_LOWER.tolist()
    lower[1] -= 0.1
    with pytest.raises(ValueError, match="ff_j11"):
        BlindgraspGripperConfig(joint_lower=lower)


# --- calibration, observation, action ----------------------------------------------------------------------------
def test_calibration_maps_ticks_to_the_sim_zero_and_direction(rig, robot):
    cal = robot.calibration
    assert [cal[j].drive_mode for j in spec.JOINT_NAMES] == [0 if s > 0 else 1 for s in MOUNT_SIGN]
    for j, i in zip(spec.JOINT_NAMES, spec.SERVO_IDS, strict=True):  # the servos hold what the file says
        servo = rig.dxl.servos[i]
        assert (servo.get("Drive_Mode"), servo.get("Homing_Offset")) == (cal[j].drive_mode, cal[j].homing_offset)
        assert servo.get("Min_Position_Limit") == rad_to_ticks(spec.JOINT_LOWER[spec.JOINT_NAMES.index(j)])
    assert robot.calibration_fpath.is_file() and robot.is_calibrated
    # Torque off, move by hand to random poses: the observation is the true joint angle within a tick.
    rng = np.random.default_rng(1)
    with robot.torque_disabled():
        assert not rig.dxl.any_torque()
        for _ in range(3):
            q = rng.uniform(spec.JOINT_LOWER, spec.JOINT_UPPER)
            rig.hand_move(q)
            np.testing.assert_allclose(as_q(robot.get_observation()), q, atol=1.01 * TICK)
    # Torque back on, holding the pose the hand left: nothing moves.
    time.sleep(0.05)
    assert all(rig.dxl.torque_enabled(i) for i in spec.SERVO_IDS)
    np.testing.assert_allclose(rig.true_q(), q, atol=1.01 * TICK)


def test_stored_calibration_is_written_to_fresh_servos(rig, robot, tmp_path):
    """Same calibration file, servos with factory EEPROM (e.g. after a servo swap): connect restores it."""
    robot.disconnect()
    for servo in rig.dxl.servos.values():
        servo.set("Homing_Offset", 0)
        servo.set("Drive_Mode", 0)
    rig.hand_move(spec.HOME_POSE)
    again = BlindgraspGripper(rig.robot_config(robot.calibration_dir))
    again.connect()  # no input() needed: the file wins
    try:
        np.testing.assert_allclose(as_q(again.get_observation()), spec.HOME_POSE, atol=1.01 * TICK)
    finally:
        again.disconnect()


def test_connect_configures_current_limit_gains_and_holds_pose(rig, robot):
    for servo in rig.dxl.servos.values():
        assert servo.get("Torque_Enable") == 1
        assert servo.get("Operating_Mode") == 5  # current-based position: the current limit is a torque limit
        assert servo.get("Current_Limit") == servo.get("Goal_Current") == 855
        gains = (servo.get("Position_P_Gain"), servo.get("Position_I_Gain"), servo.get("Position_D_Gain"))
        assert gains == (800, 0, 0)
        assert servo.get("Return_Delay_Time") == 0
    # The operator left the fingers in the calibration's positive pose; torque-on did not move them.
    np.testing.assert_allclose(rig.true_q(), 0.3, atol=2 * TICK)


def test_act_and_observe_round_trip_in_radians(rig, robot):
    target = np.array([0.1, 0.5, 0.2, 0.4, 0.1, 0.2, 0.05, 0.45, 0.0])  # within 0.3 rad of the start (0.3 rad)
    action = dict(zip(spec.ACTION_NAMES, target.tolist(), strict=True))
    sent = robot.send_action(action)
    np.testing.assert_allclose([sent[k] for k in spec.ACTION_NAMES], target, atol=0.51 * TICK)
    obs = settle(robot, action)
    np.testing.assert_allclose(as_q(obs), target, atol=1.01 * TICK)
    np.testing.assert_allclose(rig.true_q(), target, atol=1.01 * TICK)
    assert [obs[k] for k in spec.FORCE_FEATURE_NAMES] == [0.0, 0.0, 0.0]  # tared, under the deadband


def test_send_action_clips_to_the_step_bound_and_the_joint_limits(rig, robot):
    q0 = as_q(robot.get_observation())
    direction = np.array([1, -1, 1, -1, 1, -1, 1, -1, 1])
    far = dict(zip(spec.ACTION_NAMES, (q0 + direction).tolist(), strict=True))
    out = robot.send_action(far)
    sent = np.array([out[k] for k in spec.ACTION_NAMES])
    # 0.3 rad toward the target, except where a joint limit comes first (the abduction joints at 0.3 + 0.3 > 0.48).
    expected = np.clip(q0 + spec.ACTION_BOUND_RAD * direction, spec.JOINT_LOWER, spec.JOINT_UPPER)
    np.testing.assert_allclose(sent, expected, atol=1.01 * TICK)
    # What was returned is what went on the wire (a sync write has no reply: give the emulator a moment).
    expected_goal = [rad_to_ticks(v) for v in sent]
    deadline = time.monotonic() + 1.0
    while [rig.dxl.servos[i].get("Goal_Position") for i in spec.SERVO_IDS] != expected_goal:
        assert time.monotonic() < deadline, "the sync write never reached the servos"
        time.sleep(0.005)
    # Walk toward +10 rad: every joint ends at its upper limit, never past it.
    up = dict.fromkeys(spec.ACTION_NAMES, 10.0)
    obs = settle(robot, up, steps=25)
    np.testing.assert_allclose(as_q(obs), spec.JOINT_UPPER, atol=1.01 * TICK)


def test_malformed_actions_send_nothing(rig, robot):
    before = [s.get("Goal_Position") for s in rig.dxl.servos.values()]
    with pytest.raises(KeyError, match="ff_j10.pos"):
        robot.send_action(dict.fromkeys(spec.ACTION_NAMES[1:], 0.0))
    with pytest.raises(ValueError, match="Non-finite"):
        robot.send_action({**_zero_action(), "mf_j21.pos": math.nan})
    time.sleep(0.05)  # a sync write has no reply: leave time for one to land if it had been sent
    assert [s.get("Goal_Position") for s in rig.dxl.servos.values()] == before
    assert robot.is_connected and rig.dxl.any_torque()  # a caller bug is not a hardware fault


def test_forces_are_tared_scaled_and_deadbanded(rig, robot):
    rig.force.forces_n = np.array([1.5, 0.05, 3.0])
    time.sleep(0.05)
    obs = robot.get_observation()
    assert obs["ff_tip.force"] == pytest.approx(1.5, abs=0.03)
    assert obs["mf_tip.force"] == 0.0  # 0.05 N is under the 0.1 N threshold, as in the sim
    assert obs["th_tip.force"] == pytest.approx(3.0, abs=0.03)


def test_force_stream_survives_dropouts_garbage_and_bad_crcs(rig, robot):
    """Lost frames, line noise and bad CRCs from a seeded generator. Their rates leave the reader's rate floor a
    margin: even if every frame behind garbage were lost too, 80/s x (1 - 0.12)^2 = 62/s of fresh frames is 1.55 x
    the 40/s floor, and a 16-interval window of that stream falls under 40/s only ~4.6 standard deviations out."""
    floor, drop, garbage = robot.force.min_rate_hz, 0.12, 0.12
    assert rig.force.period**-1 * (1 - drop) * (1 - garbage) >= 1.5 * floor
    rig.force.rng = random.Random(57)  # the pattern of faults, whatever the board sent before
    rig.force.drop_prob, rig.force.garbage_prob, rig.force.corrupt_next = drop, garbage, 5
    rig.force.forces_n = np.array([2.0, 2.0, 2.0])
    # A run of lost frames plus a busy host's delay can outlast the default stale timeout by chance; staleness has
    # tests of its own, and this one is about surviving the damage.
    robot.force.stale_timeout_s = 0.4
    for _ in range(40):
        obs = robot.get_observation()
        time.sleep(0.01)
    assert [obs[k] for k in spec.FORCE_FEATURE_NAMES] == pytest.approx([2.0, 2.0, 2.0], abs=0.03)
    reader = robot.force
    assert reader.dropped_frames > 0 and reader.parser.crc_errors >= 1 and reader.parser.garbage_bytes > 0


def test_transient_bus_errors_are_retried(rig, robot):
    rig.dxl.corrupt_responses[12] = 2  # bus_num_retry = 2: the third try succeeds
    rig.dxl.drop_responses[30] = 1
    robot.get_observation()
    robot.send_action(_zero_action())
    assert robot.is_connected and all(rig.dxl.torque_enabled(i) for i in spec.SERVO_IDS)


def test_disconnect_turns_the_torque_off(rig, robot):
    robot.disconnect()
    assert not rig.dxl.any_torque() and not robot.is_connected


# --- faults: each ends with the torque off and a clear error -----------------------------------------------------
def _assert_stopped(rig, robot, exclude=()):
    assert not robot.is_connected  # latched: the ports are closed
    assert not any(rig.dxl.torque_enabled(i) for i in spec.SERVO_IDS if i not in exclude)


def test_persistent_timeouts_stop_the_gripper(rig, robot):
    rig.dxl.drop_responses[21] = 10_000
    # The state block is read first in each period, so its read is the one that fails.
    with pytest.raises(GripperBusError, match=r"(?s)3 times.*Torque_Enable..Goal_Current.*servo IDs \[21\]"):
        robot.get_observation()
    _assert_stopped(rig, robot)  # the broadcast torque-off reached 21 too, it just cannot answer


def test_persistent_corrupt_status_packets_stop_the_gripper(rig, robot):
    rig.dxl.corrupt_responses[12] = 10_000
    with pytest.raises(GripperBusError, match="Incorrect status packet"):
        robot.send_action(_zero_action())
    _assert_stopped(rig, robot)


def test_missing_servo_at_connect_is_named(rig, tmp_path, monkeypatch):
    monkeypatch.setattr("builtins.input", rig.calibration_inputs())
    r = BlindgraspGripper(rig.robot_config(tmp_path))
    r.connect()
    r.disconnect()
    rig.dxl.missing_ids.add(22)
    r = BlindgraspGripper(rig.robot_config(tmp_path))
    with pytest.raises(GripperBusError, match=r"missing IDs \[22\]"):
        r.connect()
    _assert_stopped(rig, r)


def test_servo_lost_while_running(rig, robot):
    rig.dxl.missing_ids.add(31)
    with pytest.raises(GripperBusError, match=r"NOT confirmed by servo IDs \[31\]: cut the servo power"):
        robot.send_action(_zero_action())
    _assert_stopped(rig, robot, exclude=(31,))


@pytest.mark.parametrize("bits,text", [(HW_OVERLOAD, "overload"), (HW_OVERHEATING, "overheating")])
def test_servo_hardware_error_stops_everything(rig, robot, bits, text):
    rig.dxl.set_hardware_error(11, bits)
    with pytest.raises(GripperHardwareError, match=rf"ff_j11 \(ID 11\): {text}.*Torque is off on all servos"):
        robot.get_observation()
    _assert_stopped(rig, robot)


def test_fingertip_overload_stops(rig, robot):
    limit = robot.config.force_sensor.overload_n
    rig.force.forces_n = np.array([0.0, limit + 15.0, 0.0])
    time.sleep(0.05)
    with pytest.raises(ForceOverloadError, match=rf"mf_tip.*> {limit:.1f} N.*Torque is off"):
        robot.get_observation()
    _assert_stopped(rig, robot)


def test_stalled_force_stream_stops(rig, robot):
    rig.force.paused = True
    time.sleep(0.25)
    with pytest.raises(ForceSensorError, match="stale"):
        robot.get_observation()
    _assert_stopped(rig, robot)


def test_force_channel_fault_stops(rig, robot):
    rig.force.status = 0b100
    time.sleep(0.05)
    with pytest.raises(ForceSensorError, match="th_tip"):
        robot.get_observation()
    _assert_stopped(rig, robot)


def test_no_force_sensor_fails_connect_with_torque_off(rig, tmp_path, monkeypatch):
    monkeypatch.setattr("builtins.input", rig.calibration_inputs())
    rig.force.paused = True
    r = BlindgraspGripper(rig.robot_config(tmp_path))
    with pytest.raises(ForceSensorError, match="No valid force-sensor frame"):
        r.connect()
    _assert_stopped(rig, r)


def test_hardware_error_present_at_connect_is_reported(rig, tmp_path, monkeypatch):
    monkeypatch.setattr("builtins.input", rig.calibration_inputs())
    rig.dxl.set_hardware_error(32, HW_OVERLOAD)
    r = BlindgraspGripper(rig.robot_config(tmp_path))
    with pytest.raises(GripperHardwareError, match=r"th_j32 \(ID 32\): overload"):
        r.connect()
    _assert_stopped(rig, r)


def test_position_mode_keeps_the_firmware_limits_happy(rig, tmp_path, monkeypatch):
    """operating_mode=POSITION: the firmware enforces Min/Max_Position_Limit (the joint limits) itself."""
    monkeypatch.setattr("builtins.input", rig.calibration_inputs())
    r = BlindgraspGripper(rig.robot_config(tmp_path, operating_mode="POSITION"))
    r.connect()
    try:
        assert {s.get("Operating_Mode") for s in rig.dxl.servos.values()} == {3}
        obs = settle(r, dict.fromkeys(spec.ACTION_NAMES, -10.0), steps=25)
        np.testing.assert_allclose(as_q(obs), spec.JOINT_LOWER, atol=1.01 * TICK)
    finally:
        r.disconnect()
