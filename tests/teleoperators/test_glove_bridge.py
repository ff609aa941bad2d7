"""`blindgrasp-glove-bridge` (issue 43 item 3): the MANUS ROS 2 publisher's `manus_ros2_msgs/msg/ManusGlove`
messages -> glove datagrams. The mapping is pure and is tested here on messages shaped as the publisher sends
them (objects with its fields, and the dicts `rosidl_runtime_py.message_to_ordereddict` makes of them), then
forwarded over UDP to the real teleoperator. ROS 2 itself is not needed: without it the command says so."""

from __future__ import annotations

import json
import sys
import threading
from importlib.metadata import entry_points
from types import SimpleNamespace

import numpy as np
import pytest
from emulators.glove_sender import FIST, OPEN, free_udp_port

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.teleoperators.manus_glove import ManusGlove, ManusGloveConfig
from lerobot_blindgrasp.teleoperators.manus_glove.manus_bridge import (
    CHANNELS,
    BridgeConfig,
    BridgeError,
    GloveBridge,
    ergonomics_from_message,
    run_bridge,
)
from lerobot_blindgrasp.teleoperators.manus_glove.protocol import GloveSender


def _publisher_message(side: str, pose: dict[str, float], glove_id: int = 1234, drop=(), invalid=()):
    """A ManusGlove as manus_data_publisher fills it: per glove, the 20 ergonomics of its side in enum order, each
    a ManusErgonomics(type=<side-less string>, value=<deg>), plus the raw skeleton (not used by the bridge)."""
    ergonomics = [SimpleNamespace(type="Invalid" if c.name in invalid else c.ros2, value=pose[c.name])
                  for c in CHANNELS if c.name not in drop]  # fmt: skip
    node = SimpleNamespace(node_id=0, parent_node_id=0, joint_type="Invalid", chain_type="Hand",
                           pose=SimpleNamespace(position=SimpleNamespace(x=0.0, y=0.0, z=0.0)))  # fmt: skip
    return SimpleNamespace(glove_id=glove_id, side=side, raw_node_count=1, raw_nodes=[node],
                           ergonomics_count=len(ergonomics), ergonomics=ergonomics, raw_sensor_count=0,
                           raw_sensor=[])  # fmt: skip


def _as_dict(msg) -> dict:
    return {"glove_id": msg.glove_id, "side": msg.side, "ergonomics_count": msg.ergonomics_count,
            "ergonomics": [{"type": e.type, "value": e.value} for e in msg.ergonomics]}  # fmt: skip


def test_a_publisher_message_maps_to_the_channels():
    side, ergo, unknown = ergonomics_from_message(_publisher_message("Right", OPEN))
    assert side == "right" and ergo == OPEN and unknown == []
    side, ergo, _ = ergonomics_from_message(_as_dict(_publisher_message("Left", FIST)))
    assert side == "left" and ergo == FIST
    _, ergo, unknown = ergonomics_from_message(_publisher_message("Right", OPEN, invalid={"IndexMCPSpread"}))
    assert "IndexMCPSpread" not in ergo and unknown == ["Invalid"]
    for bad, why in [
        (_publisher_message("Invalid", OPEN), "not Left or Right"),
        ({"side": "Right"}, "ergonomics"),
    ]:
        with pytest.raises(ValueError, match=why):
            ergonomics_from_message(bad)


@pytest.fixture
def teleop(tmp_path):
    (tmp_path / "op.json").write_text(json.dumps({"open": OPEN, "fist": FIST}))
    port = free_udp_port()
    bridge = GloveBridge(BridgeConfig(port=port, side="right", source_port=0))
    # As across machines: listen on every interface, and accept only the pinned bridge.
    sender = f"127.0.0.1:{bridge.sender.source[1]}"
    t = ManusGlove(ManusGloveConfig(id="op", host="0.0.0.0", port=port, sender=sender, calibration_dir=tmp_path))
    yield t, bridge
    if t.is_connected:
        t.disconnect()
    bridge.sender.close()


