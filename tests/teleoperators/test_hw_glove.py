"""The manus_glove teleoperator against the emulated SDK bridge (UDP), and its stream protocol."""

from __future__ import annotations

import time
from pathlib import Path

import draccus
import numpy as np
import pytest
from emulators.glove_sender import GloveEmulator, free_udp_port
from lerobot.teleoperators.config import TeleoperatorConfig

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.robots.blindgrasp_gripper import BlindgraspGripper, BlindgraspGripperConfig
from lerobot_blindgrasp.teleoperators.manus_glove import ManusGlove, ManusGloveConfig
from lerobot_blindgrasp.teleoperators.manus_glove.manus_glove import GloveStreamLost
from lerobot_blindgrasp.teleoperators.manus_glove.protocol import decode, encode
from lerobot_blindgrasp.teleoperators.manus_glove.retarget import REQUIRED_KEYS

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture
def glove():
    with GloveEmulator(free_udp_port()) as g:
        yield g


def _operator(glove):
    def answer(prompt: str = "") -> str:
        glove.closure = 0.0 if "OPEN HAND" in prompt else 1.0
        time.sleep(0.05)  # the hand gets there before ENTER
        return ""

    return answer


@pytest.fixture
def teleop(glove, tmp_path, monkeypatch):
    monkeypatch.setattr("builtins.input", _operator(glove))
    t = ManusGlove(ManusGloveConfig(id="op", port=glove.addr[1], calibration_dir=tmp_path, calibration_s=0.2))
    t.connect()
    yield t
    if t.is_connected:
        t.disconnect()


def _action(teleop, glove, closure: float) -> np.ndarray:
    glove.closure = closure
    assert teleop.receiver.wait_frames(3, 2.0)  # the first may have been built before the change
    a = teleop.get_action()
    return np.array([a[k] for k in spec.ACTION_NAMES])


def test_protocol_round_trip_and_rejections():
    ergo = {k: float(i) for i, k in enumerate(sorted(REQUIRED_KEYS))}
    d = decode(encode("s1", 7, 12.5, ergo, "left"), REQUIRED_KEYS)
    assert (d.session, d.seq, d.sent, d.side, d.ergonomics) == ("s1", 7, 12.5, "left", ergo)
    old_proto = b'{"proto": "blindgrasp-glove/1", "seq": 1, "t": 1.0, "side": "right", "ergonomics": {}}'
    for bad, why in [
        (b"\xff\xfe garbage", "not JSON"),
        (b'{"proto": "other/1", "seq": 1}', "not a blindgrasp-glove/2"),
        (old_proto, "update the bridge"),
        (encode("s", 1, 0.0, dict.fromkeys(sorted(REQUIRED_KEYS)[1:], 0.0)), "lacks"),
        (encode("s", 1, 0.0, {**ergo, "IndexMCPSpread": float("nan")}), "non-finite"),
        (encode("s", 1, 0.0, {**ergo, "IndexMCPSpread": 400.0}), "out of range"),
        (encode("s", 1, float("inf"), ergo), "sent"),
        (encode("no spaces!", 1, 0.0, ergo), "session"),
        (encode("s", 1, 0.0, {**ergo, "LeftFingerIndexMCPStretch": 3.0}, "right"), "left-hand channel"),
        (encode("s", 1, 0.0, {**ergo, "IndexSpread": 99.0}), "two different values for IndexMCPSpread"),
    ]:
        with pytest.raises(ValueError, match=why):
            decode(bad, REQUIRED_KEYS)


def test_action_keys_are_the_robot_action_keys(tmp_path):
    teleop = ManusGlove(ManusGloveConfig(id="x", calibration_dir=tmp_path))
    robot = BlindgraspGripper(BlindgraspGripperConfig(id="x", calibration_dir=tmp_path))
    assert teleop.action_features == robot.action_features
    assert teleop.feedback_features == {}


