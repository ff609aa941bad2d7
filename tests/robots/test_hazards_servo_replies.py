"""Hazards of what the servos answer: Present_Position(132) and the status packet of every reply (docs/hardware.md,
"Hazard analysis", table "XM430-W350 control table": Present_Position, status packets). A wrong position with a
valid CRC is re-read and never centres the step bound; a stray or corrupt reply is retried on a quiet line, and
only a persistent fault stops the gripper. Property-based (hypothesis) for the reply decoder and the position gate,
then end to end on the emulated bus."""

from __future__ import annotations

import time

import numpy as np
import pytest
from dynamixel_sdk import COMM_SUCCESS, PortHandler
from dynamixel_sdk import robotis_def as dx
from emulators.hostile import FAST, INT32, chunks
from emulators.loop import as_action, as_q, stopped
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.emulators.dynamixel import make_packet
from lerobot_blindgrasp.hardware.dynamixel.bus import LineWatchingPacketHandler
from lerobot_blindgrasp.hardware.plausibility import ImplausibleReadingError, PositionGate
from lerobot_blindgrasp.hardware.xm430 import NO_LOAD_SPEED_RAD_S, RAD_PER_TICK
from lerobot_blindgrasp.robots.blindgrasp_gripper.errors import GripperBusError, GripperReadingError

TICK = RAD_PER_TICK


# --- Present_Position: a wrong value with a valid CRC --------------------------------------------------------------
def test_a_corrupt_position_read_is_reread_and_never_centres_the_step_bound(rig, robot):
    """One read of ff_j11 comes back 1.2 rad low with a valid CRC. Centred on it, the +-0.3 rad window would allow a
    1.5 rad step toward the lower limit; the gate re-reads, so the step stays 0.3 rad from where the joint is."""
    q = as_q(robot.get_observation())
    rejected = robot.gate.rejected
    rig.dxl.position_glitch[11] = [-round(1.2 / TICK), 1]
    target = q.copy()
    target[1] = spec.JOINT_LOWER[1]
    sent = robot.send_action(as_action(target))
    step = sent["ff_j11.pos"] - rig.true_q()[1]
    assert abs(step) <= spec.ACTION_BOUND_RAD + 2 * TICK, step
    assert robot.gate.rejected == rejected + 1 and rig.dxl.position_glitch[11][1] == 0
    assert robot.is_connected


def test_an_out_of_range_reading_is_reread(rig, robot):
    q = as_q(robot.get_observation())
    rig.dxl.position_glitch[30] = [10**7, 1]  # ~15 000 rad: outside the encoder's single turn
    np.testing.assert_allclose(as_q(robot.get_observation()), q, atol=2 * TICK)
    assert "outside the encoder range" in robot.gate.last_problem


def test_persistently_implausible_readings_stop_with_the_torque_off(rig, robot):
    rig.dxl.position_glitch[21] = [2000, 1000]  # every read of mf_j21 is 3 rad off
    with pytest.raises(GripperReadingError, match=r"mf_j21.*3 re-reads|implausible.*mf_j21"):
        robot.send_action(as_action(as_q(robot.get_observation())))
    assert stopped(rig, robot)


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


# --- status packets: stray, corrupt, late ------------------------------------------------------------------------
def test_a_stray_status_packet_is_not_decoded_as_a_position(rig, robot):
    """A late 40-byte reply of servo 11 sits on the line when the position sync read starts: the SDK alone would
    take its first four bytes (Torque_Enable, LED, ...) as ff_j11's position, tens of thousands of rad."""
    q = as_q(robot.get_observation())
    rig.dxl.stray_replies.append((11, 40))
    sent = robot.send_action(as_action(q))
    assert not rig.dxl.stray_replies  # it was sent, and read as a corrupt reply, then retried
    np.testing.assert_allclose([sent[k] for k in spec.ACTION_NAMES], q, atol=2 * TICK)
    np.testing.assert_allclose(as_q(robot.get_observation()), q, atol=2 * TICK)


def test_a_burst_of_corrupt_replies_on_several_servos_is_absorbed(rig, robot):
    """bus_num_retry = 2: every servo below answers its next two packets with a bad CRC. Each try must start on an
    empty line, or the leftovers of the abandoned sync-read burst are parsed as the next try's replies."""
    for i in (10, 21, 32):
        rig.dxl.corrupt_responses[i] = 2
    robot.get_observation()
    for i in (11, 20, 31):
        rig.dxl.corrupt_responses[i] = 2
    robot.send_action(dict(zip(spec.ACTION_NAMES, as_q(robot.get_observation()).tolist(), strict=True)))
    assert robot.is_connected and all(rig.dxl.torque_enabled(i) for i in spec.SERVO_IDS)


def test_a_retry_waits_out_the_rest_of_an_abandoned_burst_with_gaps(rig, robot):
    """The first, fourth and seventh replies of a sync read are corrupt, and the replies follow 2 ms apart, so the line
    is empty for a while right after the first failure. The retry must wait until the abandoned burst has ended, not
    only drop what has arrived so far: otherwise the second try meets the old burst's corrupt reply of servo 20 and
    the third that of servo 30, and the gripper stops although only one try was spoiled."""
    rig.dxl.reply_gap_s = 0.002
    for _ in range(3):
        for i in (10, 20, 30):
            rig.dxl.corrupt_responses[i] = 1
        robot.get_observation()
    assert robot.is_connected and all(rig.dxl.torque_enabled(i) for i in spec.SERVO_IDS)


def test_a_burst_beyond_the_retry_budget_still_stops(rig, robot):
    for i in (10, 21, 32):
        rig.dxl.corrupt_responses[i] = 3
    with pytest.raises(GripperBusError, match="3 times"):
        robot.get_observation()
    assert stopped(rig, robot)


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
    data = chunks(parts, cuts)
    port = LineBytes(data)
    values, result, error = LineWatchingPacketHandler().readRx(port, 11, length)
    if result == COMM_SUCCESS:
        # Exactly what a complete, valid status packet of servo 11 with `length` data bytes carried.
        assert len(values) == length
        assert make_packet(11, dx.INST_STATUS, bytes([error]) + bytes(values)) in data
    else:
        assert values == [] and port.line_dirty  # the next try first waits for a quiet line
