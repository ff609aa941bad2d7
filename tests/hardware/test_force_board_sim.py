"""The force board's firmware, compiled here with Debian's AVR toolchain and run in simavr with emulated HX711 chips
on its pins (`lerobot_blindgrasp/hardware/force_board/`), read through the project's real `ForceSensorReader` on
the pseudo-terminal its UART is wired to. Skipped, naming the Debian packages, where the toolchain is missing
(`scripts/test.sh` installs them when it runs as root with apt-get, as in CI)."""

from __future__ import annotations

import logging
import re
import time

import numpy as np
import pytest

from lerobot_blindgrasp.emulators.force_board_simavr import SimulatedForceBoard
from lerobot_blindgrasp.hardware.force_board import build
from lerobot_blindgrasp.hardware.force_board import force_calibration as fc
from lerobot_blindgrasp.hardware.force_board.config_force_board import ForceSensorConfig
from lerobot_blindgrasp.hardware.force_board.force_calibration_cli import CalibrateForceConfig, calibrate_force
from lerobot_blindgrasp.hardware.force_board.reader import (
    SETTLE_FRAMES,
    ForceSensorReader,
    ForceStreamError,
)
from lerobot_blindgrasp.hardware.streams import RATE_WINDOW
from lerobot_blindgrasp.robots.blindgrasp_gripper.config_blindgrasp_gripper import BlindgraspGripperConfig

if missing := build.missing_packages():
    pytest.skip(f"force-board firmware tests need: apt-get install {' '.join(missing)}", allow_module_level=True)

# A cell per finger as a lab's would come out: two bridges wired one way, one the other (a push reads fewer counts).
SCALE = (3.1e-5, -2.2e-5, 2.7e-5)
OFFSET = (81_000, -52_000, 12_000)


@pytest.fixture(scope="module")
def build_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("force_board")
    build.build_firmware(out)
    build.build_simulator(out)
    return out


def _board(build_dir, **kw) -> SimulatedForceBoard:
    return SimulatedForceBoard(scale_n_per_count=SCALE, offset_counts=OFFSET, build_dir=build_dir, **kw).start()


def _reader(port: str, scale=SCALE) -> ForceSensorReader:
    """The reader as the robot builds it, with the robot config's defaults (stale, frozen, rate and connect)."""
    fs = ForceSensorConfig(port=port)
    return ForceSensorReader(port, fs.baudrate, list(scale), stale_timeout_s=fs.stale_timeout_s,
                             connect_timeout_s=fs.connect_timeout_s, frozen_frames=fs.frozen_frames,
                             min_rate_hz=fs.min_rate_hz)  # fmt: skip


def _flash_bytes(hex_path) -> int:
    """Bytes of program in an Intel HEX image (data records only)."""
    lines = hex_path.read_text().split()
    return sum(int(line[1:3], 16) for line in lines if line[7:9] == "00")


def test_the_firmware_builds_and_fits_a_nano_with_its_bootloader(build_dir):
    size = _flash_bytes(build_dir / "force_board.hex")
    assert 500 < size < 30_720  # 32 KiB flash less the 2 KiB bootloader


def test_the_real_reader_reads_the_forces_the_cells_were_given(build_dir):
    board = _board(build_dir)
    reader = _reader(board.port)
    try:
        reader.connect()
        reader.tare(0.3)
        t0, seq0 = time.monotonic(), reader.latest()[0].seq
        for forces in ([2.0, 0.0, 5.0], [0.5, 7.5, 1.25], [12.0, 3.0, 0.0]):
            board.set_forces(forces)
            assert reader.wait_frames(4, 1.0)  # past any conversion made before the change
            # One count is <= 31 uN; +-200 counts of noise and the tare's mean leave < 0.02 N.
            np.testing.assert_allclose(reader.read(), forces, atol=0.02)
        rate = ((reader.latest()[0].seq - seq0) % 65536) / (time.monotonic() - t0)
        assert 50 < rate < 100, rate  # 80 conversions/s per chip; simavr paced to the wall clock
        assert reader.dropped_frames == 0 and reader.counter_faults == 0 and reader.parser.crc_errors == 0
    finally:
        reader.disconnect()
        board.stop()
    # Gain 128 throughout, powered down only by the firmware's own power cycle at boot, within every HX711 timing.
    assert board.log.count("0 reads not of 25 pulses, 1 power-downs") == 3, board.log
    assert "TIMING VIOLATIONS" not in board.log, board.log


