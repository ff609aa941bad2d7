"""Fault injection, part two: readings that arrive intact but are wrong, dead data that still arrives, a loop that
loses time, a second owner, and the reconnect after a servo's power returns.

Each test is the one a row of docs/hardware.md's hazard analysis names.
The property-based fuzzing of the same decoders and gates is `test_hw_faults_fuzz.py`.
"""

from __future__ import annotations

import logging
import time

import numpy as np
import pytest
from emulators.loop import as_q, settle

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.envs.real_env import BlindGraspRealEnvConfig
from lerobot_blindgrasp.envs.real_trial import GripperSession, RealGraspEnv
from lerobot_blindgrasp.hardware.force_board.reader import ForceSensorReader, ForceTareError
from lerobot_blindgrasp.hardware.ports import PortInUseError
from lerobot_blindgrasp.hardware.xm430 import RAD_PER_TICK
from lerobot_blindgrasp.robots.blindgrasp_gripper import BlindgraspGripper
from lerobot_blindgrasp.robots.blindgrasp_gripper.errors import (
    ForceSensorError,
    GripperPortBusyError,
    GripperReadingError,
    GripperTimingError,
)

TICK = RAD_PER_TICK


def _assert_stopped(rig, robot):
    assert not robot.is_connected
    assert not rig.dxl.any_torque()


def _action(q) -> dict[str, float]:
    return dict(zip(spec.ACTION_NAMES, np.asarray(q, dtype=float).tolist(), strict=True))


def _no_prompt(monkeypatch):
    def prompt(text=""):
        raise AssertionError(f"unexpected interactive prompt: {text!r}")

    monkeypatch.setattr("builtins.input", prompt)


# --- servo position, status replies ----------------------------------------------------------------------------
def test_a_corrupt_position_read_is_reread_and_never_centres_the_step_bound(rig, robot):
    """One read of ff_j11 comes back 1.2 rad low with a valid CRC. Centred on it, the +-0.3 rad window would allow a
    1.5 rad step toward the lower limit; the gate re-reads, so the step stays 0.3 rad from where the joint is."""
    q = as_q(robot.get_observation())
    rejected = robot.gate.rejected
    rig.dxl.position_glitch[11] = [-round(1.2 / TICK), 1]
    target = q.copy()
    target[1] = spec.JOINT_LOWER[1]
    sent = robot.send_action(_action(target))
    step = sent["ff_j11.pos"] - rig.true_q()[1]
    assert abs(step) <= spec.ACTION_BOUND_RAD + 2 * TICK, step
    assert robot.gate.rejected == rejected + 1 and rig.dxl.position_glitch[11][1] == 0
    assert robot.is_connected


def test_a_stray_status_packet_is_not_decoded_as_a_position(rig, robot):
    """A late 40-byte reply of servo 11 sits on the line when the position sync read starts: the SDK alone would
    take its first four bytes (Torque_Enable, LED, ...) as ff_j11's position, tens of thousands of rad."""
    q = as_q(robot.get_observation())
    rig.dxl.stray_replies.append((11, 40))
    sent = robot.send_action(_action(q))
    assert not rig.dxl.stray_replies  # it was sent, and read as a corrupt reply, then retried
    np.testing.assert_allclose([sent[k] for k in spec.ACTION_NAMES], q, atol=2 * TICK)
    np.testing.assert_allclose(as_q(robot.get_observation()), q, atol=2 * TICK)


def test_an_out_of_range_reading_is_reread(rig, robot):
    q = as_q(robot.get_observation())
    rig.dxl.position_glitch[30] = [10**7, 1]  # ~15 000 rad: outside the encoder's single turn
    np.testing.assert_allclose(as_q(robot.get_observation()), q, atol=2 * TICK)
    assert "outside the encoder range" in robot.gate.last_problem


def test_persistently_implausible_readings_stop_with_the_torque_off(rig, robot):
    rig.dxl.position_glitch[21] = [2000, 1000]  # every read of mf_j21 is 3 rad off
    with pytest.raises(GripperReadingError, match=r"mf_j21.*3 re-reads|implausible.*mf_j21"):
        robot.send_action(_action(as_q(robot.get_observation())))
    _assert_stopped(rig, robot)


def test_a_corrupt_state_block_read_is_read_again_before_stopping(rig, robot):
    robot.get_observation()
    rig.dxl.stray_replies.append((21, 4))  # a 4-byte stray reply where the 40-byte state block is expected
    robot.get_observation()
    assert robot.is_connected


# --- force frames ------------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "fault,why",
    [
        ("resend_last", r"stale.*repeated or backward counter"),
        ("seq_step", r"stale.*repeated or backward counter"),
        ("frozen_channels", r"stale.*\['mf_tip'\] repeat the same value bit for bit"),
    ],
)
def test_dead_force_data_that_still_arrives_is_stale(rig, robot, fault, why):
    robot.get_observation()
    dropped = robot.force.dropped_frames
    setattr(rig.force, fault, {"resend_last": True, "seq_step": -1, "frozen_channels": {1}}[fault])
    deadline = time.monotonic() + 2.0
    with pytest.raises(ForceSensorError, match=why):
        while time.monotonic() < deadline:
            robot.get_observation()
            time.sleep(spec.CONTROL_DT)
    _assert_stopped(rig, robot)
    assert robot.force.dropped_frames - dropped < 5  # a backward counter is not 65 000 lost frames