class _Executor:
    """Calls the bridge's callback at 100 Hz with the newest message, as rclpy.spin does for the subscription."""

    def __init__(self, bridge: GloveBridge, msg):
        self.msg, self._stop = msg, threading.Event()
        self._thread = threading.Thread(target=self._spin, args=(bridge,), daemon=True)

    def _spin(self, bridge):
        while not self._stop.wait(0.01):
            bridge.forward(self.msg)

    def __enter__(self):
        self._thread.start()
        return self

    def __exit__(self, *exc):
        self._stop.set()
        self._thread.join()


def test_forwarded_messages_drive_the_teleoperator(teleop):
    t, bridge = teleop
    with _Executor(bridge, _publisher_message("Right", OPEN)) as ros:
        t.connect()  # calibrated from the file
        ros.msg = _publisher_message("Right", FIST)
        assert t.receiver.wait_frames(3, 2.0), t.receiver.diagnosis()
        q = np.array([t.get_action()[k] for k in spec.ACTION_NAMES])
    flex = [1, 2, 4, 5, 7, 8]
    np.testing.assert_allclose(q[flex], np.array(t.config.closed_pose)[flex], atol=1e-9)
    assert bridge.forwarded >= 3 and bridge.sender.session in bridge.status()
    assert not bridge.forward(_publisher_message("Left", OPEN)) and bridge.other_hand == 1  # the other glove
    assert not bridge.forward({"side": "Right"}) and bridge.bad == 1  # never raises into the ROS executor


def test_a_message_without_the_index_spread_is_warned_about_by_name(teleop, caplog):
    _, bridge = teleop
    msg = _publisher_message("Right", OPEN, drop={"IndexMCPSpread"})
    for _ in range(3):
        assert bridge.forward(msg)
    warned = [r.getMessage() for r in caplog.records if "lack" in r.getMessage()]
    assert len(warned) == 1 and "['IndexMCPSpread']" in warned[0]


def test_without_ros2_the_command_says_what_to_source(monkeypatch):
    monkeypatch.setitem(sys.modules, "rclpy", None)  # as on a machine without ROS 2, even if one is installed
    with pytest.raises(BridgeError, match=r"rclpy is not importable.*source /opt/ros/<distro>/setup.bash"):
        run_bridge(BridgeConfig(source_port=0))


def test_the_console_script_parses_its_config(capsys):
    (entry,) = [e for e in entry_points(group="console_scripts") if e.name == "blindgrasp-glove-bridge"]
    main = (
        entry.load()
    )  # the installed command's function, in this process: a new one would import the package again
    with pytest.raises(SystemExit) as e:
        main(["--help"])
    out = capsys.readouterr().out
    assert e.value.code == 0 and "--source_port" in out and "manus_glove_0" in out
    with pytest.raises(SystemExit, match="side must be 'left' or 'right'"):
        main(["--side=both"])


def test_a_restarted_bridge_keeps_its_address():
    a = GloveSender("127.0.0.1", 9, "right", source_host="127.0.0.1", source_port=0)
    port = a.source[1]
    a.close()
    b = GloveSender("127.0.0.1", 9, "right", source_host="127.0.0.1", source_port=port)  # the same fixed port
    try:
        assert b.source == ("127.0.0.1", port) and b.session != a.session
    finally:
        b.close()


def test_a_network_error_does_not_stop_the_bridge(caplog):
    """sendto fails while the link is down (here: broadcast without SO_BROADCAST, which the kernel refuses); the
    callback must not raise into the ROS executor, and says so once."""
    bridge = GloveBridge(BridgeConfig(source_port=0))
    bridge.sender.addr = ("255.255.255.255", 50120)
    try:
        assert not bridge.forward(_publisher_message("Right", OPEN))
        assert not bridge.forward(_publisher_message("Right", OPEN))
    finally:
        bridge.sender.close()
    assert bridge.send_errors == 2 and bridge.forwarded == 0 and "2 not sent" in bridge.status()
    assert sum("Cannot send to 255.255.255.255:50120" in r.getMessage() for r in caplog.records) == 1
