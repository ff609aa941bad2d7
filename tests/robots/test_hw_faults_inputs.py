"""Fault injection on the inputs that are not the servo bus: the calibration files (gripper and glove), a corrupt
robot config, and the glove's datagrams (hostile ones, a restarted bridge, a second glove). Split from
`test_hw_faults.py` and `test_hw_faults_trust.py`; the rows of docs/hardware.md's hazard analysis name them.
"""

from __future__ import annotations

import io
import json
import logging
import re
import socket
import time
from pathlib import Path

import draccus
import numpy as np
import pytest
from emulators.glove_sender import FIST, OPEN, GloveEmulator, free_udp_port
from lerobot.robots.config import RobotConfig
from lerobot.teleoperators.config import TeleoperatorConfig

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.robots.blindgrasp_gripper import BlindgraspGripper
from lerobot_blindgrasp.robots.blindgrasp_gripper.servo_calibration import CalibrationFileError
from lerobot_blindgrasp.teleoperators.manus_glove import ManusGlove, ManusGloveConfig
from lerobot_blindgrasp.teleoperators.manus_glove.manus_glove import GloveCalibrationError
from lerobot_blindgrasp.teleoperators.manus_glove.protocol import PROTO


def _assert_stopped(rig, robot):
    assert not robot.is_connected
    assert not rig.dxl.any_torque()


def _no_prompt(monkeypatch):
    def prompt(text=""):
        raise AssertionError(f"unexpected interactive prompt: {text!r}")

    monkeypatch.setattr("builtins.input", prompt)


# --- 6. calibration files ------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "edit,why",
    [
        (lambda c: c.pop("mf_j21"), r"joints \['mf_j21'\] are missing"),
        (lambda c: c["th_j30"].update(drive_mode=3), "th_j30: drive_mode 3"),
        (lambda c: c["ff_j10"].update(id=99), "ff_j10: servo ID 99"),
        (lambda c: c["ff_j12"].update(range_min=3000, range_max=100), r"ff_j12: range \[3000, 100\]"),
        (lambda c: c["ff_j11"].pop("homing_offset"), r"ff_j11: lacks \['homing_offset'\]"),
    ],
)
def test_bad_calibration_file_is_refused_before_any_motion(rig, robot, monkeypatch, edit, why):
    robot.disconnect()
    cal = json.loads(robot.calibration_fpath.read_text())
    edit(cal)
    robot.calibration_fpath.write_text(json.dumps(cal))
    _no_prompt(monkeypatch)
    packets = sum(rig.dxl.instruction_counts.values())
    r = BlindgraspGripper(rig.robot_config(robot.calibration_dir))
    with pytest.raises(CalibrationFileError, match=why):
        r.connect()
    assert sum(rig.dxl.instruction_counts.values()) == packets  # the port was never even opened
    assert not r.is_connected and not rig.dxl.any_torque()


def test_lerobot_calibrate_replaces_a_bad_file(rig, robot, monkeypatch):
    robot.disconnect()
    robot.calibration_fpath.write_text("{not json")
    monkeypatch.setattr("builtins.input", rig.calibration_inputs())
    r = BlindgraspGripper(rig.robot_config(robot.calibration_dir))
    r.connect(calibrate=False)  # what lerobot-calibrate does
    r.calibrate()
    r.disconnect()
    assert BlindgraspGripper(rig.robot_config(robot.calibration_dir)).calibration_error is None


def _glove_calibration(fpath: Path, open_pose: dict, fist_pose: dict) -> None:
    fpath.parent.mkdir(parents=True, exist_ok=True)
    fpath.write_text(json.dumps({"open": open_pose, "fist": fist_pose}))


def test_degenerate_glove_calibration_file_is_refused(tmp_path, monkeypatch):
    from emulators.glove_sender import OPEN

    _no_prompt(monkeypatch)
    cfg = ManusGloveConfig(id="op", port=free_udp_port(), calibration_dir=tmp_path)
    _glove_calibration(tmp_path / "op.json", OPEN, OPEN)  # both poses equal: retargeting would divide by zero
    t = ManusGlove(cfg)
    assert t.calibration is None
    with pytest.raises(GloveCalibrationError, match="changed by less than"):
        t.connect()
    assert not t.is_connected
    _glove_calibration(tmp_path / "op.json", {k: v for k, v in OPEN.items() if k != "IndexMCPSpread"}, OPEN)
    with pytest.raises(GloveCalibrationError, match=r"open pose lacks \['IndexMCPSpread'\]"):
        ManusGlove(cfg).connect()


# --- 7. streams: restarts and hostile input ------------------------------------------------------------------------
@pytest.fixture
def glove_teleop(tmp_path, monkeypatch):
    from emulators.glove_sender import FIST, OPEN

    _no_prompt(monkeypatch)
    port = free_udp_port()
    _glove_calibration(tmp_path / "op.json", OPEN, FIST)
    with GloveEmulator(port) as glove:
        t = ManusGlove(ManusGloveConfig(id="op", port=port, calibration_dir=tmp_path))
        t.connect()
        yield t, glove
        if t.is_connected:
            t.disconnect()


