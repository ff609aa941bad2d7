"""Hazards of the glove datagram `blindgrasp-glove/2` (docs/hardware.md, "Hazard analysis", table "Glove
datagram": `proto`, `session`, `seq`, `sent`, `side`, `ergonomics`, source address). The decoder accepts only sane
messages (hypothesis) and the receiver survives any datagram; a restarted bridge is followed, a bridge already
behind at connect is not, a frozen glove goes stale, a second sender is dropped, and a degenerate calibration of the
operator's hand is refused. The stream's timing over a network (late, reordered, a pause's backlog, clock steps) is
`test_glove_time.py`."""

from __future__ import annotations

import json
import logging
import math
import socket
import time

import numpy as np
import pytest
from emulators.glove_sender import (
    FIST,
    OPEN,
    GloveEmulator,
    calibrated_glove,
    free_udp_port,
    write_glove_calibration,
)
from emulators.hostile import FAST, INT32, json_values
from emulators.loop import no_prompt
from hypothesis import given
from hypothesis import strategies as st

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.teleoperators.manus_glove import ManusGlove, ManusGloveConfig
from lerobot_blindgrasp.teleoperators.manus_glove.manus_glove import GloveCalibrationError, GloveStreamLost
from lerobot_blindgrasp.teleoperators.manus_glove.protocol import MAX_ABS_DEG, PROTO, decode, encode
from lerobot_blindgrasp.teleoperators.manus_glove.retarget import REQUIRED_KEYS

# --- every field: what the decoder accepts ----------------------------------------------------------------------
scalars = st.one_of(st.floats(), st.integers(), st.booleans(), st.none(), st.text(max_size=3), st.just([1.0]))


def _datagram(seq, side, values, session="fuzz", sent=0.0) -> bytes:
    msg = {"proto": PROTO, "session": session, "seq": seq, "sent": sent, "side": side, "ergonomics": values}
    return json.dumps(msg, allow_nan=True).encode()


datagrams = st.one_of(
    st.binary(max_size=200),
    json_values.map(lambda v: json.dumps(v).encode()),
    st.builds(_datagram, st.one_of(INT32, json_values), st.sampled_from(["left", "right", 3, None]),
              st.fixed_dictionaries(dict.fromkeys(REQUIRED_KEYS, scalars))),
    st.builds(lambda s, cut: encode("fuzz", s, 1.0, OPEN)[:cut], st.integers(0, 2**32 - 1), st.integers(0, 400)),
    st.builds(_datagram, st.integers(0, 2**32), st.just("left"), st.just(OPEN), json_values | st.text(max_size=70),
              json_values | st.floats()),  # session and sender clock, any JSON
    st.builds(_datagram, st.integers(0, 2**32), st.just("right"),  # valid shape, values up to and past the range
              st.fixed_dictionaries({k: st.floats(-400, 400) | st.integers(-400, 400) for k in REQUIRED_KEYS})),
)  # fmt: skip


@FAST
@given(datagram=datagrams)
def test_the_glove_decoder_accepts_only_sane_messages(datagram):
    try:
        d = decode(datagram, REQUIRED_KEYS)
    except ValueError:
        return
    assert 0 <= d.seq < 2**32 and d.side in ("left", "right") and set(d.ergonomics) == REQUIRED_KEYS
    assert (
        type(d.sent) is float and math.isfinite(d.sent) and isinstance(d.session, str) and 0 < len(d.session) <= 64
    )
    assert all(type(v) is float and math.isfinite(v) and abs(v) <= MAX_ABS_DEG for v in d.ergonomics.values())


@pytest.fixture
def glove_teleop(tmp_path, monkeypatch):
    no_prompt(monkeypatch)
    port = free_udp_port()
    write_glove_calibration(tmp_path / "op.json", OPEN, FIST)
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


# --- session and sent: a restarted bridge, one behind at connect ------------------------------------------------
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


def test_a_bridge_that_is_behind_at_connect_is_not_followed(tmp_path):
    """Every pose leaves the bridge (on this machine) already 0.5 s old: a lagging SDK, a link still draining a
    backlog when the teleoperator connects. Its first pose cannot be the reference of its own age: the shared clock
    says it is stale, and connect refuses instead of driving the gripper half a second behind the hand."""
    port = free_udp_port()
    with GloveEmulator(port) as glove:
        glove.clock_offset_s = -0.5
        teleop = calibrated_glove(tmp_path, port, connect_timeout_s=0.5)
        with pytest.raises(ConnectionError, match=r"No glove data .* queued > 0.1 s"):
            teleop.connect()


# --- ergonomics: a frozen glove, another operator's hand -------------------------------------------------------
def _until_lost(teleop, seconds: float = 3.0) -> str:
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        try:
            teleop.get_action()
        except GloveStreamLost as e:
            return str(e)
        time.sleep(0.01)
    raise AssertionError("the glove stream was never declared lost")


def test_a_frozen_glove_goes_stale_and_stops(tmp_path):
    """The glove's radio drops and the SDK keeps reporting its last values, under new numbers and stamps. With
    `frozen_frames` set, values that repeat bit for bit (a live glove's noise never does) age like silence."""
    port = free_udp_port()
    with GloveEmulator(port, rate_hz=100.0) as glove:
        glove.noise_deg = 0.2
        teleop = calibrated_glove(tmp_path, port, frozen_frames=20)
        teleop.connect()
        try:
            time.sleep(0.3)
            teleop.get_action()  # live data with its noise: followed
            glove.frozen = True
            assert "Glove stream lost" in _until_lost(teleop)
        finally:
            teleop.disconnect()


def test_degenerate_glove_calibration_file_is_refused(tmp_path, monkeypatch):
    no_prompt(monkeypatch)
    cfg = ManusGloveConfig(id="op", port=free_udp_port(), calibration_dir=tmp_path)
    write_glove_calibration(tmp_path / "op.json", OPEN, OPEN)  # both poses equal: retargeting would divide by zero
    t = ManusGlove(cfg)
    assert t.calibration is None
    with pytest.raises(GloveCalibrationError, match="changed by less than"):
        t.connect()
    assert not t.is_connected
    write_glove_calibration(tmp_path / "op.json", {k: v for k, v in OPEN.items() if k != "IndexMCPSpread"}, OPEN)
    with pytest.raises(GloveCalibrationError, match=r"open pose lacks \['IndexMCPSpread'\]"):
        ManusGlove(cfg).connect()


# --- source address: one sender --------------------------------------------------------------------------------
def test_one_glove_per_teleoperator(tmp_path, monkeypatch, caplog):
    no_prompt(monkeypatch)
    write_glove_calibration(tmp_path / "op.json")
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
    no_prompt(monkeypatch)
    write_glove_calibration(tmp_path / "op.json")
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
