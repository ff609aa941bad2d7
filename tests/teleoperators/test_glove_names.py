"""The glove names (issue 43 item 3): the MANUS SDK's ergonomics names and the ROS 2 publisher's strings are both
accepted, through the one table of manus_bridge.py, which docs/glove.md prints; a datagram lacking a channel the
retargeting needs is reported at WARNING, once, by name; connect says why arriving data was not used."""

from __future__ import annotations

import json
import logging
import re
import socket
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from emulators.glove_sender import FIST, OPEN, GloveEmulator, free_udp_port

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.teleoperators.manus_glove import ManusGlove, ManusGloveConfig, manus_bridge
from lerobot_blindgrasp.teleoperators.manus_glove import retarget as rt
from lerobot_blindgrasp.teleoperators.manus_glove.protocol import GloveSender, decode, encode

DOC = Path(__file__).resolve().parents[2] / "docs" / "glove.md"

# As ManusSDKTypes.h spells them (typedef enum ErgonomicsDataType; the first, Invalid, is commented out so that
# LeftFingerThumbMCPSpread is 0), and as the MANUS ROS 2 publisher's ErgonomicsDataTypeToString returns them.
SDK_ENUM_RIGHT_INDEX = ("ErgonomicsDataType_RightFingerIndexMCPSpread", 24)
ROS2_STRINGS = ["ThumbMCPSpread", "ThumbMCPStretch", "ThumbPIPStretch", "ThumbDIPStretch",
                "IndexSpread", "IndexMCPStretch", "IndexPIPStretch", "IndexDIPStretch",
                "MiddleSpread", "MiddleMCPStretch", "MiddlePIPStretch", "MiddleDIPStretch",
                "RingSpread", "RingMCPStretch", "RingPIPStretch", "RingDIPStretch",
                "PinkySpread", "PinkyMCPStretch", "PinkyPIPStretch", "PinkyDIPStretch"]  # fmt: skip


def _doc_rows() -> list[list[str]]:
    text = DOC.read_text()
    table = text.split("<!-- names-table:start -->")[1].split("<!-- names-table:end -->")[0]
    rows = [
        [c.strip().strip("`") for c in line.strip().strip("|").split("|")] for line in table.strip().splitlines()
    ]
    return rows[2:]  # header, rule


def test_the_documented_table_is_the_code_table():
    use: dict[str, list[str]] = {}
    for joint, (kind, keys) in zip(spec.JOINT_NAMES, rt.CHANNELS, strict=True):
        for k in keys:
            use.setdefault(k, []).append(f"{joint} ({kind})")
    expected = [[c.name, c.enum_name("right"), f"{c.enum_value('left')} / {c.enum_value('right')}", c.ros2,
                 ", ".join(use.get(c.name, ["-"]))] for c in manus_bridge.CHANNELS]  # fmt: skip
    assert _doc_rows() == expected
    assert rt.REQUIRED_KEYS <= {c.name for c in manus_bridge.CHANNELS} and len(rt.REQUIRED_KEYS) == 12


def test_the_names_are_the_sdk_and_publisher_spellings():
    name, value = SDK_ENUM_RIGHT_INDEX
    c = next(c for c in manus_bridge.CHANNELS if c.name == "IndexMCPSpread")
    assert (c.enum_name("right"), c.enum_value("right")) == (name, value)
    assert [c.ros2 for c in manus_bridge.CHANNELS] == ROS2_STRINGS
    assert manus_bridge.CHANNELS[-1].enum_value("right") == 39  # ErgonomicsDataType_MAX_SIZE = 40


@pytest.mark.parametrize("style", ["channel", "ros2", "enum", "enum_no_prefix"])
def test_every_accepted_spelling_decodes_to_the_same_channels(style):
    def key(c):
        return {"channel": c.name, "ros2": c.ros2, "enum": c.enum_name("left"),
                "enum_no_prefix": c.enum_name("left").removeprefix("ErgonomicsDataType_")}[style]  # fmt: skip

    ergonomics = {key(c): OPEN[c.name] for c in manus_bridge.CHANNELS} | {"Invalid": 0.0}
    d = decode(encode("spellings", 1, 0.0, ergonomics, "left"), rt.REQUIRED_KEYS)
    assert d.ergonomics == {k: OPEN[k] for k in rt.REQUIRED_KEYS}


