"""Fault injection against the emulators: every fault a lab sees ends with one error type, the torque off (or the
servos stopped by their own watchdog when the host is gone), and nothing moving further than it should.

One section per class of fault: process signals, servo resets and the bus watchdog, port loss, motion bounds,
errors that must not hide the real one, and clean retries (calibration files and glove streams are
`test_hw_faults_inputs.py`). The rows of docs/hardware.md's hazard analysis name these tests.
"""

from __future__ import annotations

import json
import signal
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from emulators.harness import Operator, cli_env
from emulators.loop import as_q, settle
from emulators.rig import LATENCY_TIMER_MS

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.hardware import servo_registers as servo_state
from lerobot_blindgrasp.hardware.xm430 import RAD_PER_TICK, WATCHDOG_TRIPPED
from lerobot_blindgrasp.robots.blindgrasp_gripper import BlindgraspGripper
from lerobot_blindgrasp.robots.blindgrasp_gripper.errors import (
    ForceSensorError,
    GripperBusError,
    GripperSafetyStop,
    GripperStateError,
)

LOOP = Path(__file__).resolve().parents[1] / "emulators" / "robot_loop.py"
WATCHDOG_S = 0.200  # BlindgraspGripperConfig.bus_watchdog_ms


def _assert_stopped(rig, robot, exclude=()):
    assert not robot.is_connected
    assert not any(rig.dxl.torque_enabled(i) for i in spec.SERVO_IDS if i not in exclude)


def _no_prompt(monkeypatch):
    def prompt(text=""):
        raise AssertionError(f"unexpected interactive prompt: {text!r}")

    monkeypatch.setattr("builtins.input", prompt)


def _time_until(condition, timeout_s: float = 10.0, poll_s: float = 0.001) -> float:
    t0 = time.monotonic()
    while not condition():
        assert time.monotonic() - t0 < timeout_s, "condition never became true"
        time.sleep(poll_s)
    return time.monotonic() - t0


# --- 1. process signals ------------------------------------------------------------------------------------------
def _loop_process(rig, robot, tmp_path) -> Operator:
    robot.disconnect()  # the calibration file stays; the subprocess connects without prompting
    args = {"port": rig.dxl.port, "force_port": rig.force.port, "calibration_dir": str(robot.calibration_dir),
            "scale": rig.force.scale.tolist(), "latency_timer_ms": LATENCY_TIMER_MS}  # fmt: skip
    proc = Operator([sys.executable, str(LOOP), json.dumps(args)], cli_env(tmp_path))
    proc.expect("READY")
    time.sleep(0.3)  # a few control periods with the torque on and the fingers moving
    assert all(rig.dxl.torque_enabled(i) for i in spec.SERVO_IDS)
    return proc


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP])
def test_termination_signal_turns_the_torque_off(rig, robot, tmp_path, sig):
    proc = _loop_process(rig, robot, tmp_path)
    proc.proc.send_signal(sig)
    dt = _time_until(lambda: not rig.dxl.any_torque())
    assert proc.wait(30) == 128 + sig, proc.text[-3000:]  # SystemExit(128 + signum): unwound, not killed
    assert f"{signal.Signals(sig).name} received: stopping" in proc.text
    print(f"{signal.Signals(sig).name}: torque off on all 9 servos {dt * 1e3:.0f} ms after the signal")
    assert dt < 2.0


def test_killed_host_is_stopped_by_the_servo_watchdog(rig, robot, tmp_path):
    """SIGKILL leaves no cleanup at all: the servos' Bus_Watchdog stops them where they are."""
    proc = _loop_process(rig, robot, tmp_path)
    ids = spec.SERVO_IDS
    proc.proc.kill()
    t_kill = time.monotonic()
    proc.wait(30)
    _time_until(lambda: all(rig.dxl.servos[i].get("Bus_Watchdog") == WATCHDOG_TRIPPED for i in ids), timeout_s=2.0)
    stopped = max(rig.dxl.servos[i].watchdog_tripped_at for i in ids) - t_kill
    print(f"SIGKILL: all 9 servos stopped by their bus watchdog {stopped * 1e3:.0f} ms after the kill")
    # The watchdog counts from the last packet, which came <= one loop iteration before the kill.
    assert stopped <= WATCHDOG_S + 0.1
    q = rig.true_q()
    time.sleep(0.3)
    np.testing.assert_allclose(rig.true_q(), q, atol=RAD_PER_TICK)  # stopped, and stays stopped
    # Goals are refused until someone clears the watchdog error: a stray write cannot restart the motion.
    assert all(rig.dxl.torque_enabled(i) for i in ids)


