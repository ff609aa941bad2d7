"""Held-out faults for the consistency checks (docs/hardware.md, "Consistency"): predicted from the devices and the
data path, named by no issue, each injected into the emulated gripper. Each input stays plausible on its own (in
range, live, fresh), so only a second input that sees the same physics can tell."""

from __future__ import annotations

import numpy as np
import pytest
from emulators.fixtures import rig  # noqa: F401  (fixtures)
from test_hw_faults_consistency import BENT, _bend, robot  # noqa: F401  (fixtures)
from test_hw_health import _hold, _stopped

from lerobot_blindgrasp.robots.blindgrasp_gripper.errors import GripperConsistencyError


def _mf_squeezes(rig, robot):
    """mf closes its proximal joint onto a rigid object (its tip reads the squeeze); ff and th rest, bent."""
    _bend(robot)
    rig.place_object(contact_q=float(BENT[4]) - 0.05)
    target = BENT.copy()
    target[4] = BENT[4] - 0.6
    _hold(robot, 20, target)
    assert robot.is_connected
    return target


def test_force_channels_swapped_between_fingers_mid_run_stop(rig, robot):
    """A connector reseated into the wrong socket of the force board (or a channel_map edited under a running
    board): th's cell now reports mf's squeeze while th rests, and mf's tip reads nothing while it presses."""
    target = _mf_squeezes(rig, robot)
    squeeze = rig.force.force_fn
    rig.force.force_fn = lambda: squeeze()[[0, 2, 1]]
    with pytest.raises(GripperConsistencyError, match=r"th_tip reads 2\d\.\d N, which needs"):
        _hold(robot, 40, target)
    assert _stopped(rig, robot)


def test_a_current_reported_with_its_sign_flipped_stops(rig, robot):
    """Present_Current read in the wrong frame (Drive_Mode applied to the position but not to the current): a
    pressing joint seems to push away from its goal."""
    target = _mf_squeezes(rig, robot)
    rig.servo("mf_j21").current_sign = -1
    with pytest.raises(GripperConsistencyError, match=r"mf_j21 does not move toward its goal .* draws \+2\.30 A"):
        _hold(robot, 40, target)
    assert _stopped(rig, robot)


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
        _hold(robot, 60, target)
    assert _stopped(rig, robot)
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
        _hold(robot, 400, BENT)
    assert _stopped(rig, robot)
