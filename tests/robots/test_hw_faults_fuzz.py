"""Property-based fuzzing (hypothesis) of everything that decodes or judges what comes from outside: status packets,
the position gate, force frames, glove datagrams, and calibration files.

The property everywhere: whatever arrives (random, truncated or interleaved bytes, extreme values, wrong types),
nothing raises but the named errors, and no goal is ever computed from an implausible reading.
"""

from __future__ import annotations

import json
import math
import struct
import time

import numpy as np
import pytest
from dynamixel_sdk import COMM_SUCCESS, PortHandler
from dynamixel_sdk import robotis_def as dx
from emulators.glove_sender import FIST, OPEN
from emulators.loop import as_q
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.emulators.dynamixel import make_packet
from lerobot_blindgrasp.hardware.dynamixel.bus import LineWatchingPacketHandler
from lerobot_blindgrasp.hardware.force_board.frame_codec import SYNC, FrameParser, encode_frame
from lerobot_blindgrasp.hardware.plausibility import ImplausibleReadingError, PositionGate
from lerobot_blindgrasp.hardware.xm430 import NO_LOAD_SPEED_RAD_S, RAD_PER_TICK
from lerobot_blindgrasp.robots.blindgrasp_gripper import BlindgraspGripper, BlindgraspGripperConfig
from lerobot_blindgrasp.robots.blindgrasp_gripper import servo_calibration as calib
from lerobot_blindgrasp.robots.blindgrasp_gripper.errors import GripperReadingError
from lerobot_blindgrasp.teleoperators.manus_glove import ManusGlove, ManusGloveConfig
from lerobot_blindgrasp.teleoperators.manus_glove.manus_glove import GloveCalibrationError
from lerobot_blindgrasp.teleoperators.manus_glove.protocol import MAX_ABS_DEG, PROTO, decode, encode
from lerobot_blindgrasp.teleoperators.manus_glove.retarget import REQUIRED_KEYS

FAST = settings(max_examples=100, deadline=None)
INT32 = st.integers(-(2**31), 2**31 - 1)


def _chunks(parts: list[bytes], cuts: list[int]) -> bytes:
    return b"".join(p[: c if c >= 0 else len(p)] for p, c in zip(parts, cuts + [-1] * len(parts)))


# --- status packets --------------------------------------------------------------------------------------------
class LineBytes(PortHandler):
    """The serial line as a byte string (a stand-in for the device, not for any of our classes): what the SDK's
    packet handler reads; the reply window closes when the bytes run out."""

    def __init__(self, data: bytes):
        super().__init__("fuzz")
        self.data = bytearray(data)
        self.is_open = True

    def readPort(self, length):
        out = bytes(self.data[:length])
        del self.data[:length]
        return out

    def getBytesAvailable(self):
        return len(self.data)

    def isPacketTimeout(self):
        return not self.data


status_packets = st.builds(
    lambda i, err, params, bad: make_packet(i, dx.INST_STATUS, bytes([err]) + params, bad_crc=bad),
    st.sampled_from([11, 12, 21, 254]),
    st.integers(0, 255),
    st.binary(max_size=44),
    st.booleans(),
)
other_packets = st.builds(lambda i, inst, p: make_packet(i, inst, p), st.integers(0, 253), st.integers(0, 255),
                          st.binary(max_size=12))  # fmt: skip


@st.composite
def replies(draw):
    """A read of `length` bytes from servo 11, and what the line holds: garbage, other packets, stray status packets,
    the right reply (perhaps truncated, perhaps with a bad CRC), in any order."""
    length = draw(st.sampled_from([1, 2, 4, 40]))
    right = st.builds(lambda err, p, bad: make_packet(11, dx.INST_STATUS, bytes([err]) + p, bad_crc=bad),
                      st.integers(0, 255), st.binary(min_size=length, max_size=length), st.booleans())  # fmt: skip
    parts = draw(st.lists(st.one_of(st.binary(max_size=16), status_packets, other_packets, right), max_size=6))
    return length, parts


@FAST
@given(reply=replies(), cuts=st.lists(st.integers(-1, 30), max_size=6))
def test_status_packet_handling_never_returns_a_value_of_the_wrong_shape(reply, cuts):
    length, parts = reply
    data = _chunks(parts, cuts)
    port = LineBytes(data)
    values, result, error = LineWatchingPacketHandler().readRx(port, 11, length)
    if result == COMM_SUCCESS:
        # Exactly what a complete, valid status packet of servo 11 with `length` data bytes carried.
        assert len(values) == length
        assert make_packet(11, dx.INST_STATUS, bytes([error]) + bytes(values)) in data
    else:
        assert values == [] and port.line_dirty  # the next try first waits for a quiet line


