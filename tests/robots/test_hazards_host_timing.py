"""Hazards of the host loop's timing (docs/hardware.md, "Hazard analysis", table "The host loop's timing and OS
resources": loop period, sample spacing). Slow streaks are named when they start and when they end, and one as
long as the success rule's hold stops the gripper; after a read that stalled 30-49 ms the next sample is not taken
early, in a loop paced as LeRobot's and in the eval trial. The rules alone run on an emulated clock, so their
assertions do not depend on this machine's speed."""

from __future__ import annotations

import logging
import math
import time

import numpy as np
import pytest
from emulators.harness import trial_env
from emulators.loop import as_q, stopped
from hypothesis import given, settings
from hypothesis import strategies as st
from lerobot.utils.robot_utils import precise_sleep

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.hardware.loop_timing import LoopOverrunError, PeriodMonitor, SampleSpacing
from lerobot_blindgrasp.robots.blindgrasp_gripper import BlindgraspGripperConfig
from lerobot_blindgrasp.robots.blindgrasp_gripper.errors import GripperTimingError

DT = spec.CONTROL_DT


# --- loop period: slow streaks, on an emulated clock (`PeriodMonitor.tick` takes `now`) -------------------------
def _monitor() -> PeriodMonitor:
    config = BlindgraspGripperConfig()  # the shipped defaults
    return PeriodMonitor(1.0 / config.loop_hz, config.max_overrun_s, what="loop")


def _run(mon: PeriodMonitor, t: float, periods) -> float:
    for p in periods:
        t += p
        mon.tick(t)
    return t


def test_every_streak_is_named_when_it_starts_and_when_it_ends(caplog):
    """One slow period right after the reset spends the warning; later a second stall."""
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
    """After a bus stall a trial runs 10 steps at 6-8 Hz: it stops once the streak is as long as the hold (1 s) and
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


def test_a_slow_bus_is_warned_and_a_sustained_overrun_stops(rig, robot, caplog):
    """Every packet answered 20 ms late: a lerobot-record-shaped loop at 20 Hz runs near 8 Hz. Warned at the first
    overrun, named when the streak starts, stopped with a named error after max_overrun_s of it."""
    rig.dxl.reply_delay_s = 0.02
    t0 = time.monotonic()
    with caplog.at_level(logging.WARNING), pytest.raises(GripperTimingError, match=r"overrun its 50 ms period"):
        while time.monotonic() - t0 < 10.0:
            start = time.perf_counter()
            obs = robot.get_observation()
            robot.send_action({k: obs[k] for k in spec.ACTION_NAMES})
            time.sleep(max(0.0, spec.CONTROL_DT - (time.perf_counter() - start)))
    rig.dxl.reply_delay_s = 0.0
    assert "slow streak started" in caplog.text and "slow streak ended (stopped)" in caplog.text
    streak = robot.timing.streaks[-1]  # the one that stopped it, by the monitor's own clock
    assert streak.seconds >= robot.config.max_overrun_s and streak.periods >= robot.timing.min_overruns
    assert stopped(rig, robot)


# --- sample spacing: no short step after a stall ----------------------------------------------------------------
def _sample_times(robot) -> list[float]:
    """When each observation's data was in: the end of its reads (positions, then forces), as the robot saw it.
    (Not the return of get_observation: on a loaded CI host the thread may wait there for the CPU, after the data.)"""
    times: list[float] = []
    after_read = robot.spacing.after_read

    def timed(started: float, ended: float) -> None:
        times.append(ended)
        after_read(started, ended)

    robot.spacing.after_read = timed
    return times


STALLS_MS = {4: 30, 9: 39, 14: 45, 19: 49}  # step -> how long that step's read stalls (a slow bus, a loaded host)


def _stall_reads(robot, step: list[int]) -> None:
    """The force read of the steps in STALLS_MS takes that much longer: the whole observation is that late."""
    read = robot.force.read

    def slow():
        if (ms := STALLS_MS.get(step[0])) is not None:
            time.sleep(ms / 1e3)
        return read()

    robot.force.read = slow


def _assert_spaced(times: list[float]) -> None:
    gaps = np.diff(times)
    # The contract is 0.9 period (`SampleSpacing.min_gap_s`). 0.75 leaves room for a read faster than the recent ones
    # and for the timestamps themselves, which a shared 2-core CI host at load ~9 delays by several ms. Unspaced, a
    # 30-49 ms read is followed by the next sample 3-19 ms later.
    assert gaps.min() >= 0.75 * DT, np.round(gaps * 1e3, 1)


def _lerobot_paced_loop(robot, steps: int, step: list[int]) -> None:
    """lerobot_record.py's `record_loop`: observe, act, sleep the rest of the period from the loop's start."""
    for step[0] in range(steps):
        start = time.perf_counter()
        obs = robot.get_observation()
        robot.send_action(dict(zip(spec.ACTION_NAMES, as_q(obs).tolist(), strict=True)))
        precise_sleep(max(DT - (time.perf_counter() - start), 0.0))


def test_no_short_step_after_a_stall_in_a_loop_paced_as_lerobots(rig, robot):
    """lerobot-record's and lerobot-rollout's loop (lerobot_record.py `record_loop`): observe, act, sleep the rest of
    the period from the loop's start. After a stalled observation it goes straight on; the robot spaces its samples
    (`timing.SampleSpacing`), whatever the stall's length."""
    times, step = _sample_times(robot), [0]
    _stall_reads(robot, step)
    _lerobot_paced_loop(robot, 24, step)
    _assert_spaced(times)
    assert robot.spacing.waits >= len(STALLS_MS)


