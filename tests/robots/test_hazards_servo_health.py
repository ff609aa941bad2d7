"""Hazards of the XM430's health block, Present_Current(126)..Present_Temperature(146), judged against each servo's
own Temperature_Limit(31) (docs/hardware.md, "Hazard analysis", table "XM430-W350 control table": Present_Current,
Present_Input_Voltage, Present_Temperature, Temperature_Limit; the levels table above it). Servo health
(`hardware/servo_diagnostics.py`) against the emulated XM430's temperature, supply and firmware
(`emulators/servo_health.py`): warnings with joint and value, refused starts, and named stops with the torque off
before the firmware's own shutdown; the level rules alone on readings given by hand."""

from __future__ import annotations

import json
import logging
import time

import numpy as np
import pytest
from dynamixel_sdk import robotis_def as dx
from emulators.harness import connect_gripper, trial_env
from emulators.loop import hold, stopped

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.emulators.dynamixel import EmulatedServo
from lerobot_blindgrasp.envs.real_trial import RealGraspEnv
from lerobot_blindgrasp.hardware import xm430
from lerobot_blindgrasp.hardware.servo_diagnostics import ERROR, OK, WARN, ServoHealth, ServoStallError
from lerobot_blindgrasp.robots.blindgrasp_gripper import BlindgraspGripper
from lerobot_blindgrasp.robots.blindgrasp_gripper.errors import (
    GripperHardwareError,
    GripperHealthError,
    GripperStallError,
)

JOINTS = ["ff_j10"]


def _block(temp=35, volts=12.0, current=0) -> dict:
    return {"ff_j10": {"Present_Temperature": temp, "Present_Input_Voltage": round(volts * 10),
                       "Present_Current": current & 0xFFFF}}  # fmt: skip


def test_the_emulated_firmware_shuts_down_as_the_datasheet_says():
    servo = EmulatedServo(10)
    servo.set("Torque_Enable", 1)
    servo.health.supply.open_v = 9.0  # below Min_Voltage_Limit 9.5 V: flagged, torque stays (not in Shutdown 0x34)
    servo.step(0.01)
    assert servo.get("Hardware_Error_Status") == 0x01 and servo.get("Torque_Enable") == 1
    servo.health.temperature_c = 80.2  # Temperature_Limit 80: overheating, in Shutdown: torque off
    servo.step(0.01)
    assert servo.get("Hardware_Error_Status") & 0x04 and servo.get("Torque_Enable") == 0


def test_the_health_block_is_read_every_n_periods(rig, robot):
    """The bus budget: one extra 21-byte sync read every `health_every_n` (4) periods, nothing else."""
    robot.get_observation()
    before = rig.dxl.instruction_counts.get(dx.INST_SYNC_READ, 0)
    for _ in range(8):
        robot.get_observation()
    # per period: the state block and the positions; plus 2 health reads in 8 periods
    assert rig.dxl.instruction_counts[dx.INST_SYNC_READ] - before == 8 * 2 + 2


# --- Present_Temperature and Temperature_Limit ----------------------------------------------------------------
def test_a_warm_servo_is_warned_with_its_joint_and_value(rig, robot, caplog):
    rig.servo("mf_j21").health.temperature_c = 66.0
    with caplog.at_level(logging.WARNING):
        hold(robot, 6)
    assert "WARN mf_j21 temperature: 66 degC (Temperature_Limit 80, stop at 77): nearing the limit" in caplog.text
    assert robot.is_connected


def test_a_hot_servo_refuses_the_start_before_any_torque(rig, tmp_path, monkeypatch):
    monkeypatch.setattr("builtins.input", rig.calibration_inputs())
    rig.servo("th_j31").health.temperature_c = 75.0  # 5 degC under the firmware's limit
    robot = BlindgraspGripper(rig.robot_config(tmp_path / "cal"))
    with pytest.raises(GripperHealthError, match=r"Refused to start: th_j31 temperature 75 degC"):
        robot.connect()
    assert stopped(rig, robot)


