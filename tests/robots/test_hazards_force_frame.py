"""Hazards of the force frame (docs/hardware.md, "Hazard analysis", table "Force frame": SYNC/LEN/CRC, SEQ, COUNTS,
COUNTS vs the tare, channel count). The decoder yields only frames that were sent (hypothesis); on the emulated
board, dead data that still arrives goes stale, a board reset mid-run stops, a loaded or moving tare is refused,
a clearly negative force and a missing channel are faults. The reader's own resynchronisation, the firmware and the
stream's rate are tests/hardware/ (`test_hw_force.py`, `test_force_board_*.py`)."""

from __future__ import annotations

import struct
import time

import numpy as np
import pytest
from emulators.hostile import FAST, INT32, chunks
from emulators.loop import hold, stopped
from hypothesis import given
from hypothesis import strategies as st

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.hardware.force_board.frame_codec import SYNC, FrameParser, encode_frame
from lerobot_blindgrasp.hardware.force_board.reader import ForceTareError
from lerobot_blindgrasp.robots.blindgrasp_gripper.errors import ForceSensorError

# --- SYNC, LEN, CRC -------------------------------------------------------------------------------------------
frames = st.builds(
    encode_frame, st.integers(0, 65535), st.lists(INT32, min_size=1, max_size=8), st.integers(0, 255)
)


@FAST
@given(parts=st.lists(st.one_of(frames, st.binary(max_size=24)), max_size=8), cuts=st.lists(st.integers(-1, 40)),
       split=st.integers(1, 64))  # fmt: skip
def test_the_force_frame_decoder_yields_only_frames_that_were_sent(parts, cuts, split):
    data = chunks(parts, cuts)
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


def test_struct_sanity_of_the_frame_strategy():
    """The frame strategy builds what the firmware sends (LEN, CRC): one decoded back unchanged."""
    f = encode_frame(7, [1, -2, 3], 0)
    (out,) = FrameParser().feed(f)
    assert (out.seq, out.counts, out.status) == (7, (1, -2, 3), 0) and struct.unpack_from("<B", f, 2)[0] == 15


# --- SEQ and COUNTS: dead data that still arrives, a board reset ------------------------------------------------
@pytest.mark.parametrize(
    "fault,why",
    [
        ("resend_last", r"stale.*repeated or backward counter"),
        ("seq_step", r"stale.*repeated or backward counter"),
        ("frozen_channels", r"stale.*\['mf_tip'\] repeat the same value bit for bit"),
    ],
)
def test_dead_force_data_that_still_arrives_is_stale(rig, robot, fault, why):
    robot.get_observation()
    dropped = robot.force.dropped_frames
    setattr(rig.force, fault, {"resend_last": True, "seq_step": -1, "frozen_channels": {1}}[fault])
    deadline = time.monotonic() + 2.0
    with pytest.raises(ForceSensorError, match=why):
        while time.monotonic() < deadline:
            robot.get_observation()
            time.sleep(spec.CONTROL_DT)
    assert stopped(rig, robot)
    assert robot.force.dropped_frames - dropped < 5  # a backward counter is not 65 000 lost frames


def test_a_force_board_reset_mid_run_stops(rig, robot):
    """The force board resets (a brown-out, a USB glitch) mid-trial: silent for its 0.5 s boot, longer than the stale
    timeout, so the trial stops, torque off (the reader itself resynchronises after it: test_hw_force.py)."""
    hold(robot, 6)
    rig.force.reset()
    with pytest.raises(ForceSensorError, match=r"Force"):
        hold(robot, 40)
    assert not robot.is_connected and not rig.dxl.any_torque()


def test_a_clearly_negative_force_is_a_fault(rig, robot):
    rig.force.forces_n = np.array([0.0, -3.0, 0.0])  # what a tare under 3 N reads once the pad is free
    time.sleep(0.05)
    with pytest.raises(ForceSensorError, match=r"mf_tip -(3\.0|2\.9)\d N.*only feels compression"):
        robot.get_observation()
    assert stopped(rig, robot)


# --- COUNTS vs the tare -----------------------------------------------------------------------------------------
def test_a_retare_with_a_loaded_pad_is_refused_and_keeps_the_zero(rig, robot):
    zero = robot.force.offset.copy()
    rig.force.forces_n = np.array([6.0, 0.0, 0.0])  # the object still presses on ff's pad
    time.sleep(0.05)
    with pytest.raises(ForceTareError, match=r"ff_tip reads \+(6\.0|5\.9)\d N against the current zero"):
        robot.tare_forces()
    np.testing.assert_array_equal(robot.force.offset, zero)
    assert robot.is_connected and all(rig.dxl.torque_enabled(i) for i in spec.SERVO_IDS)  # refused, not stopped
    rig.force.forces_n = np.zeros(3)
    time.sleep(0.05)
    assert robot.get_observation()["ff_tip.force"] == 0.0  # unloaded reads 0, not -6 N


def test_a_tare_with_a_pad_that_moves_is_refused(rig, robot):
    rig.force.noise = 2.0 / rig.force.scale[0]  # 2 N of wobble: a hand on the pad
    with pytest.raises(ForceTareError, match=r"varies by"):
        robot.tare_forces()
    assert robot.is_connected


# --- channel count ----------------------------------------------------------------------------------------------
def test_force_frames_with_the_wrong_channel_count_are_a_sensor_error(rig, robot):
    rig.force.channels = 2  # firmware built for two cells, config maps three
    time.sleep(0.05)
    with pytest.raises(ForceSensorError, match=r"carry 2 channels.*channel_map \[0, 1, 2\].*Torque is off"):
        robot.get_observation()
    assert stopped(rig, robot)


def test_extra_force_channels_are_fine(rig, robot):
    rig.force.channels = 4
    rig.force.forces_n = np.array([2.0, 0.0, 0.0])
    time.sleep(0.05)
    assert robot.get_observation()["ff_tip.force"] == pytest.approx(2.0, abs=0.03)
