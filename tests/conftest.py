"""Session-wide settings (headless rendering, no network, modest threading on small CI machines) and the fixtures
of the emulated gripper that tests in every folder use."""

import gc
import os

# Before anything imports mujoco: EGL renders headless (OSMesa is not installed, GLFW needs a display).
os.environ.setdefault("MUJOCO_GL", "egl")
# Tests build their own data; any Hub access is a bug and should fail fast.
os.environ.setdefault("HF_HUB_OFFLINE", "1")


import pytest  # noqa: E402  (after the environment settings above)
from emulators.rig import GripperRig  # noqa: E402

from lerobot_blindgrasp import spec  # noqa: E402


def pytest_collection_finish(session):
    """The emulated servos and boards answer from threads of the test process, within a reply window a real device
    meets in microseconds. A full garbage collection walks the whole heap (torch, LeRobot, MuJoCo and every
    collected test) with every thread stopped, and on a busy 2-core machine that pause outlasts the window. What
    collection leaves alive lives for the session, so it is frozen out of the collector's walks."""
    gc.freeze()


@pytest.fixture
def one_torch_thread():
    """Small CPU ops on a shared 2-core machine run far faster on one thread than with two spinning OpenMP
    threads. Modules that run many small torch ops use it with `pytestmark = pytest.mark.usefixtures(...)`."""
    import torch

    previous = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(previous)


@pytest.fixture
def rig():
    with GripperRig() as r:
        r.hand_move(spec.HOME_POSE)
        yield r


@pytest.fixture
def calibrated(rig, tmp_path, monkeypatch):
    """The gripper's config on the rig; its first connect calibrates it, answered by the scripted operator."""
    monkeypatch.setattr("builtins.input", rig.calibration_inputs())
    return rig.robot_config(tmp_path / "calibration")


@pytest.fixture
def robot(calibrated):
    """A connected, calibrated gripper on the rig (calibrated by the scripted operator)."""
    from lerobot_blindgrasp.robots.blindgrasp_gripper import BlindgraspGripper

    r = BlindgraspGripper(calibrated)
    r.connect()
    yield r
    if r.is_connected:
        r.disconnect()