def test_the_margins_follow_the_servos_own_temperature_limit(rig, tmp_path, monkeypatch):
    """Temperature_Limit lowered to 70 degC in EEPROM: the firmware stops at 70, so 63 degC must not start."""
    rig.servo("ff_j12").set("Temperature_Limit", 70)
    rig.servo("ff_j12").health.temperature_c = 63.0
    with pytest.raises(
        GripperHealthError, match=r"ff_j12 temperature 63 degC \(start needs < 62, Temperature_Limit 70"
    ):
        connect_gripper(rig, tmp_path, monkeypatch)
    assert not rig.dxl.any_torque()


def test_a_trial_does_not_start_with_a_servo_near_its_limit(rig, robot):
    robot.check_health_before_start()  # healthy: nothing happens
    rig.servo("ff_j10").health.temperature_c = 73.0
    with pytest.raises(GripperHealthError, match=r"Refused to start: ff_j10 temperature 73 degC"):
        robot.check_health_before_start()
    assert stopped(rig, robot)


def test_over_temperature_stops_before_the_firmware_does(rig, robot):
    servo = rig.servo("ff_j11")
    servo.health.temperature_c = 77.3
    with pytest.raises(GripperHealthError, match=r"ff_j11 temperature: 77 degC .*too hot.*before the firmware"):
        hold(robot, 10)
    assert stopped(rig, robot) and servo.get("Hardware_Error_Status") == 0  # the firmware never had to act


def test_an_over_temperature_trend_stops_early(rig, robot):
    servo = rig.servo("mf_j22")
    servo.health.temperature_c = 68.0
    servo.health.extra_heating_c_per_s = 1.0  # a blocked winding: 12 s to the limit
    with pytest.raises(GripperHealthError, match=r"mf_j22 temperature: .*over-temperature trend"):
        hold(robot, 200)
    assert stopped(rig, robot) and servo.get("Present_Temperature") < 80 - xm430.TEMPERATURE_STOP_MARGIN_C


def test_one_degree_steps_of_a_steady_servo_are_no_trend():
    """Present_Temperature has 1 degC steps: a reading that flips 70 <-> 71 must not look like a rising trend."""
    health = ServoHealth(JOINTS)
    found = [health.assess(_block(temp=70 + (k % 2)), 0, now=0.25 * k)[0] for k in range(40)]
    assert {d.level for d in found} == {WARN}  # near the limit (>= 65), never an over-temperature ERROR


def test_a_recording_episode_does_not_start_with_a_servo_near_its_limit(rig, robot):
    """lerobot-record announces every episode (`log_say("Recording episode N")`, at INFO; its init_logging leaves
    the root logger open to INFO). A servo that warmed to the start level during the last episode refuses the
    next one at its first read: the episode before it ran on, with a warning only."""
    from lerobot.utils.utils import log_say

    rig.servo("mf_j21").health.temperature_c = 74.0  # start needs < 72; stop at 77
    hold(robot, 6)  # the episode in progress goes on
    assert robot.is_connected
    root = logging.getLogger()
    level, root.level = root.level, logging.NOTSET  # as LeRobot's init_logging leaves it
    try:
        log_say("Recording episode 1", play_sounds=False)
    finally:
        root.level = level
    with pytest.raises(GripperHealthError, match=r"Refused to start: mf_j21 temperature 74 degC"):
        robot.get_observation()
    assert stopped(rig, robot)


def test_a_loop_that_resumes_after_a_pause_is_checked_as_a_start(rig, robot):
    rig.servo("ff_j10").health.temperature_c = 73.0
    hold(robot, 2)
    time.sleep(1.1)  # a save, a prompt: the loop paused
    with pytest.raises(GripperHealthError, match=r"Refused to start: ff_j10 temperature 73 degC"):
        hold(robot, 1)
    assert stopped(rig, robot)


def test_an_action_only_loop_reads_health_too(rig, robot):
    """A loop that only sends actions (a replay script): send_action stands in for the period's reads."""
    rig.servo("th_j32").health.temperature_c = 78.0  # over the stop level (77)
    with pytest.raises(GripperHealthError, match=r"th_j32 temperature: 78 degC .*: too hot"):
        for _ in range(8):
            robot.send_action(dict(zip(spec.ACTION_NAMES, spec.HOME_POSE.tolist(), strict=True)))
            time.sleep(spec.CONTROL_DT)
    assert stopped(rig, robot)


