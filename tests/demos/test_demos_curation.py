"""Curation rules (paper Sec. III-C) on synthetic trajectories, with values exactly at each threshold."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from lerobot_blindgrasp.demos import curation
from lerobot_blindgrasp.demos.curation import NO_CURATION, PAPER_CURATION, hold_run_lengths, judge_episode

T = 100  # 5 s at 20 Hz


def trajectory(hold_start: int, hold_len: int, level: float = 0.9, force_per_step=(2.0, 2.0, 1.0)):
    """r_t = level on [hold_start, hold_start + hold_len), 0 elsewhere; constant forces on every step."""
    r = np.zeros(T)
    r[hold_start : hold_start + hold_len] = level
    f = np.tile(np.asarray(force_per_step, dtype=np.float64), (T, 1))
    return r, f


def test_paper_thresholds_are_the_config_defaults():
    c = PAPER_CURATION
    assert (c.task_reward_threshold, c.min_hold_s, c.force_sum_threshold_n) == (0.5, 0.5, 200.0)
    assert c.min_hold_steps == 10 and c.episode_steps == 100


@pytest.mark.parametrize("hold_len, passes", [(9, False), (10, True), (11, True)])
def test_hold_of_exactly_half_a_second_passes(hold_len, passes):
    r, f = trajectory(30, hold_len)
    res = judge_episode(r, f)
    assert res.passed is passes and res.keep is passes
    assert res.longest_hold_steps == hold_len


def test_reward_exactly_at_threshold_does_not_count():
    r, f = trajectory(30, 50, level=0.5)  # r_t > 0.5 is strict
    res = judge_episode(r, f)
    assert not res.passed and res.longest_hold_steps == 0
    r2, _ = trajectory(30, 50, level=np.nextafter(0.5, 1.0))
    assert judge_episode(r2, f).passed


def test_interrupted_hold_does_not_add_up():
    r = np.zeros(T)
    r[10:19] = 0.9  # 9 steps
    r[20:29] = 0.9  # 9 more after a one-step drop: never 10 in a row
    f = np.full((T, 3), 5.0)
    res = judge_episode(r, f)
    assert res.longest_hold_steps == 9 and not res.passed


def test_force_sum_exactly_200_fails_and_just_above_passes():
    r, _ = trajectory(0, T)
    f = np.zeros((T, 3))
    f[:40] = (2.0, 2.0, 1.0)  # exactly 200 N over the episode
    res = judge_episode(r, f)
    assert res.force_sum_n == 200.0 and not res.passed
    f[50, 0] = 1e-6
    res = judge_episode(r, f)
    assert res.passed and res.force_sum_n > 200.0


def test_negative_readings_do_not_cancel_pressing():
    r, _ = trajectory(0, T)
    f = np.zeros((T, 3))
    f[:50, 0] = 4.1  # 205 N of compression on one sensor
    f[:50, 1] = -3.0  # a tip pulled along its axis: not pressing, must not subtract
    res = judge_episode(r, f)
    assert res.force_sum_n == pytest.approx(205.0) and res.passed


def test_kept_episodes_are_whole_by_default():
    # The paper keeps selected episodes as they are: the hold after the criteria is what teaches holding.
    assert not PAPER_CURATION.trim_to_success
    r, f = trajectory(30, 60, force_per_step=(5.0, 0.0, 0.0))
    res = judge_episode(r, f)
    assert res.passed and res.criteria_step == 40 and res.keep_steps == T


TRIM = dataclasses.replace(PAPER_CURATION, trim_to_success=True)


def test_trim_ends_at_the_step_both_criteria_hold():
    # Hold reaches 10 steps at step 39 (starts at 30); the force sum passes 200 N at step 40 (41 * 5 N = 205 N).
    r, f = trajectory(30, 60, force_per_step=(5.0, 0.0, 0.0))
    res = judge_episode(r, f, TRIM)
    assert res.criteria_step == 40 and res.keep_steps == 41
    # Force first, hold later: the cut is the later of the two.
    r, f = trajectory(60, 20, force_per_step=(10.0, 10.0, 10.0))
    res = judge_episode(r, f, TRIM)
    assert res.criteria_step == 69 and res.keep_steps == 70
    assert judge_episode(r, f).keep_steps == T


def test_no_curation_keeps_everything_whole_but_still_reports():
    r, f = trajectory(0, 0, force_per_step=(0.0, 0.0, 0.0))
    res = judge_episode(r, f, NO_CURATION)
    assert res.keep and res.keep_steps == T and not res.passed
    r, f = trajectory(30, 20)
    res = judge_episode(r, f, NO_CURATION)
    assert res.keep and res.keep_steps == T and res.passed


def test_short_episode_is_judged_on_what_it_has():
    # An episode that ended early (object left the workspace) after meeting both criteria is kept: whole, or
    # trimmed when asked.
    r, f = trajectory(5, 15, force_per_step=(10.0, 10.0, 10.0))
    assert judge_episode(r[:25], f[:25]).keep_steps == 25
    res = judge_episode(r[:25], f[:25], TRIM)
    assert res.passed and res.keep_steps == 15


def test_rejects_episodes_longer_than_the_window_and_empty_ones():
    with pytest.raises(ValueError, match="more than"):
        judge_episode(np.zeros(T + 1), np.zeros((T + 1, 3)))
    with pytest.raises(ValueError, match="empty"):
        judge_episode(np.zeros(0), np.zeros((0, 3)))


def test_hold_run_lengths():
    r = np.array([0.6, 0.7, 0.1, 0.9, 0.9, 0.9, 0.5, 0.51])
    assert hold_run_lengths(r, 0.5).tolist() == [1, 2, 0, 1, 2, 3, 0, 1]
    assert curation.CurationConfig(min_hold_s=0.25).min_hold_steps == 5


def test_a_real_scripted_lift_passes_and_an_idle_hand_does_not():
    """The thresholds are reachable in our physics: the scripted pinch-and-lift of the medium cylinder passes once
    lifted (kept whole, hold included; trimmed before the hold when asked), a hand that never moves fails both criteria."""
    from lerobot_blindgrasp import spec
    from lerobot_blindgrasp.demos.collection_loop import DEMO_TRACES
    from lerobot_blindgrasp.rollout.envs import make_batched_env
    from lerobot_blindgrasp.rollout.loop import stream
    from lerobot_blindgrasp.sim import randomization
    from lerobot_blindgrasp.sim.scripted import PinchLiftScript
    from lerobot_blindgrasp.sim.viewer import grasp_geometry

    name = "cylinder_a_medium"
    env = make_batched_env(
        "demos", (name,), num_envs=1, seed=spec.DEMO_SEED, episode_s=5.0, dr=randomization.NO_DR, nthread=1
    )
    script = PinchLiftScript(*grasp_geometry(name), lift_m=0.03)
    lifted = next(stream(env, lambda obs, env: script(env.joint_positions()), lambda: False, record=DEMO_TRACES))
    res = judge_episode(lifted.task_reward, lifted.uniaxial_force)
    assert lifted.length == T and lifted.success
    assert res.passed and 40 <= res.criteria_step < 90 and res.keep_steps == T
    assert judge_episode(lifted.task_reward, lifted.uniaxial_force, TRIM).keep_steps == res.criteria_step + 1
    assert res.force_sum_n > PAPER_CURATION.force_sum_threshold_n

    idle = next(stream(env, lambda obs, env: np.zeros((1, 9)), lambda: False, record=DEMO_TRACES))
    res = judge_episode(idle.task_reward, idle.uniaxial_force)
    assert not res.passed and res.force_sum_n == 0.0 and res.longest_hold_steps == 0
