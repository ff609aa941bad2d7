"""Sim and real read the uniaxial force the same way (`lerobot_blindgrasp.hardware.force`): true force + noise, then the deadband.

The real side is the real reader (`ForceSensorReader`: serial port, frame parser, tare, scale) on the emulated
load-cell microcontroller; the sim side is the pipeline `BatchedGraspEnv` builds its observation with, and the env
itself. Named test_hw_* because the emulator is timing-sensitive (see docs/hardware.md, section 7).
"""

from __future__ import annotations

import logging
import time
from dataclasses import replace

import numpy as np
import pytest
from emulators.faults import FaultyForceBoard

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.hardware import force
from lerobot_blindgrasp.hardware.force_board.frame_codec import encode_frame
from lerobot_blindgrasp.hardware.force_board.reader import SETTLE_FRAMES, ForceSensorReader, ForceStreamError
from lerobot_blindgrasp.sim import randomization
from lerobot_blindgrasp.sim.batched_config import GraspEnvConfig
from lerobot_blindgrasp.sim.batched_env import BatchedGraspEnv

# (true force, the sensor's noise sample) per tip, N. Chosen away from the 0.1 N edge by more than a count (25 uN).
CASES = [
    ([0.0, 0.0, 0.0], [0.05, -0.3, 0.6]),  # free tips: noise under the deadband is cut, larger noise passes
    ([2.0, 0.08, 0.0], [0.0, 0.05, -0.04]),  # 0.08 N alone would be cut; with +0.05 N of noise it reads 0.13 N
    ([1.5, 0.05, 3.0], [-0.02, 0.0, 0.25]),
]


def test_noise_comes_before_the_deadband():
    np.testing.assert_array_equal(force.reading([0.0, 0.0, 0.0], [0.05, -0.099, 0.3]), [0.0, 0.0, 0.3])
    np.testing.assert_allclose(force.reading([0.08, 2.0], [0.05, -0.04]), [0.13, 1.96])
    # Without noise it is the plain deadband: the noise-free reading the rewards use.
    np.testing.assert_array_equal(force.reading([0.0, 0.05, -0.099, 0.1, -0.5, 3.0]), [0, 0, 0, 0.1, -0.5, 3.0])


@pytest.fixture
def sensor():
    # No emulator noise of its own: each case puts its noise sample into the true force, as a load cell does.
    emu = FaultyForceBoard(noise_counts=0.0)
    emu.start()
    reader = ForceSensorReader(emu.port, 115_200, emu.scale.tolist(), stale_timeout_s=0.5)
    try:
        reader.connect()
        reader.tare(0.1)
        yield emu, reader
    finally:
        reader.disconnect()
        emu.stop()


def test_sim_and_real_give_the_same_reading_for_the_same_true_force(sensor):
    emu, reader = sensor
    for true, noise in CASES:
        sim = force.reading(np.array([true]), np.array([noise]))[0]  # what `BatchedGraspEnv._observe` does
        emu.forces_n = np.add(true, noise)  # the physical sensor's output holds the noise
        assert reader.wait_frames(3, 1.0)  # past any frame built before the change
        real = reader.read()
        np.testing.assert_allclose(real, sim, atol=1e-4)  # one ADC count is 25 uN
        np.testing.assert_array_equal(real == 0.0, sim == 0.0)  # and the deadband decides alike


def test_the_sim_observation_goes_through_the_sensor_pipeline():
    """In the env: every observed force is exactly 0 or at least 0.1 N in magnitude (the deadband comes last), free
    tips read exactly 0 whenever their noise is small, and with the noise off the observation is the noise-free
    reading the rewards see."""
    kw = {"num_envs": 4, "objects": ("cylinder_a_medium",), "autoreset": False, "nthread": 1}
    env = BatchedGraspEnv(GraspEnvConfig(**kw))
    obs = env.reset()
    seen = [obs["policy"][:, spec.STATE_FORCE_SLICE]]
    for _ in range(10):
        obs, *_ = env.step(np.zeros((4, spec.NUM_JOINTS)))
        seen.append(obs["policy"][:, spec.STATE_FORCE_SLICE])
    seen = np.concatenate(seen)
    assert np.all((seen == 0.0) | (np.abs(seen) >= spec.FORCE_THRESHOLD_N - 1e-6))
    # 132 tip readings, mostly in free air: with sigma 0.5 N about 16 % of them have |noise| < 0.1 N.
    assert (seen == 0.0).sum() >= 5

    env = BatchedGraspEnv(GraspEnvConfig(**kw, dr=replace(randomization.PAPER_DR, force_noise_n=0.0)))
    env.reset()
    for _ in range(5):
        obs, *_, info = env.step(np.zeros((4, spec.NUM_JOINTS)))
        clean = info["uniaxial_force"].astype(np.float32)
        np.testing.assert_array_equal(obs["policy"][:, spec.STATE_FORCE_SLICE], clean)