# --- the position gate -------------------------------------------------------------------------------------------
NAMES = [f"j{k}" for k in range(3)]
readings = st.lists(st.lists(st.one_of(INT32, st.integers(0, 4095), st.integers(1900, 2200)), min_size=3,
                             max_size=3), min_size=1, max_size=4)  # fmt: skip


@FAST
@given(estimate=st.lists(st.integers(1900, 2200), min_size=3, max_size=3), goal_offset=st.integers(-300, 300),
       seq=readings, free=st.booleans())  # fmt: skip
def test_the_gate_never_passes_an_implausible_reading(estimate, goal_offset, seq, free):
    gate = PositionGate(speed_ticks_s=NO_LOAD_SPEED_RAD_S / RAD_PER_TICK, margin_ticks=0.1 / RAD_PER_TICK)
    est = np.array(estimate, dtype=float)
    gate.estimate, gate.estimate_t = est, time.monotonic()
    gate.goal = est + goal_offset
    pending = list(seq)

    def read():
        return np.array(pending.pop(0) if pending else seq[-1], dtype=float)

    t0 = gate.estimate_t
    try:
        ticks = gate.read(read, NAMES, free=free)
    except ImplausibleReadingError:
        return
    dt = time.monotonic() - t0
    assert np.all((ticks >= 0) & (ticks <= 4095))
    if not free:  # the servos drive the joints: reachable, and between the estimate and the goal
        assert np.all(np.abs(ticks - est) <= gate.speed_ticks_s * dt + gate.margin_ticks)
        lo, hi = np.minimum(est, est + goal_offset), np.maximum(est, est + goal_offset)
        assert np.all((ticks >= lo - gate.margin_ticks) & (ticks <= hi + gate.margin_ticks))
    else:  # a hand may move them: then two readings in a row agree
        assert any(np.array_equal(ticks, np.array(r, dtype=float)) for r in seq)


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(joint=st.integers(0, 8), offset=INT32, count=st.integers(1, 4))
def test_no_goal_is_computed_from_an_implausible_reading(rig, robot, joint, offset, count):
    """On the emulated gripper: Present_Position of one servo comes back `offset` ticks off (valid CRC) `count` times
    in a row. The goal sent is within the step bound of the true position, or the gripper stops with the torque off."""
    if not robot.is_connected:
        robot.connect()
    q = as_q(robot.get_observation())
    rig.dxl.position_glitch[spec.SERVO_IDS[joint]] = [offset, count]
    target = np.clip(q + np.where(np.arange(9) == joint, -3.0, 0.0), spec.JOINT_LOWER, spec.JOINT_UPPER)
    try:
        sent = robot.send_action(dict(zip(spec.ACTION_NAMES, target.tolist(), strict=True)))
    except GripperReadingError:
        assert not rig.dxl.any_torque() and not robot.is_connected
        return
    finally:
        rig.dxl.position_glitch.clear()
    step = np.array([sent[k] for k in spec.ACTION_NAMES]) - rig.true_q()
    assert np.abs(step).max() <= spec.ACTION_BOUND_RAD + 0.1 + 2 * RAD_PER_TICK, step


# --- force frames ------------------------------------------------------------------------------------------------
frames = st.builds(
    encode_frame, st.integers(0, 65535), st.lists(INT32, min_size=1, max_size=8), st.integers(0, 255)
)


@FAST
@given(parts=st.lists(st.one_of(frames, st.binary(max_size=24)), max_size=8), cuts=st.lists(st.integers(-1, 40)),
       split=st.integers(1, 64))  # fmt: skip
def test_the_force_frame_decoder_yields_only_frames_that_were_sent(parts, cuts, split):
    data = _chunks(parts, cuts)
    parser = FrameParser()
    out = []
    for k in range(0, len(data), split):  # in arbitrary pieces, as reads from the serial port come
        out += parser.feed(data[k : k + split])
    for f in out:
        assert encode_frame(f.seq, f.counts, f.status) in data


@FAST
@given(parts=st.lists(st.tuples(frames, st.binary(max_size=24).map(lambda b: b.replace(SYNC[:1], b""))), max_size=6),
       split=st.integers(1, 64))  # fmt: skip