def test_each_frame_is_handed_on_when_it_arrives(build_dir):
    """The host reports the rate the firmware sends (~80/s, counted by SEQ over the same time), and the newest
    frame is, at any moment, no older than the board's own period explains: frames are not held back to be handed
    on in batches (which reads as a faster board, and a slow one as fast enough)."""
    board = _board(build_dir)
    reader = _reader(board.port)
    try:
        reader.connect()
        assert reader.wait_frames(20, 1.0)
        t0, seq0 = time.monotonic(), reader.latest()[0].seq
        ages = []
        for k in range(60):
            time.sleep(0.003 + 0.0013 * (k % 7))  # at every phase of the 12.5 ms period
            ages.append(reader.latest()[1])
        sent = ((reader.latest()[0].seq - seq0) % 65536) / (time.monotonic() - t0)
        estimate = reader.rate_hz()
    finally:
        reader.disconnect()
        board.stop()
    assert 70 < sent < 90, sent
    assert abs(estimate - sent) < 0.1 * sent, (estimate, sent)
    # Half a period (6 ms) typically, plus the host's scheduling; frames handed on in batches of even two periods
    # would make it 12.5 ms. The median, because a busy host's scheduling stalls a few samples, not the reader.
    assert np.median(ages) < 0.0095, ages


def test_a_dead_or_saturated_cell_is_a_named_fault_and_the_stream_goes_on(build_dir):
    board = _board(build_dir)
    reader = _reader(board.port)
    try:
        reader.connect()
        reader.tare(0.2)
        board.send("dead 1")  # the chip stops converting
        time.sleep(0.3)
        with pytest.raises(ForceStreamError, match=r"mf_tip \(channel 1\) stopped converting"):
            reader.read()
        board.send("alive 1")
        assert reader.wait_frames(RATE_WINDOW + 1, 1.0)  # the rate is judged again on the frames since
        np.testing.assert_allclose(reader.read(), 0.0, atol=0.02)
        board.set_counts([0x7FFFFF + 5000, -52_000, 12_000])  # far beyond the ADC's range
        time.sleep(0.2)
        with pytest.raises(ForceStreamError, match=r"ff_tip \(channel 0\) is saturated at 8388607"):
            reader.read()
    finally:
        reader.disconnect()
        board.stop()


def test_a_cell_whose_dout_is_held_low_keeps_its_last_value(build_dir):
    """A DOUT line shorted to GND reads as "ready" and clocks out 24 zeros, and the 25th pulse leaves it low, so the
    firmware rejects the read. The fault frames then carry that cell's last valid conversion with its bit set,
    never the zeros of the failed read."""
    board = _board(build_dir)
    reader = _reader(board.port)
    try:
        reader.connect()
        assert reader.wait_frames(3, 1.0)
        board.send("stuck 1")  # DOUT shorted to GND: every read clocks out zeros
        assert reader.wait_frames(3, 2.0)  # 50 ms without a valid conversion, then a fault frame every 50 ms
        frame = reader.latest()[0]
    finally:
        reader.disconnect()
        board.stop()
    assert frame.status == 0b010, frame
    assert "mf_tip (channel 1) stopped converting" in reader.fault_message(frame)
    assert abs(frame.counts[1] - OFFSET[1]) <= 200, frame  # the last conversion (+-200 counts of noise), not 0
    assert [abs(c - o) <= 200 for c, o in zip(frame.counts, OFFSET)] == [True] * 3


def test_a_board_at_36_per_second_is_called_slow(build_dir):
    """Every frame fresh and on time, none old enough to be stale, just fewer than the 40/s the host needs: "slow",
    with the rate the board sends at and the RATE pin named."""
    board = _board(build_dir, sps=36)
    reader = _reader(board.port)
    try:
        reader.connect()
        assert reader.wait_frames(RATE_WINDOW + 1, 1.0)
        slow = r"stream is slow: fresh frames arrive at 3[4-8]\.\d/s, below the 40/s.*RATE pin low"
        with pytest.raises(ForceStreamError, match=slow):
            reader.read()
    finally:
        reader.disconnect()
        board.stop()


