"""The force board's SEQ judged against elapsed time (`hardware/force_board/counter_clock.py`), on an emulated
clock: the frame times are given, so every case is exact and no test depends on the machine's load. The clock is
built as the force reader builds it (`ForceSensorReader._new_clock`, 80 frames/s, stale timeout 0.15 s)."""

from __future__ import annotations

from lerobot_blindgrasp.hardware.force_board.counter_clock import FrameVerdict
from lerobot_blindgrasp.hardware.force_board.reader import SETTLE_FRAMES, ForceSensorReader

PERIOD = 1 / 80


def _clock():
    return ForceSensorReader("/dev/null", 115_200, [2.5e-5] * 3, stale_timeout_s=0.15)._new_clock()


def _run(clock, seqs, t0: float, period: float = PERIOD, boot_first: bool = False) -> list[FrameVerdict]:
    return [clock.judge(s, t0 + k * period, boot=boot_first and k == 0) for k, s in enumerate(seqs)]


def test_a_restart_after_its_boot_silence_is_held_then_live():
    clock = _clock()
    assert set(_run(clock, range(1000, 1100), 0.0)) == {FrameVerdict.LIVE}
    t = 100 * PERIOD + 0.3  # 0.3 s of silence while it boots, then SEQ from 0, no boot frame
    verdicts = _run(clock, range(10), t)
    assert verdicts == [FrameVerdict.HOLD] * SETTLE_FRAMES + [FrameVerdict.LIVE] * (10 - SETTLE_FRAMES)
    [r] = clock.restarts
    assert (r.last_seq, r.first_seq, r.confirmed_seq, r.marked) == (1099, 0, SETTLE_FRAMES, False)
    assert clock.lost == 0


def test_a_boot_frame_needs_no_silence_and_counts_even_across_the_wrap():
    """A host stall can hide the boot silence; the boot frame says it. Near the wrap a restart even looks like a
    forward step (65530 -> 0 is +6), which only the boot frame tells apart."""
    clock = _clock()
    _run(clock, range(65_500, 65_531), 0.0)
    verdicts = _run(clock, range(6), 31 * PERIOD, boot_first=True)
    assert verdicts == [FrameVerdict.HOLD] * SETTLE_FRAMES + [FrameVerdict.LIVE] * (6 - SETTLE_FRAMES)
    assert clock.restarts[0].marked and clock.restarts[0].last_seq == 65_530


def test_replays_never_go_live():
    clock = _clock()
    _run(clock, range(5000, 5100), 0.0)
    t = 100 * PERIOD
    backwards = _run(clock, range(5098, 4098, -1), t)  # a counter running backwards at the board's rate, 12.5 s
    assert set(backwards) == {FrameVerdict.BACKWARD}
    in_order = _run(clock, range(800), t + 1000 * PERIOD)  # an old recording from SEQ 0, with no silence
    assert set(in_order) == {FrameVerdict.BACKWARD}
    resent = _run(clock, [5099] * 50, t + 1800 * PERIOD)
    assert set(resent) == {FrameVerdict.REPEAT} and not clock.restarts


def test_a_counter_ahead_of_time_is_dropped_and_the_stream_goes_on():
    clock = _clock()
    _run(clock, range(100, 120), 0.0)
    t = 20 * PERIOD
    assert clock.judge(30_000, t) is FrameVerdict.AHEAD  # 29 880 frames in 12.5 ms
    assert _run(clock, range(120, 130), t) == [FrameVerdict.LIVE] * 10
    # Lost frames are a forward step the time allows: 40 lost over half a second (USB, CRC errors).
    assert clock.judge(170, t + 10 * PERIOD + 0.5) is FrameVerdict.LIVE and clock.lost == 40


def test_a_stray_frame_taken_for_a_restart_is_cancelled_by_the_old_counter():
    """A frame with SEQ 3 after a 0.1 s host stall looks like a restart; the next frame continues the old counter
    (the board never reset), so the restart is dropped and the stream goes on from it."""
    clock = _clock()
    _run(clock, range(700, 720), 0.0)
    t = 20 * PERIOD + 0.1
    assert clock.judge(3, t) is FrameVerdict.HOLD
    assert _run(clock, range(728, 732), t + PERIOD) == [FrameVerdict.LIVE] * 4
    assert not clock.restarts and clock.resyncing is None