def test_a_slow_stream_is_told_from_a_stale_one():
    """Slow: fresh frames, none old enough to be stale, but fewer per second than the control loop needs. Stale:
    no fresh frame for `stale_timeout_s`. Each error says which, and the stream recovers from a slow spell."""
    emu = FaultyForceBoard(rate_hz=15.0).start()
    reader = ForceSensorReader(emu.port, 115_200, emu.scale.tolist(), stale_timeout_s=0.15, min_rate_hz=40.0)
    try:
        reader.connect()
        time.sleep(0.6)  # 9 frames: enough intervals for a rate
        with pytest.raises(
            ForceStreamError, match=r"stream is slow: fresh frames arrive at 1\d\.\d/s, below the 40/s"
        ):
            reader.read()
        emu.period = 1.0 / 80.0  # the HX711 board's rate
        time.sleep(0.5)
        assert reader.rate_hz() > 40.0
        reader.read()
        emu.paused = True
        time.sleep(0.3)
        with pytest.raises(ForceStreamError, match=r"stale: newest frame is \d+ ms old \(limit 150 ms"):
            reader.read()
    finally:
        reader.disconnect()
        emu.stop()


def test_a_channel_at_the_adc_rail_is_flagged_saturated(sensor):
    """The emulator follows the board's rule: a channel at the 24-bit full scale sets its STATUS bit."""
    emu, reader = sensor
    emu.forces_n = np.array([0.0, 0.0, 400.0])  # 400 N / 25 uN = 16 M counts, beyond +2^23
    assert reader.wait_frames(3, 1.0)
    with pytest.raises(ForceStreamError, match=r"th_tip \(channel 2\) is saturated at 8388607 counts"):
        reader.read()


def _reads_through_a_restart(reader, deadline_s: float = 5.0) -> list:
    """What the control loop gets, read after read, until a read succeeds after the reader confirmed a restart (or
    `deadline_s`, a bound far above the emulator's boot time plus the frames the host waits for; not a timing
    assertion)."""
    seen, deadline = [], time.monotonic() + deadline_s
    while time.monotonic() < deadline:
        try:
            seen.append(reader.read())
            if reader.clock.restarts and reader.clock.restarts[-1].confirmed_seq >= 0:
                return seen
        except ForceStreamError as e:
            seen.append(str(e))
        time.sleep(0.004)
    return seen


@pytest.mark.parametrize("cause", [0x08, None], ids=["boot-frame", "no-boot-frame"])
def test_a_board_reset_resynchronises_and_a_loaded_tip_stays_loaded(cause, caplog):
    """The board resets with ff_tip loaded (5 N): silent while it boots, then SEQ from 0, the first frames unsettled
    (an unloaded cell's counts, as a firmware that does not wait for the HX711s would send). The host names the reset
    (not a replay), holds the stream stale until `SETTLE_FRAMES` frames advanced with time, then reads 5 N again with
    the same tare: no read in between ever says the tip is unloaded."""
    emu = FaultyForceBoard(noise_counts=0.0).start()
    reader = ForceSensorReader(emu.port, 115_200, emu.scale.tolist(), stale_timeout_s=0.15, min_rate_hz=40.0)
    try:
        reader.connect()
        reader.tare(0.1)
        zero = reader.offset.copy()
        emu.forces_n = np.array([5.0, 0.0, 0.0])
        assert reader.wait_frames(3, 1.0)
        np.testing.assert_allclose(reader.read(), [5.0, 0.0, 0.0], atol=1e-3)
        with caplog.at_level(logging.WARNING):
            emu.reset(boot_s=0.3, cause=cause, unsettled_frames=SETTLE_FRAMES)
            seen = _reads_through_a_restart(reader)
    finally:
        reader.disconnect()
        emu.stop()
    values = [s for s in seen if not isinstance(s, str)]
    errors = [s for s in seen if isinstance(s, str)]
    assert isinstance(seen[-1], np.ndarray) and errors, seen[-3:]  # stale while it booted, then live
    np.testing.assert_allclose(values, [[5.0, 0.0, 0.0]] * len(values), atol=1e-3)  # never the unsettled 0 N
    assert all("stale" in e for e in errors), errors
    np.testing.assert_array_equal(reader.offset, zero)  # the tare is kept, never retaken
    # Live again at the rebooted board's frame SETTLE_FRAMES: its own clock says 5 frames (62.5 ms at 80/s) after its
    # first, so the stream is back within the boot time plus 62.5 ms.
    assert [r.confirmed_seq for r in reader.clock.restarts] == [SETTLE_FRAMES]
    assert reader.counter_faults == 0 and reader.seq_ahead == 0
    why = "reset (watchdog)" if cause is not None else "reset (no boot frame; judged by SEQ against time)"
    assert why in caplog.text and "replay" not in caplog.text, caplog.text


