"""Slow streaks of the control loop, named as they happen (docs/hardware.md, "loop period"), on an emulated clock:
`PeriodMonitor.tick` takes `now`, so no assertion depends on this machine's speed."""

from __future__ import annotations

import logging
import math

import pytest

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.hardware.loop_timing import LoopOverrunError, PeriodMonitor
from lerobot_blindgrasp.robots.blindgrasp_gripper import BlindgraspGripperConfig

DT = spec.CONTROL_DT


def _monitor() -> PeriodMonitor:
    config = BlindgraspGripperConfig()  # the shipped defaults
    return PeriodMonitor(1.0 / config.loop_hz, config.max_overrun_s, what="loop")


def _run(mon: PeriodMonitor, t: float, periods) -> float:
    for p in periods:
        t += p
        mon.tick(t)
    return t


def test_every_streak_is_named_when_it_starts_and_when_it_ends(caplog):
    """The issue's case: one slow period right after the reset spends the warning; later a second stall."""
    mon = _monitor()
    with caplog.at_level(logging.WARNING):
        t = _run(mon, 0.0, [0.0, 0.12] + [DT] * 20)  # one slow period after the reset
        t = _run(mon, t, [0.09, 0.11, 0.10] + [DT] * 5)  # a second streak, three periods
    starts = [r.message for r in caplog.records if "slow streak started" in r.message]
    ends = [r.message for r in caplog.records if "slow streak ended" in r.message]
    assert len(starts) == 2 and len(ends) == 2 and len(caplog.records) == 4  # one warning each way, per streak
    assert "after 3 periods, 0.30 s" in ends[1] and "worst period 110 ms" in ends[1]
    assert [(s.periods, round(s.seconds, 2)) for s in mon.streaks] == [(1, 0.12), (3, 0.3)]


def test_ten_steps_at_7_hz_stop_with_a_named_error(caplog):
    """After a bus stall the trial ran 10 steps at 6-8 Hz: it stops once the streak is as long as the hold (1 s) and
    10 periods long."""
    mon = _monitor()
    t = _run(mon, 0.0, [0.0] + [DT] * 10)
    slow = 0.15  # 6.7 Hz
    needed = max(mon.min_overruns, math.ceil(mon.max_overrun_s / slow))  # 10 periods = 1.5 s: the 10 steps
    with caplog.at_level(logging.WARNING):
        t = _run(mon, t, [slow] * (needed - 1))
        with pytest.raises(LoopOverrunError, match=rf"in a row \({needed} periods, worst 150 ms, about 6\.7 Hz"):
            mon.tick(t + slow)
    assert f"slow streak ended (stopped) after {needed} periods" in caplog.text


def test_a_few_slow_steps_are_named_but_do_not_stop():
    """Deliberately slow calls (a script waiting 0.4 s between them), one fewer than min_overruns: named only."""
    mon = _monitor()
    _run(mon, 0.0, [0.0] + [0.4] * (mon.min_overruns - 1) + [DT])
    assert mon.streaks[-1].periods == mon.min_overruns - 1 and mon.streak is None


def test_a_pause_ends_a_streak_and_a_slow_loop_with_the_stop_off_is_only_named(caplog):
    mon = _monitor()
    _run(mon, 0.0, [0.0, 0.2, 0.2, 1.5])  # a pause (a dataset save) ends the streak
    assert mon.streak is None and "ended (a pause of 1.5 s) after 2 periods" in " ".join(
        r.message for r in caplog.records
    )
    off = PeriodMonitor(DT, max_overrun_s=0.0)
    _run(off, 0.0, [0.0] + [0.2] * 50)  # 10 s at 5 Hz: never stops
    assert off.streak.periods == 50