def _documented_python_sender() -> str:
    """The ```python block of docs/glove.md that builds datagrams with this package's sender."""
    blocks = re.findall(r"^```python\n(.*?)^```", DOC.read_text(), flags=re.M | re.S)
    [block] = [b for b in blocks if "GloveSender(" in b]
    return block


def test_an_sdk_array_through_the_documented_python_sender(monkeypatch):
    """docs/glove.md's Python sender, run as the page prints it (only its two port numbers swapped for free ones),
    next to a copy of manus_bridge.py as on the MANUS machine: ErgonomicsData.data (40 floats by
    ErgonomicsDataType) -> the datagram the receiver decodes."""
    monkeypatch.syspath_prepend(str(Path(manus_bridge.__file__).parent))
    block = _documented_python_sender()
    assert "50120" in block and "source_port=50121" in block
    data = [float(i) for i in range(40)]  # value = its enum index, so a wrong index shows
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as rx:
        rx.bind(("127.0.0.1", 0))
        rx.settimeout(5.0)
        source = free_udp_port()
        code = block.replace("50120", str(rx.getsockname()[1])).replace("50121", str(source))
        scope: dict = {}
        exec(compile(code, f"{DOC}:python sender", "exec"), scope)
        try:
            scope["on_ergonomics"](data)
            datagram, addr = rx.recvfrom(65536)
        finally:
            scope["sender"].close()
            sys.modules.pop("manus_bridge", None)  # the top-level copy the block imported, as on the MANUS machine
    assert addr[1] == source
    d = decode(datagram, rt.REQUIRED_KEYS)
    assert d.side == "right" and d.seq == 1
    assert d.ergonomics["ThumbMCPSpread"] == 20.0 and d.ergonomics["IndexMCPSpread"] == 24.0
    assert d.ergonomics["MiddleDIPStretch"] == 31.0
    assert set(d.ergonomics) == set(rt.REQUIRED_KEYS)  # decode keeps the channels the retargeting uses


def _teleop(tmp_path, port, **kw) -> ManusGlove:
    (tmp_path / "op.json").write_text(json.dumps({"open": OPEN, "fist": FIST}))
    return ManusGlove(ManusGloveConfig(id="op", port=port, calibration_dir=tmp_path, **kw))


def test_the_ros2_publishers_strings_drive_the_gripper(tmp_path):
    port = free_udp_port()
    with GloveEmulator(port, keys="ros2") as glove:
        teleop = _teleop(tmp_path, port)
        teleop.connect()
        try:
            glove.closure, glove.spread_offset_deg = 1.0, 10.0
            assert teleop.receiver.wait_frames(3, 2.0)
            a = teleop.get_action()
            q = np.array([a[k] for k in spec.ACTION_NAMES])
            np.testing.assert_allclose(q[[1, 2]], teleop.config.closed_pose[1:3], atol=1e-9)
            assert q[0] == pytest.approx(np.radians(10.0 - 5.0))  # IndexSpread: fist -3 deg +10 against open 2 deg
        finally:
            teleop.disconnect()


def test_an_old_calibration_file_keyed_by_the_publishers_strings_still_loads(tmp_path):
    ros2 = {c.name: c.ros2 for c in manus_bridge.CHANNELS}
    (tmp_path / "op.json").write_text(json.dumps({"open": {ros2[k]: v for k, v in OPEN.items()},
                                                  "fist": {ros2[k]: v for k, v in FIST.items()}}))  # fmt: skip
    t = ManusGlove(ManusGloveConfig(id="op", calibration_dir=tmp_path))
    assert t.calibration_error is None and t.calibration.open["IndexMCPSpread"] == OPEN["IndexMCPSpread"]