def test_a_retare_with_a_loaded_pad_is_refused_and_keeps_the_zero(rig, robot):
    zero = robot.force.offset.copy()
    rig.force.forces_n = np.array([6.0, 0.0, 0.0])  # the object still presses on ff's pad
    time.sleep(0.05)
    with pytest.raises(ForceTareError, match=r"ff_tip reads \+(6\.0|5\.9)\d N against the current zero"):
        robot.tare_forces()
    np.testing.assert_array_equal(robot.force.offset, zero)
    assert robot.is_connected and all(rig.dxl.torque_enabled(i) for i in spec.SERVO_IDS)  # refused, not stopped
    rig.force.forces_n = np.zeros(3)
    time.sleep(0.05)
    assert robot.get_observation()["ff_tip.force"] == 0.0  # unloaded reads 0, not -6 N


def test_a_tare_with_a_pad_that_moves_is_refused(rig, robot):
    rig.force.noise = 2.0 / rig.force.scale[0]  # 2 N of wobble: a hand on the pad
    with pytest.raises(ForceTareError, match=r"varies by"):
        robot.tare_forces()
    assert robot.is_connected


def test_a_clearly_negative_force_is_a_fault(rig, robot):
    rig.force.forces_n = np.array([0.0, -3.0, 0.0])  # what a tare under 3 N reads once the pad is free
    time.sleep(0.05)
    with pytest.raises(ForceSensorError, match=r"mf_tip -(3\.0|2\.9)\d N.*only feels compression"):
        robot.get_observation()
    _assert_stopped(rig, robot)


# --- host loop timing --------------------------------------------------------------------------------------------
def test_a_slow_bus_is_warned_and_a_sustained_overrun_stops(rig, robot, caplog):
    """Every packet answered 20 ms late: a lerobot-record-shaped loop at 20 Hz runs near 8 Hz. Warned at the first
    overrun, named when the streak starts, stopped with a named error after max_overrun_s of it."""
    rig.dxl.reply_delay_s = 0.02
    t0 = time.monotonic()
    with caplog.at_level(logging.WARNING), pytest.raises(GripperTimingError, match=r"overrun its 50 ms period"):
        while time.monotonic() - t0 < 10.0:
            start = time.perf_counter()
            obs = robot.get_observation()
            robot.send_action({k: obs[k] for k in spec.ACTION_NAMES})
            time.sleep(max(0.0, spec.CONTROL_DT - (time.perf_counter() - start)))
    rig.dxl.reply_delay_s = 0.0
    assert "slow streak started" in caplog.text and "slow streak ended (stopped)" in caplog.text
    streak = robot.timing.streaks[-1]  # the one that stopped it, by the monitor's own clock
    assert streak.seconds >= robot.config.max_overrun_s and streak.periods >= robot.timing.min_overruns
    _assert_stopped(rig, robot)


def test_the_trial_rebases_after_a_stall_instead_of_bursting(rig, tmp_path, monkeypatch):
    monkeypatch.setattr("builtins.input", rig.calibration_inputs())
    cfg = BlindGraspRealEnvConfig(robot=rig.robot_config(tmp_path / "cal"), task="foam_brick", success_mode="force",
                                  unattended_reset_s=0.0, episode_s=5.0)  # fmt: skip
    env = RealGraspEnv(GripperSession(cfg), "foam_brick")
    try:
        env.reset(seed=0)
        timing = env.robot.timing
        for k in range(16):
            rig.dxl.reply_delay_s = 0.03 if k in (4, 5) else 0.0  # two steps stalled by a slow bus (~0.2 s each)
            env.step(spec.HOME_POSE)
            if k == 5:
                after_stall = len(timing.recent)
        # The observation times (one per step, at the schedule's tick): no catch-up burst (it was 3 ms apart). A
        # tick can come up to one sleep overshoot early relative to a late previous one, hence half a period.
        periods = np.array(timing.recent)[after_stall:]
        assert len(periods) == 10 and periods.min() >= 0.5 * spec.CONTROL_DT, periods
        assert env._schedule.rebased >= 1 and timing.overruns >= 1
    finally:
        env.close()


# --- OS resources: ports ---------------------------------------------------------------------------------------
def test_a_second_owner_is_refused_before_it_sends_a_byte(rig, robot):
    robot.get_observation()
    before = dict(rig.dxl.instruction_counts)
    second = BlindgraspGripper(rig.robot_config(robot.calibration_dir))
    with pytest.raises(GripperPortBusyError, match=r"already in use by another process.*Nothing was sent"):
        second.connect()
    assert rig.dxl.instruction_counts == before  # not one packet: no ping, no torque-off
    assert all(rig.dxl.torque_enabled(i) for i in spec.SERVO_IDS) and robot.is_connected
    robot.get_observation()
    with pytest.raises(PortInUseError, match="force-sensor port"):  # the sensor port alone, too
        ForceSensorReader(rig.force.port, 115_200, [1, 1, 1]).connect()


# --- recovery --------------------------------------------------------------------------------------------------
def test_reconnect_after_power_returns_to_a_lost_servo(rig, robot, monkeypatch):
    """mf_j21 loses power while the host is quiet (> the 200 ms bus watchdog): the others stop on their watchdog,
    the next call stops the gripper. Power returns (the servo boots with RAM defaults), and the operator reconnects.
    The watchdog error of the other servos outlives the torque-off and makes Goal_Current read-only, so configure()
    must clear it before anything else."""
    robot.get_observation()
    rig.dxl.missing_ids.add(21)
    time.sleep(0.3)
    with pytest.raises(Exception, match=r"servo IDs \[21\]"):
        robot.get_observation()
    assert not robot.is_connected and not any(rig.dxl.torque_enabled(i) for i in spec.SERVO_IDS if i != 21)
    rig.dxl.missing_ids.discard(21)
    rig.dxl.reset_servo(21)
    _no_prompt(monkeypatch)
    robot.connect()
    q = as_q(robot.get_observation())
    target = q.copy()
    target[4] += 0.2
    np.testing.assert_allclose(as_q(settle(robot, _action(target), steps=8)), target, atol=2 * TICK)