def test_a_disconnect_after_a_latched_stop_leaves_the_fault_last(rig, robot, tmp_path):
    """LeRobot's scripts call disconnect() in a `finally` (lerobot-calibrate, the robot's __exit__): after the latch
    stopped the gripper that call is quiet, so the traceback ends on the fault, not on "not connected". A gripper
    that was never connected still gets LeRobot's error."""
    from lerobot.utils.errors import DeviceNotConnectedError

    from lerobot_blindgrasp.robots.blindgrasp_gripper import BlindgraspGripper

    rig.servo("ff_j10").health.temperature_c = 80.0  # the firmware's own overheating stop
    with pytest.raises(GripperHardwareError, match=r"ff_j10 \(ID 10\): overheating"):
        hold(robot, 40)
    assert stopped(rig, robot)
    robot.disconnect()
    with pytest.raises(DeviceNotConnectedError):
        BlindgraspGripper(rig.robot_config(tmp_path / "never")).disconnect()


# --- Present_Input_Voltage and Present_Current ------------------------------------------------------------------
def _squeeze(rig, robot):
    """At the start pose, close every proximal joint onto a rigid object: the three J*1 servos sit at their current
    limit (the step bound keeps the goal 0.3 rad into the object), the other six hold at rest."""
    hold(robot, 40, spec.HOME_POSE)
    rig.place_object(contact_q=float(spec.HOME_POSE[1]) - 0.05)
    target = spec.HOME_POSE.copy()
    target[1::3] = spec.HOME_POSE[1] - 0.6
    return target


def test_a_supply_sagging_under_load_stops(rig, robot):
    target = _squeeze(rig, robot)
    rig.dxl.supply.r_ohm = 0.2  # a weak supply on a thin cable: 3 stalled servos x 2.3 A sag 11.2 V to ~9.8 V,
    rig.dxl.supply.open_v = 11.2  # under the 10 V rating, above the firmware's 9.5 V Min_Voltage_Limit
    with pytest.raises(GripperHealthError, match=r"input voltage: .* below the rating for .*sagging under load"):
        hold(robot, 100, target)
    assert stopped(rig, robot)


def test_a_brief_dip_under_the_rating_warns_but_does_not_stop():
    """All fingers starting at once dip the supply for a moment: only a sag held for 0.5 s stops."""
    health = ServoHealth(JOINTS)
    levels = [health.assess(_block(volts=9.8), 855, now=t)[1].level for t in (0.0, 0.2)]
    levels.append(health.assess(_block(volts=11.8), 855, now=0.3)[1].level)
    levels.append(health.assess(_block(volts=9.8), 855, now=0.6)[1].level)  # the hold starts again
    assert levels == [WARN, WARN, OK, WARN]


def test_an_over_voltage_supply_below_the_firmware_limit_is_refused(rig, tmp_path, monkeypatch):
    """15.2 V (a wrong power supply): over the XM430's 14.8 V rating, under the firmware's 16.0 V limit (no bit)."""
    rig.dxl.supply.open_v = 15.2
    with pytest.raises(GripperHealthError, match=r"input voltage 15.2 V \(start needs 10.8-14.8 V"):
        connect_gripper(rig, tmp_path, monkeypatch)
    assert not any(s.get("Hardware_Error_Status") for s in rig.dxl.servos.values())


def test_a_stall_at_the_current_limit_stops_before_the_firmware_overload(rig, robot, monkeypatch):
    monkeypatch.setattr(xm430, "STALL_STOP_S", 1.5)  # the test's clock; the firmware's overload is 2x later
    monkeypatch.setattr(xm430, "STALL_WARN_S", 0.5)
    for servo in rig.dxl.servos.values():
        servo.health.overload_s = 3.0
    target = _squeeze(rig, robot)
    with pytest.raises(
        GripperHealthError, match=r"current: 2\.\d\d A \(limit 2\.30 A\): at the current limit for"
    ):
        hold(robot, 100, target)
    assert stopped(rig, robot)
    assert not any(s.get("Hardware_Error_Status") for s in rig.dxl.servos.values())  # before the firmware's stop


