"""Hazards of inconsistency between inputs that see the same physics (docs/hardware.md, "Hazard analysis", table
"Consistency: inputs that see the same physics": a fingertip's force against its finger's currents, a finger's
effort against its tip force, commanded against measured motion). Analytic redundancy: a fingertip's force against its finger's servos, and each
servo's motion against its command. The model alone first (no emulator), then each fault injected into the emulated
gripper: the check fires with the torque off, and a normal squeeze does not fire it."""

from __future__ import annotations

import logging

import numpy as np
import pytest
from emulators.loop import hold, stopped

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.hardware import consistency as c
from lerobot_blindgrasp.hardware import xm430
from lerobot_blindgrasp.robots.blindgrasp_gripper.errors import GripperConsistencyError
from lerobot_blindgrasp.sim import gripper

LIMIT = xm430.amps_to_current_units(xm430.STALL_CURRENT_A)
BENT = spec.HOME_POSE.copy()
BENT[2::3] = 1.0  # every distal joint bent: a tip force then has a lever on J11/J12


def test_the_finger_geometry_is_the_sim_models():
    assert (c.LINK_J11_J12, c.TIP_CAPSULE_START, c.TIP_CAPSULE_RADIUS, c.TIP_CAPSULE_END) == (
        gripper.LINK_J11_J12, gripper.TIP_CAPSULE_START, gripper.TIP_CAPSULE_RADIUS, gripper.TIP_CAPSULE_END)  # fmt: skip


def test_the_lever_is_zero_only_for_a_strut_and_grows_with_the_bend():
    """A straight finger loaded along its axis needs no joint torque (a strut); bent, the tip load must be held."""
    assert c.lever_m(0.0) < 1e-4
    levers = [c.lever_m(q) for q in (0.3, 0.6, 1.0, 1.5)]
    assert all(a < b for a, b in zip(levers, levers[1:]))
    assert c.lever_m(-1.0) == c.lever_m(1.0)
    # Upper bound: no lever exceeds the distance from J11 to the tip's far end.
    assert max(levers) < c.LINK_J11_J12 + c.TIP_CAPSULE_END + c.TIP_CAPSULE_RADIUS


def _assess(mon, forces, currents, q=BENT, goal=None, t=0.0):
    mon.assess(t, q, q if goal is None else goal, forces, currents, LIMIT)


def test_a_tip_force_the_servos_do_not_hold_stops_after_persisting():
    f = 2 * c.HOLD_ALLOWANCE_NM / c.lever_m(1.0)  # twice what a resting finger at q12 = 1 rad can hold
    mon = c.ConsistencyMonitor()
    _assess(mon, [f, 0, 0], np.zeros(9))  # one read: an impact is carried by the rotor's inertia
    with pytest.raises(c.ConsistencyError, match=r"ff_tip reads .* N, which needs"):
        _assess(mon, [f, 0, 0], np.zeros(9), t=0.2)


def test_the_same_force_held_by_current_or_on_a_strut_passes():
    f = 2 * c.HOLD_ALLOWANCE_NM / c.lever_m(1.0)
    held = np.zeros(9)
    held[1] = xm430.amps_to_current_units(f * c.lever_m(1.0) / c.KT_NM_PER_A)  # J11 carries it
    straight = spec.HOME_POSE.copy()  # q12 = 0: a strut
    mon = c.ConsistencyMonitor()
    for t in range(5):
        _assess(mon, [f, 0, 0], held, t=t)
        _assess(mon, [f, f, f], np.zeros(9), q=straight, t=t)
    assert 0.4 < mon.worst["force without effort"] <= 1.0


def test_a_joint_that_does_not_follow_its_goal_stops():
    goal = BENT.copy()
    goal[4] += 0.3
    mon = c.ConsistencyMonitor()
    for t in range(c.PERSIST):
        _assess(mon, np.zeros(3), np.zeros(9), goal=goal, t=0.2 * t)
    with pytest.raises(c.ConsistencyError, match=r"mf_j21 does not move toward its goal \(\+0.30 rad away"):
        _assess(mon, np.zeros(3), np.zeros(9), goal=goal, t=0.6)