# --- 2. servo state: resets, silent changes, the watchdog after a pause ------------------------------------------
def test_servo_reset_is_caught_on_the_next_call(rig, robot):
    robot.get_observation()
    rig.dxl.reset_servo(21)  # brown-out: torque off, RAM defaults, no error bit
    with pytest.raises(
        GripperStateError, match=r"mf_j21 \(ID 21\): Torque_Enable 0 \(set 1\).*reset.*Torque is off"
    ):
        robot.get_observation()
    _assert_stopped(rig, robot)


def test_reset_is_caught_by_send_action_alone(rig, robot):
    """lerobot-replay only sends actions: the check then runs in send_action, still once per control period."""
    robot.send_action(dict(zip(spec.ACTION_NAMES, as_q(robot.get_observation()).tolist(), strict=True)))
    time.sleep(spec.CONTROL_DT)
    rig.dxl.reset_servo(32)
    with pytest.raises(GripperStateError, match=r"th_j32 \(ID 32\)"):
        robot.send_action(dict.fromkeys(spec.ACTION_NAMES, 0.3))
    _assert_stopped(rig, robot)


def test_a_changed_limit_is_caught(rig, robot):
    rig.servo("ff_j12").set("Goal_Current", 1193)  # torque limit raised behind the robot's back
    with pytest.raises(GripperStateError, match=r"ff_j12 \(ID 12\): Goal_Current 1193 \(set 855\)"):
        robot.get_observation()
    _assert_stopped(rig, robot)


def test_state_check_cost(rig, robot):
    n = 40
    t = []
    for _ in range(n):
        t0 = time.perf_counter()
        robot.bus.read_block(*servo_state.BLOCK, servo_state.READ)
        t.append(time.perf_counter() - t0)
    print(f"servo state check: median {np.median(t) * 1e3:.2f} ms, p90 {np.percentile(t, 90) * 1e3:.2f} ms")
    assert robot.bus.sync_reader.data_length == 40  # one 40-byte block per servo, one transaction


def test_watchdog_stop_after_a_host_pause_is_rearmed(rig, robot, caplog):
    servos = [rig.dxl.servos[i] for i in spec.SERVO_IDS]
    assert {s.get("Bus_Watchdog") for s in servos} == {10}  # 10 x 20 ms
    q0 = as_q(robot.get_observation())
    time.sleep(WATCHDOG_S + 0.15)  # a slow save between episodes, an operator prompt
    assert {s.get("Bus_Watchdog") for s in servos} == {WATCHDOG_TRIPPED}
    assert all(s.get("Torque_Enable") == 1 for s in servos)  # stopped, not limp
    with caplog.at_level("WARNING"):
        robot.get_observation()
    assert "re-arming" in caplog.text and {s.get("Bus_Watchdog") for s in servos} == {10}
    target = dict(zip(spec.ACTION_NAMES, (q0 + 0.1).tolist(), strict=True))
    np.testing.assert_allclose(as_q(settle(robot, target, steps=8)), q0 + 0.1, atol=1.01 * RAD_PER_TICK)


# --- 3. port loss --------------------------------------------------------------------------------------------------
def test_unplugged_bus_adapter_is_a_bus_error_that_says_cut_the_power(rig, robot):
    robot.get_observation()
    rig.dxl.unplug()
    t0 = time.monotonic()
    with pytest.raises(GripperBusError, match=r"port lost.*unplugged.*NOT confirmed.*cut the servo power"):
        robot.get_observation()
    print(f"bus adapter unplugged: GripperBusError after {(time.monotonic() - t0) * 1e3:.0f} ms")
    assert not robot.is_connected


def test_unplugged_bus_adapter_during_send_action(rig, robot):
    rig.dxl.unplug()
    with pytest.raises(GripperBusError, match="cut the servo power"):
        robot.send_action(dict.fromkeys(spec.ACTION_NAMES, 0.3))
    assert not robot.is_connected


def test_unplugged_force_sensor_is_a_sensor_error(rig, robot):
    rig.force.unplug()
    time.sleep(0.05)
    with pytest.raises(ForceSensorError, match=r"port .* failed \(USB cable unplugged\?\).*Torque is off"):
        robot.get_observation()
    _assert_stopped(rig, robot)


def test_force_frames_with_the_wrong_channel_count_are_a_sensor_error(rig, robot):
    rig.force.channels = 2  # firmware built for two cells, config maps three
    time.sleep(0.05)
    with pytest.raises(ForceSensorError, match=r"carry 2 channels.*channel_map \[0, 1, 2\].*Torque is off"):
        robot.get_observation()
    _assert_stopped(rig, robot)


def test_extra_force_channels_are_fine(rig, robot):
    rig.force.channels = 4
    rig.force.forces_n = np.array([2.0, 0.0, 0.0])
    time.sleep(0.05)
    assert robot.get_observation()["ff_tip.force"] == pytest.approx(2.0, abs=0.03)