def test_a_board_whose_rate_pin_is_low_is_named(build_dir):
    """Tied low, RATE makes an HX711 convert 10 times a second: a sample, then a not-converting fault 50 ms later,
    ~20 frames/s. Whichever frame is the newest, the host refuses the stream and names the RATE pin (as "slow" after
    a sample, as the cells' fault after a fault frame)."""
    board = _board(build_dir, sps=10)
    reader = _reader(board.port)
    try:
        reader.connect()
        assert reader.wait_frames(6, 1.0)  # enough intervals for a rate
        assert 15 < reader.rate_hz() < 25, reader.rate_hz()
        with pytest.raises(ForceStreamError, match=r"RATE pin (is )?low"):
            reader.read()
    finally:
        reader.disconnect()
        board.stop()


def test_force_calibration_on_the_simulated_board(build_dir, tmp_path, monkeypatch):
    """`blindgrasp-calibrate-force`'s procedure on the firmware: the operator's weight on each pad in turn gives
    back the cells' own scales (signs included) and zeros."""
    board = _board(build_dir)
    weight_n = 0.5 * fc.STANDARD_GRAVITY
    loads = [[0, 0, 0], [weight_n, 0, 0], [0, weight_n, 0], [0, 0, weight_n], [0, 0, 0]]
    prompts = []

    def operator(prompt: str = "") -> str:
        board.set_forces(loads[len(prompts)])
        prompts.append(prompt)
        return ""

    monkeypatch.setattr("builtins.input", operator)
    robot = BlindgraspGripperConfig(
        id="lab", calibration_dir=tmp_path, force_sensor=ForceSensorConfig(port=board.port)
    )
    try:
        cal = calibrate_force(CalibrateForceConfig(robot=robot, mass_kg=0.5, settle_s=0.2, window_s=0.4))
    finally:
        board.stop()
    assert len(prompts) == 5 and "ff_tip" in prompts[1] and "th_tip" in prompts[3]
    np.testing.assert_allclose(cal.scales(), SCALE, rtol=3e-3)
    np.testing.assert_allclose(cal.offsets(), OFFSET, atol=60)
    assert fc.load_force_calibration(tmp_path / "lab.force.json").scales() == cal.scales()


# What the harness reports for a build that breaks each HX711 timing (T2 cannot be seen on the pins: its cost is
# the bits, each read one clock late).
BROKEN = {"T1": r"T1 [1-9]", "T2": None, "T3": r"T3 [1-9]\d* \(high < 0.2 us\)", "T4": r"T4 [1-9]"}


@pytest.mark.parametrize("timing", sorted(BROKEN))
def test_a_firmware_that_breaks_an_hx711_timing_fails(build_dir, timing):
    """Test builds of the firmware, each breaking one of the datasheet's minimum timings: T1 clocks chips whose DOUT
    has not fallen (reads all three when the first is ready), T2 samples DOUT one cycle (62.5 ns) after the rising
    edge, T3 holds PD_SCK high and T4 low for one port write (< 0.2 us). Each fails: the harness names the timing,
    or the counts come back wrong."""
    given = (100_000, -52_000, 12_000)
    board = SimulatedForceBoard(build_dir=build_dir, noise_counts=0, defines=(f"VIOLATE_{timing}",)).start()
    reader = _reader(board.port)
    try:
        board.set_counts(given)
        reader.connect()
        assert reader.wait_frames(20, 2.0)
        counts = reader.latest()[0].counts
    finally:
        reader.disconnect()
        board.stop()
    if BROKEN[timing]:
        assert re.search(BROKEN[timing], board.log), board.log
    else:
        assert counts != given, counts  # each bit read before it was valid: the previous one
    wrong = counts != given or "TIMING VIOLATIONS" in board.log
    assert wrong


def _reads_until_resynchronised(reader, deadline_s: float) -> list:
    """Read after read until one succeeds after the reader confirmed a restart (`deadline_s` bounds the wait far
    above the watchdog, the boot and the frames the host waits for; it is no timing assertion)."""
    seen, deadline = [], time.monotonic() + deadline_s
    while time.monotonic() < deadline:
        try:
            seen.append(reader.read())
            if reader.clock.restarts and reader.clock.restarts[-1].confirmed_seq >= 0:
                break
        except ForceStreamError as e:
            seen.append(str(e))
        time.sleep(0.005)
    return seen