def test_a_joint_moving_to_its_goal_or_blocked_at_full_current_passes():
    goal = BENT.copy()
    goal[4] += 0.3
    q = BENT.copy()
    blocked = np.zeros(9)
    blocked[4] = LIMIT
    mon = c.ConsistencyMonitor()
    for t in range(6):
        q[4] += 0.03  # moving toward the goal, at low current (free motion)
        mon.assess(0.2 * t, q, q + np.eye(9)[4] * 0.3, np.zeros(3), np.zeros(9), LIMIT)
    for t in range(6):
        _assess(mon, np.zeros(3), blocked, goal=goal, t=2 + 0.2 * t)


def test_effort_without_tip_force_warns_when_it_starts_and_when_it_ends(caplog):
    goal = BENT.copy()
    goal[1] -= 0.3
    pressing = np.zeros(9)
    pressing[1] = -LIMIT  # pushing toward its goal
    mon = c.ConsistencyMonitor()
    with caplog.at_level(logging.WARNING):
        for t in range(4):
            _assess(mon, np.zeros(3), pressing, goal=goal, t=0.2 * t)
        _assess(mon, [5.0, 0, 0], pressing, goal=goal, t=1.0)
    assert caplog.text.count("Consistency WARN ff") == 1 and mon.warnings == 1
    assert "Consistency OK ff: its tip force agrees with its servos again (5.00 N) after 0.8 s" in caplog.text


# --- against the emulated gripper --------------------------------------------------------------------------------
@pytest.fixture
def robot(rig, tmp_path, monkeypatch):
    """A connected gripper whose loop may run slow on a loaded test host (the timing is not under test here)."""
    from lerobot_blindgrasp.robots.blindgrasp_gripper import BlindgraspGripper

    monkeypatch.setattr("builtins.input", rig.calibration_inputs())
    config = rig.robot_config(tmp_path / "calibration", max_overrun_s=0.0)
    config.force_sensor.min_rate_hz = 0.0  # nor the force stream's rate: the emulator's thread competes for a core
    r = BlindgraspGripper(config)
    r.connect()
    yield r
    if r.is_connected:
        r.disconnect()


def _bend(robot):
    hold(robot, 30, BENT)


def test_a_tip_reading_force_with_its_finger_at_rest_stops(rig, robot):
    """A load cell that reads 20 N (a shorted bridge, a drifted zero) on a bent finger at rest, touching nothing."""
    _bend(robot)
    rig.force.force_fn = lambda: np.array([0.0, 20.0, 0.0])
    with pytest.raises(GripperConsistencyError, match=r"mf_tip reads 20\.\d N, which needs"):
        hold(robot, 40, BENT)
    assert stopped(rig, robot)


def test_a_normal_squeeze_fires_nothing(rig, robot, caplog):
    """Every proximal joint closed onto a rigid object at its current limit, the tips reading the squeeze."""
    _bend(robot)
    rig.place_object(contact_q=float(BENT[1]) - 0.05)
    target = BENT.copy()
    target[1::3] = BENT[1] - 0.6
    with caplog.at_level(logging.WARNING):
        hold(robot, 40, target)
    assert robot.is_connected and "Consistency" not in caplog.text
    assert 0 < robot.consistency.worst["force without effort"] < 0.2


def test_a_finger_pressing_on_a_dead_load_cell_warns(rig, robot, caplog):
    """The same squeeze, with the mf cell reading nothing (unplugged): a WARN that names it, no stop."""
    _bend(robot)
    rig.place_object(contact_q=float(BENT[1]) - 0.05)
    squeeze = rig.force.force_fn
    rig.force.force_fn = lambda: squeeze() * np.array([1.0, 0.0, 1.0])
    target = BENT.copy()
    target[1::3] = BENT[1] - 0.6
    with caplog.at_level(logging.WARNING):
        hold(robot, 40, target)
    assert robot.is_connected
    assert "Consistency WARN mf: ['mf_j21'] press" in caplog.text and "Consistency WARN ff" not in caplog.text


