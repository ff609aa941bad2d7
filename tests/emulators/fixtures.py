"""pytest fixtures for the emulated gripper; test modules import the ones they use."""

from __future__ import annotations

import numpy as np
import pytest

from lerobot_blindgrasp import spec

from .rig import GripperRig


@pytest.fixture
def rig():
    with GripperRig() as r:
        r.hand_move(spec.HOME_POSE)
        yield r


@pytest.fixture
def robot(rig, tmp_path, monkeypatch):
    """A connected, calibrated gripper on the rig (calibrated by the scripted operator)."""
    from lerobot_blindgrasp.robots.blindgrasp_gripper import BlindgraspGripper

    monkeypatch.setattr("builtins.input", rig.calibration_inputs())
    r = BlindgraspGripper(rig.robot_config(tmp_path / "calibration"))
    r.connect()
    yield r
    if r.is_connected:
        r.disconnect()


def settle(robot, target: dict[str, float], steps: int = 20) -> dict[str, float]:
    """Send the same target at 20 Hz until the servos get there (emulated time constant ~30 ms)."""
    import time

    for _ in range(steps):
        robot.send_action(target)
        time.sleep(spec.CONTROL_DT / 2)
    return robot.get_observation()


def as_q(obs: dict[str, float]) -> np.ndarray:
    return np.array([obs[k] for k in spec.JOINT_FEATURE_NAMES])