def _proximal(teleop, glove, closure: float) -> float:
    glove.closure = closure
    assert teleop.receiver.wait_frames(3, 2.0)  # the first may have been built before the change
    return teleop.get_action()["ff_j11.pos"]


HOSTILE = [
    b"",
    b"\xff\xfe",
    b"[]",
    b"null",
    b"1e999",
    b"[" * 100_000,  # not a message; deep nesting
    b'{"proto": "blindgrasp-glove/2", "session": "s", "seq": 1, "sent": 0, "side": "right", '
    b'"ergonomics": {"IndexMCPSpread": NaN}}',
    b'{"proto": "blindgrasp-glove/2", "session": "s", "seq": 1, "sent": 0, "side": "right", "ergonomics": [1, 2]}',
]


def _message(seq, value, side="right", session="hostile", sent=0.0) -> bytes:
    from emulators.glove_sender import OPEN

    ergo = dict(OPEN)
    ergo["IndexMCPStretch"] = value
    msg = {"proto": PROTO, "session": session, "seq": seq, "sent": sent, "side": side, "ergonomics": ergo}
    return json.dumps(msg).encode()


def test_glove_receiver_survives_any_datagram(glove_teleop):
    teleop, glove = glove_teleop
    hostile = HOSTILE + [
        _message(10**6, "Infinity").replace(b'"Infinity"', b"Infinity"),
        _message(10**6, 0).replace(b'"IndexMCPStretch": 0', b'"IndexMCPStretch": 1' + b"0" * 400),  # > float max
        _message(10**6, 1e300),
        _message(10**6, True),
        _message("abc", 5.0),
        _message(-1, 5.0),
        _message(2**40, 5.0),
        _message(1.5, 5.0),
        _message(10**6, 5.0, side={"x": 1}),
        _message(10**6, 5.0, session=""),
        _message(10**6, 5.0, session=["a"]),
        _message(10**6, 5.0, sent="now"),
        _message(10**6, 5.0, sent=True),
    ]
    before = teleop.receiver.rejected
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        for d in hostile:
            s.sendto(d[:65000], glove.addr)
    time.sleep(0.1)
    assert teleop.receiver.rejected - before >= len(hostile) - 1  # the 100 kB one is cut and still rejected
    assert teleop.receiver._thread.is_alive()
    a = np.array(list(teleop.get_action().values()))
    assert np.all(np.isfinite(a)) and np.all(a >= spec.JOINT_LOWER) and np.all(a <= spec.JOINT_UPPER)
    assert _proximal(teleop, glove, 1.0) == pytest.approx(teleop.config.closed_pose[1], abs=1e-9)


def test_glove_bridge_restart_resets_the_counter(glove_teleop, caplog):
    teleop, glove = glove_teleop
    glove.sender.seq = 50_000
    assert _proximal(teleop, glove, 0.0) == pytest.approx(teleop.config.open_pose[1], abs=1e-9)
    with caplog.at_level(logging.WARNING):
        glove.restart()  # the bridge restarted: a new session, counting from 1
        assert _proximal(teleop, glove, 1.0) == pytest.approx(teleop.config.closed_pose[1], abs=1e-9)
    assert teleop.receiver.restarts == 1 and "Glove bridge restarted" in caplog.text


def test_reconnecting_to_a_running_bridge(glove_teleop):
    teleop, glove = glove_teleop
    assert _proximal(teleop, glove, 1.0) == pytest.approx(teleop.config.closed_pose[1], abs=1e-9)
    teleop.disconnect()
    glove.restart()  # and it restarted meanwhile
    teleop.connect()
    assert _proximal(teleop, glove, 0.0) == pytest.approx(teleop.config.open_pose[1], abs=1e-9)


# --- glove datagrams -----------------------------------------------------------------------------------------------
def _glove_files(tmp_path):
    (tmp_path / "op.json").write_text(json.dumps({"open": OPEN, "fist": FIST}))


def test_one_glove_per_teleoperator(tmp_path, monkeypatch, caplog):
    _no_prompt(monkeypatch)
    _glove_files(tmp_path)
    port = free_udp_port()
    cfg = ManusGloveConfig(id="op", port=port, calibration_dir=tmp_path)
    with GloveEmulator(port) as first, GloveEmulator(port) as intruder:
        first.closure, intruder.closure = 0.0, 1.0
        intruder.paused = True  # the teleoperator binds to the first valid sender
        teleop = ManusGlove(cfg)
        teleop.connect()
        try:
            intruder.paused = False
            with caplog.at_level(logging.WARNING):
                time.sleep(0.2)
                for _ in range(5):
                    assert teleop.get_action()["ff_j11.pos"] == pytest.approx(cfg.open_pose[1], abs=1e-9)
                    time.sleep(0.02)
            assert teleop.receiver.foreign > 5
            assert caplog.text.count("Dropping glove datagrams from") == 1  # warned once per sender
            first.paused = (
                True  # the bound bridge goes away: no takeover, the target holds, then the stream is lost
            )
            time.sleep(cfg.hold_timeout_s + 0.05)
            assert teleop.get_action()["ff_j11.pos"] == pytest.approx(cfg.open_pose[1], abs=1e-9)
            teleop.disconnect()  # changing the sender takes a reconnect
            teleop.connect()
            assert teleop.receiver.bound == intruder.source
            assert teleop.receiver.wait_frames(3, 2.0)
            assert teleop.get_action()["ff_j11.pos"] == pytest.approx(cfg.closed_pose[1], abs=1e-9)
        finally:
            if teleop.is_connected:
                teleop.disconnect()