def test_a_stripped_gear_stops(rig, robot):
    """The motor spins at its no-load current, the output shaft (and encoder) stays: commanded, not moving."""
    _bend(robot)
    rig.servo("th_j31").stripped = True
    target = BENT.copy()
    target[7] += 0.5
    with pytest.raises(GripperConsistencyError, match=r"th_j31 does not move toward its goal"):
        hold(robot, 60, target)
    assert stopped(rig, robot)


# --- faults predicted from the devices and the data path, each injected into the emulated gripper. Each input stays
# plausible on its own (in range, live, fresh), so only a second input that sees the same physics can tell.


def _mf_squeezes(rig, robot):
    """mf closes its proximal joint onto a rigid object (its tip reads the squeeze); ff and th rest, bent."""
    _bend(robot)
    rig.place_object(contact_q=float(BENT[4]) - 0.05)
    target = BENT.copy()
    target[4] = BENT[4] - 0.6
    hold(robot, 20, target)
    assert robot.is_connected
    return target


def test_force_channels_swapped_between_fingers_mid_run_stop(rig, robot):
    """A connector reseated into the wrong socket of the force board (or a channel_map edited under a running
    board): th's cell now reports mf's squeeze while th rests, and mf's tip reads nothing while it presses."""
    target = _mf_squeezes(rig, robot)
    squeeze = rig.force.force_fn
    rig.force.force_fn = lambda: squeeze()[[0, 2, 1]]
    with pytest.raises(GripperConsistencyError, match=r"th_tip reads 2\d\.\d N, which needs"):
        hold(robot, 40, target)
    assert stopped(rig, robot)


def test_a_current_reported_with_its_sign_flipped_stops(rig, robot):
    """Present_Current read in the wrong frame (Drive_Mode applied to the position but not to the current): a
    pressing joint seems to push away from its goal."""
    target = _mf_squeezes(rig, robot)
    rig.servo("mf_j21").current_sign = -1
    with pytest.raises(GripperConsistencyError, match=r"mf_j21 does not move toward its goal .* draws \+2\.30 A"):
        hold(robot, 40, target)
    assert stopped(rig, robot)


def test_a_present_position_frozen_while_the_joint_moves_stops(rig, robot):
    """The encoder's reading stops updating (a firmware fault, a stuck register) while the joint really moves: the
    reading is plausible (it is the estimate), the servo reaches its goal and its current falls, but the reading
    stays away from the goal."""
    _bend(robot)
    servo = rig.servo("ff_j12")
    servo.frozen_position = servo.get("Present_Position")
    target = BENT.copy()
    target[2] = BENT[2] + 0.5
    with pytest.raises(GripperConsistencyError, match=r"ff_j12 does not move toward its goal"):
        hold(robot, 60, target)
    assert stopped(rig, robot)
    assert abs(servo.present_position() - servo.frozen_position) > 100  # it did move: only the reading froze


def test_a_load_cell_creeping_after_its_tare_stops_once_it_is_implausible(rig, robot):
    """A cell whose zero creeps (a cracked bond, moisture) by 2 N/s on a bent finger at rest: fine while the reading
    is within what the resting servos could hold, stopped once it is not."""
    _bend(robot)
    ticks = [0]

    def creep() -> np.ndarray:
        ticks[0] += 1
        return np.array([min(40.0, 2.0 * ticks[0] / 80.0), 0.0, 0.0])  # the board sends 80 frames/s

    rig.force.force_fn = creep
    with pytest.raises(GripperConsistencyError, match=r"ff_tip reads \d+\.\d N"):
        hold(robot, 400, BENT)
    assert stopped(rig, robot)
