"""Hazards of the XM430's per-period state block, Torque_Enable(64)..Goal_Current(102), and of Goal_Position(116)
(docs/hardware.md, "Hazard analysis", table "XM430-W350 control table": Torque_Enable, Operating_Mode, the gains,
Goal_Current, Goal_Position). A reset or a register changed behind the robot's back is caught at the next call,
in a loop that only sends actions too; a joint outside its limits comes back one bounded step at a time."""

from __future__ import annotations

import time

import numpy as np
import pytest
from emulators.loop import as_q, stopped

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.hardware import servo_registers as servo_state
from lerobot_blindgrasp.hardware.xm430 import RAD_PER_TICK
from lerobot_blindgrasp.robots.blindgrasp_gripper.errors import GripperStateError


def test_servo_reset_is_caught_on_the_next_call(rig, robot):
    robot.get_observation()
    rig.dxl.reset_servo(21)  # brown-out: torque off, RAM defaults, no error bit
    with pytest.raises(
        GripperStateError, match=r"mf_j21 \(ID 21\): Torque_Enable 0 \(set 1\).*reset.*Torque is off"
    ):
        robot.get_observation()
    assert stopped(rig, robot)


def test_reset_is_caught_by_send_action_alone(rig, robot):
    """lerobot-replay only sends actions: the check then runs in send_action, still once per control period."""
    robot.send_action(dict(zip(spec.ACTION_NAMES, as_q(robot.get_observation()).tolist(), strict=True)))
    time.sleep(spec.CONTROL_DT)
    rig.dxl.reset_servo(32)
    with pytest.raises(GripperStateError, match=r"th_j32 \(ID 32\)"):
        robot.send_action(dict.fromkeys(spec.ACTION_NAMES, 0.3))
    assert stopped(rig, robot)


def test_a_changed_limit_is_caught(rig, robot):
    rig.servo("ff_j12").set("Goal_Current", 1193)  # torque limit raised behind the robot's back
    with pytest.raises(GripperStateError, match=r"ff_j12 \(ID 12\): Goal_Current 1193 \(set 855\)"):
        robot.get_observation()
    assert stopped(rig, robot)


def test_state_check_cost(rig, robot):
    n = 40
    t = []
    for _ in range(n):
        t0 = time.perf_counter()
        robot.bus.read_block(*servo_state.BLOCK, servo_state.READ)
        t.append(time.perf_counter() - t0)
    print(f"servo state check: median {np.median(t) * 1e3:.2f} ms, p90 {np.percentile(t, 90) * 1e3:.2f} ms")
    assert robot.bus.sync_reader.data_length == 40  # one 40-byte block per servo, one transaction


def test_a_corrupt_state_block_read_is_read_again_before_stopping(rig, robot):
    robot.get_observation()
    rig.dxl.stray_replies.append((21, 4))  # a 4-byte stray reply where the 40-byte state block is expected
    robot.get_observation()
    assert robot.is_connected


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