def test_a_configured_glove_sender_is_the_only_one_accepted(tmp_path, monkeypatch):
    _no_prompt(monkeypatch)
    _glove_files(tmp_path)
    port = free_udp_port()
    with GloveEmulator(port) as other, GloveEmulator(port) as bridge:
        other.closure, bridge.closure = 1.0, 0.0
        host, src = bridge.source
        teleop = ManusGlove(ManusGloveConfig(id="op", port=port, calibration_dir=tmp_path, sender=f"{host}:{src}"))
        teleop.connect()
        try:
            assert teleop.receiver.wait_frames(5, 2.0)
            assert teleop.get_action()["ff_j11.pos"] == pytest.approx(teleop.config.open_pose[1], abs=1e-9)
            assert teleop.receiver.foreign > 0
        finally:
            teleop.disconnect()
    with pytest.raises(ValueError, match="host:port"):
        ManusGloveConfig(sender="localhost")


# --- calibration and config files ----------------------------------------------------------------------------------
def _file_variants(text: str, wrong_values=(True, "12", 1.5, None)):
    raw = json.loads(text)
    first = next(iter(raw))
    yield "empty", b""
    yield "half", text[: len(text) // 2].encode()
    yield "last byte cut", text.rstrip()[:-1].encode()
    yield "not UTF-8", b"\xff\xfe" + text.encode()
    yield "a list", b"[]"
    for key in list(raw[first])[:1]:
        for wrong in wrong_values:
            bad = json.loads(text)
            bad[first][key] = wrong
            yield f"{key}={wrong!r}", json.dumps(bad).encode()


def test_truncated_or_corrupt_gripper_calibration_is_refused(rig, robot, monkeypatch):
    robot.disconnect()
    _no_prompt(monkeypatch)
    good = robot.calibration_fpath.read_text()
    for name, text in _file_variants(good):
        robot.calibration_fpath.write_bytes(text)
        r = BlindgraspGripper(rig.robot_config(robot.calibration_dir))
        with pytest.raises(
            CalibrationFileError, match=r"invalid.*Run lerobot-calibrate --robot.type=blindgrasp_grip"
        ):
            r.connect()
        assert not r.is_connected, name
    assert not rig.dxl.any_torque()


def test_truncated_or_corrupt_glove_calibration_is_refused(tmp_path, monkeypatch):
    _no_prompt(monkeypatch)
    _glove_files(tmp_path)
    good = (tmp_path / "op.json").read_text()
    cfg = ManusGloveConfig(id="op", port=free_udp_port(), calibration_dir=tmp_path)
    as_bool = json.dumps({"open": OPEN, "fist": {**FIST, "IndexMCPSpread": True}}).encode()
    for _name, text in [*_file_variants(good, (True, "12", None, [1])), ("a bool for a number", as_bool)]:
        (tmp_path / "op.json").write_bytes(text)
        with pytest.raises(
            GloveCalibrationError, match=r"invalid.*Run lerobot-calibrate --teleop.type=manus_glove"
        ):
            ManusGlove(cfg).connect()


@pytest.mark.parametrize(
    "cut,why",
    [
        ("baudrate: 1000000", "baudrate 100 is not a Dynamixel rate"),
        ("  tare_s: 0.5", r"force_sensor.\['tare_s'\]"),
    ],
)
def test_a_corrupt_robot_config_is_refused(tmp_path, cut, why):
    text = (Path(__file__).resolve().parents[2] / "robot_configs" / "blindgrasp_gripper.yaml").read_text()
    broken = text.replace(cut, cut.split(":")[0] + ": " + ("100" if "baud" in cut else "0"))
    (tmp_path / "r.yaml").write_text(broken)
    with pytest.raises(Exception) as e, open(tmp_path / "r.yaml") as f, draccus.config_type("yaml"):
        draccus.load(RobotConfig, f)
    assert re.search(why, _chain(e.value)), _chain(e.value)
    with pytest.raises(Exception) as e, draccus.config_type("yaml"):
        draccus.load(TeleoperatorConfig, io.StringIO("type: manus_glove\nfrozen_frames: -3\n"))
    assert "frozen_frames must be 0 (off) or >= 2" in _chain(e.value)


def _chain(e: BaseException | None) -> str:
    """The messages of an exception and its causes (draccus wraps a config's ValueError in its own error)."""
    out = []
    while e is not None:
        out.append(str(e))
        e = e.__cause__ or e.__context__
    return " <- ".join(out)
