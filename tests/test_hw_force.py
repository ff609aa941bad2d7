"""Sim and real read the uniaxial force the same way (`lerobot_blindgrasp.hardware.force`): true force + noise, then the deadband.

The real side is the real reader (`ForceSensorReader`: serial port, frame parser, tare, scale) on the emulated
load-cell microcontroller; the sim side is the pipeline `BatchedGraspEnv` builds its observation with, and the env
itself. Named test_hw_* because the emulator is timing-sensitive (see docs/hardware.md, section 7).
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np
import pytest

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.emulators.force_board import ForceSensorEmulator
from lerobot_blindgrasp.hardware import force
from lerobot_blindgrasp.robots.blindgrasp_gripper.force_sensor import ForceSensorReader, ForceStreamError
from lerobot_blindgrasp.sim import randomization, sensors
from lerobot_blindgrasp.sim.batched_env import BatchedGraspEnv
from lerobot_blindgrasp.sim.env_config import GraspEnvConfig

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
    emu = ForceSensorEmulator(noise_counts=0.0)
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
        sim = sensors.reading(np.array([true]), np.array([noise]))[0]  # what `BatchedGraspEnv._observe` does
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
    emu = ForceSensorEmulator(rate_hz=15.0).start()
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