def test_the_watchdog_resets_a_hung_firmware_and_the_host_resynchronises(build_dir, caplog):
    """A test build whose main loop hangs once, 1.5 s after power-on, with ff_tip loaded (4 N). No frame goes out, so
    the watchdog resets the board; it boots (every HX711 power-cycled) and sends its boot frame, "watchdog". The host
    names the reset, holds the stream until SETTLE_FRAMES frames advanced with time, and reads 4 N again with the
    same tare: stale in between, never 0 N."""
    board = _board(build_dir, defines=("HANG_ONCE_MS=1500",))
    reader = _reader(board.port)
    try:
        reader.connect()
        reader.tare(0.2)
        zero = reader.offset.copy()
        board.set_forces([4.0, 0.0, 0.0])
        assert reader.wait_frames(4, 1.0)
        with caplog.at_level(logging.WARNING):
            seen = _reads_until_resynchronised(reader, deadline_s=8.0)
    finally:
        reader.disconnect()
        board.stop()
    values = [s for s in seen if not isinstance(s, str)]
    assert any("stale" in s for s in seen if isinstance(s, str)), seen[-3:]
    np.testing.assert_allclose(values, [[4.0, 0.0, 0.0]] * len(values), atol=0.02)
    [restart] = reader.clock.restarts
    assert restart.cause == "watchdog" and restart.first_seq == 0 and restart.confirmed_seq == SETTLE_FRAMES
    np.testing.assert_array_equal(reader.offset, zero)
    assert "reset (watchdog)" in caplog.text and "replay" not in caplog.text, caplog.text
    assert "1 AVR resets" in board.log, board.log
    assert "TIMING VIOLATIONS" not in board.log, board.log


def test_a_stuck_hx711_is_power_cycled_and_comes_back(build_dir):
    """mf_tip's HX711 locks up (stops converting until it loses power). Its STATUS bit is set while it is stuck; after
    250 ms the firmware powers it down through PD_SCK and up again, and it converts again: the stream recovers with no
    host action and no board reset."""
    board = _board(build_dir)
    reader = _reader(board.port)
    try:
        reader.connect()
        reader.tare(0.2)
        board.send("hang 1")  # the chip locks up until the firmware power-cycles it
        time.sleep(0.15)
        with pytest.raises(ForceStreamError, match=r"mf_tip \(channel 1\) stopped converting"):
            reader.read()
        deadline = time.monotonic() + 5.0  # the 250 ms and the chip's 50 ms settling, with room for a busy host
        while reader.latest()[0].status and time.monotonic() < deadline:
            time.sleep(0.01)
        assert reader.wait_frames(RATE_WINDOW + 1, 1.0)
        np.testing.assert_allclose(reader.read(), 0.0, atol=0.02)
    finally:
        reader.disconnect()
        board.stop()
    assert "chip 1: " in board.log and re.search(r"chip 1: .* 2 power-downs", board.log), board.log
    assert "0 AVR resets" in board.log, board.log


def test_a_board_reset_by_its_reset_pin_comes_back_with_the_same_forces(build_dir):
    """The reset pin pulled (a USB glitch, DTR) with th_tip loaded: the boot frame says "reset pin", the host
    resynchronises on the rebooted board's frame SETTLE_FRAMES and reads the same 2 N. The chips were not reset with
    the AVR (only power-cycled by its boot), and stayed within every HX711 timing."""
    board = _board(build_dir)
    reader = _reader(board.port)
    try:
        reader.connect()
        reader.tare(0.2)
        board.set_forces([0.0, 0.0, 2.0])
        assert reader.wait_frames(4, 1.0)
        board.send("reset")  # the reset pin (a USB glitch, DTR): the chips keep converting
        seen = _reads_until_resynchronised(reader, deadline_s=8.0)
    finally:
        reader.disconnect()
        board.stop()
    values = [s for s in seen if not isinstance(s, str)]
    np.testing.assert_allclose(values, [[0.0, 0.0, 2.0]] * len(values), atol=0.02)
    [restart] = reader.clock.restarts
    assert restart.cause == "reset pin" and restart.confirmed_seq == SETTLE_FRAMES
    assert "1 AVR resets" in board.log and "TIMING VIOLATIONS" not in board.log, board.log