def test_every_whole_frame_between_garbage_comes_out_in_order(parts, split):
    data = b"".join(g + f for f, g in parts)
    parser = FrameParser()
    out = []
    for k in range(0, len(data), split):
        out += parser.feed(data[k : k + split])
    assert [encode_frame(f.seq, f.counts, f.status) for f in out] == [f for f, _ in parts]
    assert parser.garbage_bytes == sum(len(g) for _, g in parts)


# --- glove datagrams -----------------------------------------------------------------------------------------------
json_values = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=8),
    lambda children: st.lists(children, max_size=4) | st.dictionaries(st.text(max_size=8), children, max_size=4),
    max_leaves=12,
)


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


# --- calibration files ---------------------------------------------------------------------------------------------
def _gripper_file() -> bytes:
    ids = dict(zip(spec.JOINT_NAMES, spec.SERVO_IDS, strict=True))
    cal = calib.build(ids, dict.fromkeys(ids, 1), dict.fromkeys(ids, -1000), spec.JOINT_LOWER, spec.JOINT_UPPER)
    return json.dumps({j: vars(c) for j, c in cal.items()}, indent=4).encode()


def _mutations(good: bytes):
    raw = json.loads(good)
    keys = st.sampled_from(sorted(raw))
    return st.one_of(
        st.integers(0, len(good) - 1).map(lambda n: good[:n]),  # truncated anywhere
        st.binary(max_size=80),
        json_values.map(lambda v: json.dumps(v).encode()),
        st.builds(
            lambda n, junk: good[:n] + junk + good[n:],
            st.integers(0, len(good)),
            st.binary(min_size=1, max_size=8),
        ),  # fmt: skip
        st.builds(lambda k, v: _replace(raw, k, v), keys, json_values | st.integers(-(2**70), 2**70)),
    )


def _replace(raw: dict, key: str, value) -> bytes:
    out = json.loads(json.dumps(raw))
    inner = out[key]
    if isinstance(inner, dict):
        inner[sorted(inner)[len(str(value)) % len(inner)]] = value
    else:
        out[key] = value
    return json.dumps(out).encode()


@FAST
@given(data=_mutations(_gripper_file()))
def test_a_gripper_calibration_file_is_valid_or_refused_by_name(tmp_path_factory, data):
    d = tmp_path_factory.mktemp("cal")
    (d / "g.json").write_bytes(data)
    robot = BlindgraspGripper(BlindgraspGripperConfig(id="g", calibration_dir=d))  # never raises
    if robot.calibration_error is not None:
        assert isinstance(robot.calibration_error, calib.CalibrationFileError)
        assert "lerobot-calibrate" in str(robot.calibration_error) and robot.calibration == {}
        with pytest.raises(calib.CalibrationFileError):
            robot.connect()  # refused before the port is opened
    else:
        ids = dict(zip(spec.JOINT_NAMES, spec.SERVO_IDS, strict=True))
        assert calib.servo_calibration_problems(robot.calibration, ids) == []
        assert all(type(getattr(c, f)) is int for c in robot.calibration.values() for f in calib.RECORD_FIELDS)


@FAST
@given(data=_mutations(json.dumps({"open": OPEN, "fist": FIST}).encode()))
def test_a_glove_calibration_file_is_valid_or_refused_by_name(tmp_path_factory, data):
    d = tmp_path_factory.mktemp("glove")
    (d / "op.json").write_bytes(data)
    glove = ManusGlove(ManusGloveConfig(id="op", calibration_dir=d))  # never raises
    if glove.calibration_error is not None:
        assert isinstance(glove.calibration_error, GloveCalibrationError)
        assert "lerobot-calibrate" in str(glove.calibration_error) and glove.calibration is None
    else:
        cal = glove.calibration
        for pose in (cal.open, cal.fist):
            assert all(math.isfinite(pose[k]) and not isinstance(pose[k], bool) for k in REQUIRED_KEYS)


def test_struct_sanity_of_the_frame_strategy():
    """The frame strategy builds what the firmware sends (LEN, CRC): one decoded back unchanged."""
    f = encode_frame(7, [1, -2, 3], 0)
    (out,) = FrameParser().feed(f)
    assert (out.seq, out.counts, out.status) == (7, (1, -2, 3), 0) and struct.unpack_from("<B", f, 2)[0] == 15