class _EmulatedClock:
    """A clock that moves only when the loop sleeps or a read takes time: the spacing rule's outcome on it does not
    depend on how busy the machine running the test is."""

    def __init__(self):
        self.t = 0.0

    def now(self) -> float:
        return self.t

    def sleep(self, s: float) -> None:
        self.t += max(s, 0.0)


def _paced_loop_on_clock(read_s: list[float]) -> tuple[SampleSpacing, list[float], list[int]]:
    """lerobot_record.py's loop (observe, act, sleep the rest of the period) on an emulated clock, each step's read
    taking `read_s[i]`; returns the spacing, when each read ended and the reads held back so far after each step."""
    clock = _EmulatedClock()
    spacing, ends, waits = SampleSpacing(DT, clock=clock.now, sleep=clock.sleep), [], []
    for read in read_s:
        start = clock.now()
        spacing.before_read()
        began = clock.now()
        clock.sleep(read)
        spacing.after_read(began, clock.now())
        ends.append(clock.now())
        waits.append(spacing.waits)
        clock.sleep(DT - (clock.now() - start))
    return spacing, ends, waits


@settings(max_examples=60, deadline=None)
@given(read_s=st.floats(0.0, 0.045))
def test_a_steadily_loaded_loop_is_not_slowed(read_s):
    """Reads that take the same time every step (a slow bus all along), up to 0.9 period: once the spacing has seen
    `SampleSpacing.MIN_READS` reads it never holds one back, and the samples come exactly one period apart. (The
    first reads after a (re)start are spaced as if reads took no time.)"""
    # MIN_READS reads teach it the read time; the holds made before then shift the caller's phase, which its own
    # sleep absorbs over a few more periods (at most 0.1 period a step, the slack).
    warm_up = 3 * SampleSpacing.MIN_READS
    _, ends, waits = _paced_loop_on_clock([read_s] * 36)
    assert waits[-1] == waits[warm_up]  # nothing held back after the warm-up
    assert np.diff(ends[warm_up:]) == pytest.approx(DT, abs=1e-9)


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), base_s=st.floats(0.0, 0.035), jitter_s=st.floats(0.0, 0.01))
def test_jittery_reads_stay_spaced_within_their_own_jitter(seed, base_s, jitter_s):
    """Reads that vary by up to `jitter_s` (bus jitter, a health read): the rule expects the shortest recent read,
    so a sample can come early only by as much as a read undercuts that, never by more than the jitter."""
    rng = np.random.default_rng(seed)
    spacing, ends, _ = _paced_loop_on_clock(list(base_s + jitter_s * rng.random(60)))
    assert np.diff(ends).min() >= spacing.min_gap_s - jitter_s - 1e-9


def _force_trial(robot_config):
    """An unattended force-mode eval trial, long enough for the steps below."""
    return trial_env(robot_config, "foam_brick", success_mode="force", unattended_reset_s=0.0, episode_s=5.0)


def test_no_short_step_after_a_stall_in_the_eval_trial(calibrated):
    env = _force_trial(calibrated)
    try:
        env.reset(seed=0)
        times, step = _sample_times(env.robot), [0]
        _stall_reads(env.robot, step)
        for step[0] in range(24):
            env.step(spec.HOME_POSE)
        _assert_spaced(times)
        # The trial spaces its reads itself (`StepPacer`, re-based on the held read), and the loop keeps its rate.
        assert env._schedule.spacing.waits >= len(STALLS_MS)
        assert np.median(np.diff(times)) <= 1.5 * DT
    finally:
        env.close()


def test_the_trial_rebases_after_a_stall_instead_of_bursting(rig, calibrated):
    env = _force_trial(calibrated)
    try:
        env.reset(seed=0)
        timing = env.robot.timing
        for k in range(16):
            rig.dxl.reply_delay_s = 0.03 if k in (4, 5) else 0.0  # two steps stalled by a slow bus (~0.2 s each)
            env.step(spec.HOME_POSE)
            if k == 5:
                after_stall = len(timing.recent)
        # The observation times (one per step, at the schedule's tick): no catch-up burst (3 ms apart). A
        # tick can come up to one sleep overshoot early relative to a late previous one, hence half a period.
        periods = np.array(timing.recent)[after_stall:]
        assert len(periods) == 10 and periods.min() >= 0.5 * spec.CONTROL_DT, periods
        assert env._schedule.rebased >= 1 and timing.overruns >= 1
    finally:
        env.close()