def _stall_trial(calibrated, tmp_path, monkeypatch) -> tuple[RealGraspEnv, np.ndarray]:
    """An eval trial (force mode, a criterion no squeeze meets) on a rigid object, and the action that squeezes it
    with the three proximal servos at their current limit (the step bound keeps each goal 0.3 rad into it)."""
    monkeypatch.setattr(xm430, "STALL_STOP_S", 1.5)
    monkeypatch.setattr(xm430, "STALL_WARN_S", 0.5)
    env = trial_env(calibrated, "foam_brick", success_mode="force", hold_force_n=1e3, unattended_reset_s=0.0,
                    episode_s=3.0, trial_log=str(tmp_path / "trials.jsonl"))  # fmt: skip
    squeeze = spec.HOME_POSE.copy()
    squeeze[1::3] = spec.HOME_POSE[1] - 0.6
    env.reset(seed=0)
    return env, squeeze


def test_a_stall_ends_the_eval_trial_as_a_failure_and_the_next_trial_reconnects(
    rig, calibrated, tmp_path, monkeypatch
):
    """In lerobot-eval a missed grasp runs its full 10 s, and a finger may squeeze at its limit past the stall stop.
    That stop ends the trial (torque off, a failure in the record), not the evaluation: the next trial reconnects
    through every check of a first connect."""
    env, squeeze = _stall_trial(calibrated, tmp_path, monkeypatch)
    rig.place_object(contact_q=float(spec.HOME_POSE[1]) - 0.05)
    try:
        for steps in range(1, env._max_episode_steps + 1):  # noqa: B007 (read after the loop)
            _, reward, terminated, truncated, info = env.step(squeeze)
            if terminated or truncated:
                break
        assert terminated and not truncated and not info["is_success"] and reward == 0.0
        assert steps < env._max_episode_steps  # the stop, not the time limit, ended it
        assert stopped(rig, env.robot)
        rig.remove_object()
        env.reset(seed=1)  # the next trial: connected again, homed, torqued
        assert env.robot.is_connected and rig.dxl.any_torque()
        for _ in range(env._max_episode_steps):
            *_, truncated, _ = env.step(spec.HOME_POSE)
        assert truncated
    finally:
        env.close()
    first, second = (json.loads(line) for line in (tmp_path / "trials.jsonl").read_text().splitlines())
    assert (first["success"], first["decided_by"]) == (False, "stall stop")
    assert "at the current limit for" in first["stopped"] and "Torque is off on all servos" in first["stopped"]
    assert second["trial"] == 2 and second["stopped"] is None


def test_a_stall_stop_whose_torque_off_is_unconfirmed_ends_the_evaluation(rig, calibrated, tmp_path, monkeypatch):
    """A servo that does not confirm the torque-off may still be squeezing: nothing goes on, whatever the cause."""
    env, squeeze = _stall_trial(calibrated, tmp_path, monkeypatch)
    rig.place_object(contact_q=float(spec.HOME_POSE[1]) - 0.05)
    check = ServoHealth.check

    def check_then_lose_a_servo(self, *args, **kwargs):
        try:
            return check(self, *args, **kwargs)
        except ServoStallError:
            rig.dxl.missing_ids.add(31)  # its cable comes loose as the stall stop begins
            raise

    monkeypatch.setattr(ServoHealth, "check", check_then_lose_a_servo)
    try:
        with pytest.raises(GripperStallError, match=r"NOT confirmed by servo IDs \[31\]"):
            for _ in range(env._max_episode_steps):
                env.step(squeeze)
    finally:
        env.close()
    assert not env.robot.is_connected


def test_a_negative_current_read_raw_is_a_stall_not_174_amps():
    """LeRobot's raw sync read returns Present_Current unsigned: -855 reads 64681. A reversed servo closing at its
    limit is a stall by magnitude; without the sign it would read 174 A, or pass unseen."""
    health = ServoHealth(JOINTS)
    first = health.assess(_block(current=-855), 855, now=0.0)
    later = health.assess(_block(current=-855), 855, now=xm430.STALL_STOP_S + 0.1)
    assert first[2].level == OK and first[2].value == pytest.approx(2.30, abs=0.01)
    assert later[2].level == ERROR and "stalled" in later[2].message