# --- 4. motion bounds from the first step --------------------------------------------------------------------------
def test_a_joint_outside_its_limits_comes_back_one_bounded_step_at_a_time(rig, robot):
    start = spec.HOME_POSE.copy()
    start[1] = spec.JOINT_UPPER[1] + 0.5  # ff_j11 half a radian past its limit
    start[7] = spec.JOINT_UPPER[7] + 0.3
    with robot.torque_disabled():
        rig.hand_move(start)
    time.sleep(0.05)
    np.testing.assert_allclose(rig.true_q(), start, atol=RAD_PER_TICK)  # torque on did not move anything
    home = dict(zip(spec.ACTION_NAMES, spec.HOME_POSE.tolist(), strict=True))
    q = as_q(robot.get_observation())
    for _ in range(5):
        sent = robot.send_action(home)
        step = np.array([sent[k] for k in spec.ACTION_NAMES]) - q
        assert np.abs(step).max() <= spec.ACTION_BOUND_RAD + RAD_PER_TICK, step
        time.sleep(0.2)  # settled (emulated time constant 30 ms), so the next q is the one send_action reads
        q = as_q(robot.get_observation())
    np.testing.assert_allclose(q, spec.HOME_POSE, atol=1.01 * RAD_PER_TICK)


def test_position_mode_refuses_to_hold_a_pose_outside_the_limits(rig, robot, tmp_path):
    with robot.torque_disabled():
        rig.hand_move(np.r_[spec.JOINT_UPPER[0] + 0.3, spec.HOME_POSE[1:]])
    robot.disconnect()
    r = BlindgraspGripper(rig.robot_config(robot.calibration_dir, operating_mode="POSITION"))
    with pytest.raises(GripperSafetyStop, match=r"ff_j10.*outside their limits.*POSITION mode"):
        r.connect()
    _assert_stopped(rig, r)


# --- 5. errors that must not hide the real one ---------------------------------------------------------------------
def test_a_safety_stop_inside_with_robot_raises_the_original_fault(rig, robot, monkeypatch):
    robot.disconnect()
    _no_prompt(monkeypatch)
    rig.dxl.drop_responses[22] = 10_000
    with pytest.raises(GripperBusError, match=r"servo IDs \[22\]"):
        with BlindgraspGripper(rig.robot_config(robot.calibration_dir)) as r:
            r.get_observation()
    assert not rig.dxl.any_torque()


def test_with_robot_disconnects_on_other_exceptions(rig, robot):
    robot.disconnect()
    with pytest.raises(ZeroDivisionError), BlindgraspGripper(rig.robot_config(robot.calibration_dir)) as r:
        r.get_observation()
        1 / 0  # noqa: B018  (a bug in the caller's loop)
    assert not r.is_connected and not rig.dxl.any_torque()


# --- 8. clean retries ----------------------------------------------------------------------------------------------
def test_a_burst_of_corrupt_replies_on_several_servos_is_absorbed(rig, robot):
    """bus_num_retry = 2: every servo below answers its next two packets with a bad CRC. Each try must start on an
    empty line, or the leftovers of the abandoned sync-read burst are parsed as the next try's replies."""
    for i in (10, 21, 32):
        rig.dxl.corrupt_responses[i] = 2
    robot.get_observation()
    for i in (11, 20, 31):
        rig.dxl.corrupt_responses[i] = 2
    robot.send_action(dict(zip(spec.ACTION_NAMES, as_q(robot.get_observation()).tolist(), strict=True)))
    assert robot.is_connected and all(rig.dxl.torque_enabled(i) for i in spec.SERVO_IDS)


def test_a_retry_waits_out_the_rest_of_an_abandoned_burst_with_gaps(rig, robot):
    """The first, fourth and seventh replies of a sync read are corrupt, and the replies follow 2 ms apart, so the line
    is empty for a while right after the first failure. The retry must wait until the abandoned burst has ended, not
    only drop what has arrived so far: otherwise the second try meets the old burst's corrupt reply of servo 20 and
    the third that of servo 30, and the gripper stops although only one try was spoiled."""
    rig.dxl.reply_gap_s = 0.002
    for _ in range(3):
        for i in (10, 20, 30):
            rig.dxl.corrupt_responses[i] = 1
        robot.get_observation()
    assert robot.is_connected and all(rig.dxl.torque_enabled(i) for i in spec.SERVO_IDS)


def test_a_burst_beyond_the_retry_budget_still_stops(rig, robot):
    for i in (10, 21, 32):
        rig.dxl.corrupt_responses[i] = 3
    with pytest.raises(GripperBusError, match="3 times"):
        robot.get_observation()
    _assert_stopped(rig, robot)