def test_replayed_frames_stay_rejected_after_a_silence_or_near_zero():
    """A replay is no reset: old SEQs sent again straight after live ones (no boot silence), even near 0, or after a
    silence from far back (more than the time allows for a counter restarted at 0), stay dropped: stale."""
    emu = FaultyForceBoard()
    emu.seq = 20_000  # a board that has run for 4 minutes: a replayed counter does not catch up during the test
    emu.start()
    reader = ForceSensorReader(emu.port, 115_200, emu.scale.tolist(), stale_timeout_s=0.15)
    try:
        reader.connect()
        assert reader.wait_frames(8, 1.0)
        emu.seq = 2  # jumps back near 0 with no silence: frames keep coming every 12.5 ms
        time.sleep(0.4)
        with pytest.raises(ForceStreamError, match=r"stale.*replayed"):
            reader.read()
        faults = reader.counter_faults
        assert faults > 0 and not reader.clock.restarts
        emu.seq = reader.latest()[0].seq + 1
        assert reader.wait_frames(2, 1.0)  # live again: the counter goes on
        emu.paused = True
        time.sleep(0.2)  # silent for longer than a boot
        emu.seq, emu.paused = emu.seq - 1_000, False  # then SEQs from before: too far back for a restart at 0
        time.sleep(0.3)
        with pytest.raises(ForceStreamError, match=r"stale.*replayed"):
            reader.read()
    finally:
        reader.disconnect()
        emu.stop()
    assert reader.counter_faults > faults and not reader.clock.restarts


def test_a_stray_frame_far_ahead_is_dropped_and_does_not_lock_the_stream():
    """One frame whose SEQ is 30 000 ahead (garbage that passed the CRC, a corrupted counter): more than 160/s over
    the time since the last frame. Adopting it would make every real frame look replayed; it is dropped instead."""
    emu = FaultyForceBoard().start()
    reader = ForceSensorReader(emu.port, 115_200, emu.scale.tolist(), stale_timeout_s=0.15)
    try:
        reader.connect()
        assert reader.wait_frames(4, 1.0)
        emu.write(encode_frame((emu.seq + 30_000) % 65536, [81_000, -52_000, 12_000]))
        assert reader.wait_frames(8, 1.0)
        reader.read()
    finally:
        reader.disconnect()
        emu.stop()
    assert reader.seq_ahead == 1 and reader.counter_faults == 0


def test_a_lossy_link_is_told_from_a_slow_board():
    """3 frames in 4 lost on the way (seeded): fresh frames arrive at ~20/s, under the 40/s floor, but the board's SEQ
    advances at 80/s, so the message says frames are lost, not that the board is slow."""
    emu = FaultyForceBoard(seed=3).start()
    reader = ForceSensorReader(emu.port, 115_200, emu.scale.tolist(), stale_timeout_s=0.5, min_rate_hz=40.0)
    try:
        reader.connect()
        emu.drop_prob = 0.75
        assert reader.wait_frames(20, 3.0)  # the window holds only frames sent after the change
        with pytest.raises(
            ForceStreamError, match=r"slow.*SEQ advances at [6-9]\d/s, so frames are lost on the way"
        ):
            reader.read()
    finally:
        reader.disconnect()
        emu.stop()


def test_a_board_reset_between_trials_leaves_the_robot_able_to_tare(rig, robot):
    """The force board resets while the robot waits between trials (the operator places the object): the next
    trial's tare works as soon as the rebooted board's SEQ confirmed the restart, instead of every frame being
    refused as a replay until the counter caught up (minutes)."""
    rig.force.reset(boot_s=0.3)
    deadline = time.monotonic() + 5.0  # far above the 0.3 s boot and the SETTLE_FRAMES frames; not asserted
    while not any(r.confirmed_seq >= 0 for r in robot.force.clock.restarts) and time.monotonic() < deadline:
        time.sleep(0.01)
    robot.tare_forces()
    assert robot.is_connected and robot.force.counter_faults == 0
    np.testing.assert_allclose(robot.force.read(), 0.0, atol=0.5)
