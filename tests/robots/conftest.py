"""The calibrated gripper and glove that lerobot-record's tests share (one calibration per test module)."""

from __future__ import annotations

import json
from unittest import mock

import pytest
from emulators.glove_sender import FIST, OPEN, free_udp_port
from emulators.harness import cli_env
from emulators.rig import GripperRig

from lerobot_blindgrasp import spec


@pytest.fixture(scope="module")
def station(tmp_path_factory):
    from lerobot_blindgrasp.robots.blindgrasp_gripper import BlindgraspGripper

    home = tmp_path_factory.mktemp("station")
    with GripperRig() as rig:
        rig.hand_move(spec.HOME_POSE)
        robot = BlindgraspGripper(rig.robot_config(home / "calibration" / "robots" / "blindgrasp_gripper"))
        with mock.patch("builtins.input", rig.calibration_inputs()):
            robot.connect()
        robot.disconnect()
    glove = home / "calibration" / "teleoperators" / "manus_glove"
    glove.mkdir(parents=True)
    (glove / "op.json").write_text(json.dumps({"open": OPEN, "fist": FIST}))
    return home, cli_env(home), free_udp_port()
