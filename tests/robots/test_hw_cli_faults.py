"""lerobot-record itself, as a subprocess against the emulators, meeting two faults of the hazard analysis
(docs/hardware.md): a servo too warm to start the next episode, and a full disk when the dataset is finalized.
The gripper and the glove are calibrated in-process here (the CLI calibration is test_hw_cli.py's)."""

from __future__ import annotations

import sys
import time

import pytest
from emulators.glove_sender import GloveEmulator
from emulators.harness import Operator
from emulators.rig import GripperRig
from test_hw_cli import REPO_ID, _record_cmd, _wait_for_torque

from lerobot_blindgrasp import spec

pytestmark = pytest.mark.slow

# lerobot-record with LeRobotDataset.finalize failing as on a full disk, and a thread that never ends (so the
# interpreter can never exit, and `atexit` never runs): only a guard before Python reports the error helps.
FULL_DISK = """
import errno, sys, threading
from lerobot.datasets.lerobot_dataset import LeRobotDataset

def finalize(self):
    raise OSError(errno.ENOSPC, "No space left on device")

LeRobotDataset.finalize = finalize
threading.Thread(target=threading.Event().wait, name="never-ends").start()
from lerobot.scripts.lerobot_record import main
sys.argv = ["lerobot-record", *sys.argv[1:]]
main()
"""


def test_a_supply_too_weak_for_the_next_episode_refuses_it(station, tmp_path):
    """The supply sags to 10.6 V during episode 0: a warning there (under 11.0 V), and at the announcement of
    episode 1 the start check refuses it (a start needs 10.8 V at rest): torque off, episode 0 kept."""
    from lerobot.datasets import LeRobotDataset

    _, env, port = station
    with GripperRig() as rig, GloveEmulator(port) as glove:
        rig.hand_move(spec.HOME_POSE)
        glove.closure = 0.3
        op = Operator(_record_cmd(rig, glove, tmp_path / "ds", episodes=2, episode_s=1.5), env)
        op.expect("Recording episode 0", timeout_s=120)
        time.sleep(0.5)  # episode 0 is under way
        rig.dxl.supply.open_v = 10.6
        assert op.wait(120) != 0 and "Refused to start: ff_j10 input voltage 10.6 V" in op.text, op.text[-3000:]
        assert not rig.dxl.any_torque()
    assert LeRobotDataset(REPO_ID, root=tmp_path / "ds").num_episodes == 1  # episode 0 kept, episode 1 never began


def test_a_full_disk_at_finalize_still_turns_the_torque_off(station, tmp_path):
    """lerobot-record's `finally` runs dataset.finalize() before robot.disconnect(): the disk error skips the
    disconnect. The robot's guard turns the torque off before Python reports the error, while the process lives on."""
    _, env, port = station
    with GripperRig() as rig, GloveEmulator(port) as glove:
        rig.hand_move(spec.HOME_POSE)
        glove.closure = 0.3
        cmd = [
            sys.executable,
            "-c",
            FULL_DISK,
            *_record_cmd(rig, glove, tmp_path / "ds", episodes=1, episode_s=1)[1:],
        ]
        op = Operator(cmd, env)
        try:
            _wait_for_torque(rig, op.proc)
            deadline = time.monotonic() + 60
            while rig.dxl.any_torque():
                assert time.monotonic() < deadline and op.proc.poll() is None, op.text[-3000:]
                time.sleep(0.05)
            op.expect("turning the torque off now", timeout_s=10)
            op.expect("No space left on device", timeout_s=10)  # then Python reports the error
            assert op.proc.poll() is None  # and the process cannot exit: the torque went off without it
        finally:
            op.proc.kill()
            op.proc.wait(timeout=30)