def test_config_file_parses():
    with open(ROOT / "robot_configs" / "manus_glove.yaml") as f, draccus.config_type("yaml"):
        cfg = draccus.load(TeleoperatorConfig, f)
    assert isinstance(cfg, ManusGloveConfig) and cfg.port == ManusGloveConfig().port
    np.testing.assert_allclose(cfg.open_pose, spec.HOME_POSE)


def test_open_hand_and_fist_map_to_the_calibrated_gripper_poses(teleop, glove):
    cfg = teleop.config
    np.testing.assert_allclose(_action(teleop, glove, 0.0), cfg.open_pose, atol=1e-9)
    flex = [1, 2, 4, 5, 7, 8]  # spread (J*0) follows the hand's spread, which a fist changes a little
    np.testing.assert_allclose(_action(teleop, glove, 1.0)[flex], np.array(cfg.closed_pose)[flex], atol=1e-9)
    half = _action(teleop, glove, 0.5)
    mid = (np.array(cfg.open_pose) + np.array(cfg.closed_pose)) / 2
    np.testing.assert_allclose(half[flex], mid[flex], atol=1e-9)
    assert np.all(half >= spec.JOINT_LOWER) and np.all(half <= spec.JOINT_UPPER)
    # Spread: relative to the open hand, in rad per rad.
    glove.spread_offset_deg = 10.0
    spread = _action(teleop, glove, 0.0)[[0, 3, 6]]
    np.testing.assert_allclose(spread, np.radians(10.0), atol=1e-9)


def test_calibration_is_saved_per_operator_and_reloaded(teleop, glove):
    assert teleop.calibration_fpath.is_file()
    again = ManusGlove(teleop.config)
    assert again.is_calibrated and again.calibration == teleop.calibration


def test_calibration_refuses_a_fist_that_did_not_close(glove, tmp_path, monkeypatch):
    monkeypatch.setattr("builtins.input", lambda prompt="": "")  # the operator never makes a fist
    t = ManusGlove(ManusGloveConfig(id="lazy", port=glove.addr[1], calibration_dir=tmp_path, calibration_s=0.1))
    with pytest.raises(ValueError, match="changed by less than"):
        t.connect()
    t.disconnect()
    assert not (tmp_path / "lazy.json").exists()


def test_a_gap_holds_the_last_target_and_a_loss_raises(teleop, glove):
    before = _action(teleop, glove, 0.3)
    glove.paused = True
    time.sleep(0.3)  # > hold_timeout_s
    glove.closure = 1.0
    held = np.array([teleop.get_action()[k] for k in spec.ACTION_NAMES])
    np.testing.assert_array_equal(held, before)  # motion stops: the target does not change
    time.sleep(teleop.config.disconnect_timeout_s)
    with pytest.raises(GloveStreamLost, match="Glove stream lost"):
        teleop.get_action()
    glove.paused = False  # the bridge comes back: teleoperation resumes with fresh data
    time.sleep(0.1)
    np.testing.assert_allclose(_action(teleop, glove, 1.0)[1:3], teleop.config.closed_pose[1:3], atol=1e-9)


def test_garbage_and_reordered_datagrams_are_ignored(teleop, glove):
    glove.garbage_every, glove.reorder = 3, True
    for closure in (0.2, 0.8):
        np.testing.assert_allclose(_action(teleop, glove, closure)[[1, 2]],
                                   _expected_flex(teleop, closure), atol=0.05)  # fmt: skip
    assert teleop.receiver.rejected > 0


def _expected_flex(teleop, closure):
    lo, hi = np.array(teleop.config.open_pose)[[1, 2]], np.array(teleop.config.closed_pose)[[1, 2]]
    return lo + closure * (hi - lo)


def test_connect_without_a_bridge_is_a_clear_error(tmp_path):
    t = ManusGlove(ManusGloveConfig(id="x", port=free_udp_port(), calibration_dir=tmp_path, connect_timeout_s=0.3))
    with pytest.raises(ConnectionError, match="no datagram arrived: is the bridge running"):
        t.connect()
    assert not t.is_connected