def test_a_missing_channel_is_warned_once_by_name_and_connect_says_why(tmp_path, caplog):
    port = free_udp_port()
    teleop = _teleop(tmp_path, port, connect_timeout_s=0.5)
    sender = GloveSender("127.0.0.1", port, "right")
    without = {k: v for k, v in OPEN.items() if k != "IndexMCPSpread"}  # a publisher copy that skips it
    with caplog.at_level(logging.WARNING):
        stop = threading.Event()

        def send():
            while not stop.wait(0.01):
                sender.send(without)

        th = threading.Thread(target=send)
        th.start()
        try:
            with pytest.raises(ConnectionError) as e:
                teleop.connect()
        finally:
            stop.set()
            th.join()
            sender.close()
    msg = str(e.value)
    assert re.search(r"\d+ datagrams arrived, 0 used; \d+ rejected \(last: ergonomics lacks \['IndexMCPSpread'\]\)",
                     msg), msg  # fmt: skip
    warnings = [
        r for r in caplog.records if r.levelno == logging.WARNING and "lack the channels" in r.getMessage()
    ]
    assert len(warnings) == 1 and "['IndexMCPSpread']" in warnings[0].getMessage()


def test_the_other_hand_and_an_old_bridge_are_named_at_connect(tmp_path):
    port = free_udp_port()
    teleop = _teleop(tmp_path, port, connect_timeout_s=0.3)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        left = GloveSender("127.0.0.1", port, "left")
        teleop.receiver.start()
        try:
            left.send(OPEN)
            s.sendto(json.dumps({"proto": "blindgrasp-glove/1", "seq": 1, "t": time.time(), "side": "right",
                                 "ergonomics": OPEN}).encode(), ("127.0.0.1", port))  # fmt: skip
            deadline = time.monotonic() + 5.0
            while teleop.receiver.received < 2 and time.monotonic() < deadline:
                time.sleep(0.01)
            why = teleop.receiver.diagnosis()
        finally:
            teleop.receiver.stop()
            left.close()
    assert "1 for the left hand (this teleoperator is --teleop.side=right)" in why
    assert "update the bridge" in why


def test_a_zero_spread_gain_makes_that_spread_optional(tmp_path, monkeypatch):
    """The way around a publisher that drops IndexMCPSpread: the first finger's abduction stays at the open pose."""
    without = {k: v for k, v in OPEN.items() if k != "IndexMCPSpread"}
    assert rt.required_keys([0.0, 1.0, 1.0]) == rt.REQUIRED_KEYS - {"IndexMCPSpread"}
    port = free_udp_port()
    sender = GloveSender("127.0.0.1", port, "right")
    pose = {"now": without}

    def operator(prompt: str = "") -> str:  # the operator makes the pose the prompt asks for, then ENTER
        pose["now"] = (
            without if "OPEN HAND" in prompt else {k: v for k, v in FIST.items() if k != "IndexMCPSpread"}
        )
        time.sleep(0.05)
        return ""

    monkeypatch.setattr("builtins.input", operator)
    stop = threading.Event()

    def send():
        while not stop.wait(0.01):
            sender.send(pose["now"])

    th = threading.Thread(target=send)
    th.start()
    teleop = ManusGlove(ManusGloveConfig(id="nospread", port=port, calibration_dir=tmp_path, calibration_s=0.2,
                                         spread_gain=[0.0, 1.0, 1.0]))  # fmt: skip
    try:
        teleop.connect()  # calibrates: open hand, then fist
        assert teleop.receiver.wait_frames(3, 2.0)
        a = teleop.get_action()
        assert a["ff_j10.pos"] == teleop.config.open_pose[0] and a["ff_j11.pos"] == pytest.approx(
            teleop.config.closed_pose[1], abs=1e-9)  # fmt: skip
        saved = json.loads((tmp_path / "nospread.json").read_text())
        assert "IndexMCPSpread" not in saved["open"] and "MiddleMCPSpread" in saved["open"]
    finally:
        stop.set()
        th.join()
        teleop.disconnect()
        sender.close()
