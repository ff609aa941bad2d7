"""The evaluation protocol: disjoint seed ranges per stage, per-object start states, Wilson intervals, pairing."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.demos import collect_cli
from lerobot_blindgrasp.pipeline import recipe
from lerobot_blindgrasp.results import rates
from lerobot_blindgrasp.sim import objects


def test_stage_seed_ranges_are_disjoint_and_hold_every_default():
    ranges = spec.SEED_RANGES
    assert set(ranges) == {"teacher_train", "demos", "eval"}
    for (a, ra), (b, rb) in itertools.combinations(ranges.items(), 2):
        assert ra.stop <= rb.start or rb.stop <= ra.start, f"{a} and {b} overlap"
    # Each CLI's default start seed and a generous run size fall in its own range, not in another's.
    spec.check_seeds("teacher_train", spec.TEACHER_TRAIN_SEED, 9000)  # the paper's env count
    spec.check_seeds("demos", collect_cli.CollectConfig.seed, 9000 * 1000)  # 1000 env rebuilds
    spec.check_seeds("demos", recipe.DEMO_SEED_BLOCK * 100 + spec.DEMO_SEED, recipe.DEMO_SEED_BLOCK)
    for stage, r in ranges.items():
        for other in set(ranges) - {stage}:
            with pytest.raises(ValueError, match=f"outside the {other} range"):
                spec.check_seeds(other, r.start, 1)


def test_every_eval_seed_of_every_object_is_in_the_eval_range_and_objects_never_share_one():
    eval_range = spec.SEED_RANGES["eval"]
    n_tasks = len(objects.CATALOGUE)
    seen = set()
    for tid in range(n_tasks):
        for s in (0, spec.EVAL_SEED, spec.EVAL_TASK_STRIDE - 1):  # first, default and last index of a block
            env_seed = spec.eval_env_seed(s, tid)
            assert env_seed in eval_range
            seen.add(env_seed)
    assert len(seen) == 3 * n_tasks
    # Object blocks do not touch: the last index of one object is just below the first of the next.
    assert spec.eval_env_seed(spec.EVAL_TASK_STRIDE - 1, 0) + 1 == spec.eval_env_seed(0, 1)
    for bad in (-1, spec.EVAL_TASK_STRIDE):
        with pytest.raises(ValueError, match="evaluation seed"):
            spec.eval_env_seed(bad, 0)


def test_lerobot_eval_seeds_reach_the_env_as_per_object_eval_seeds():
    """The blindgrasp env config builds envs that map lerobot-eval's seeds per object (no two tasks alike)."""
    from lerobot_blindgrasp.envs.sim_env import BlindGraspEnvConfig, object_for_task_id

    cfg = BlindGraspEnvConfig(task="cuboid_a_large,sphere_small")
    envs = cfg.create_envs(n_envs=2)["blindgrasp"]
    first_obs, env_seeds = {}, {}
    for tid, vec in envs.items():
        obs, info = vec.reset(seed=[spec.EVAL_SEED, spec.EVAL_SEED + 1])
        name = object_for_task_id(tid)
        env_seeds[name] = list(info["env_seed"])
        assert env_seeds[name] == [spec.eval_env_seed(spec.EVAL_SEED + k, tid) for k in range(2)]
        first_obs[name] = obs["agent_pos"][0]
        vec.close()
    a, b = first_obs.values()
    assert not np.allclose(a[spec.STATE_JOINT_SLICE], b[spec.STATE_JOINT_SLICE])  # different start poses


@pytest.mark.parametrize(
    ("k", "n", "low", "high"),
    # Reference values from the closed form (Wilson 1927), z = 1.96, rounded to 3 decimals.
    [(0, 20, 0.0, 0.161), (20, 20, 0.839, 1.0), (10, 20, 0.299, 0.701), (60, 90, 0.564, 0.755)],
)
def test_wilson_interval(k, n, low, high):
    lo, hi = rates.wilson_interval(k, n)
    assert lo == pytest.approx(low, abs=1e-3) and hi == pytest.approx(high, abs=1e-3)
    assert lo <= k / n <= hi


def test_rate_formatting_and_bad_counts():
    assert rates.format_rate(13, 20) == "65 % [43-82] (13/20)"
    assert rates.format_rate(0, 0) == "n/a (0 episodes)"
    with pytest.raises(ValueError):
        rates.wilson_interval(3, 2)


def test_paired_counts_and_the_exact_mcnemar_test():
    t = [True, True, False, False, True]
    s = [True, False, True, False, True]
    assert rates.paired_counts(t, s) == {"both": 2, "a_only": 1, "b_only": 1, "neither": 1}
    with pytest.raises(ValueError, match="equal counts"):
        rates.paired_counts(t, s[:4])
    # Hand values: 0 vs 6 discordant pairs is 2 x 0.5**6; 1 vs 9 is 2 x 11 / 1024; a tie is 1.
    assert rates.mcnemar_exact_p(0, 6) == pytest.approx(2 / 64)
    assert rates.mcnemar_exact_p(9, 1) == pytest.approx(22 / 1024)
    assert rates.mcnemar_exact_p(4, 4) == 1.0 and rates.mcnemar_exact_p(0, 0) == 1.0
    # A report's reading of p says which side of the threshold it is on (it once said "below 0.05" for p = 0.25).
    assert rates.paired_verdict(0.253).startswith("not below 0.05: no difference")
    assert rates.paired_verdict(0.01).startswith("below 0.05: the two differ")


def test_paired_difference_pools_objects_in_the_given_order():
    a = {"x": [True, True, False], "y": [True]}
    b = {"x": [True, False, True], "y": [False], "z": [True]}  # z is not among the keys: left out
    d = rates.paired_difference(a, b, ["x", "y"])
    counts = ("both", "a_only", "b_only", "neither", "n", "a_successes", "b_successes")
    assert [d[k] for k in counts] == [1, 2, 1, 0, 4, 3, 2]
    assert d["diff_pp"] == pytest.approx(-25.0) and d["p"] == rates.mcnemar_exact_p(2, 1) == 1.0
    # An object one side lacks counts as no episodes there, so the two no longer pair.
    with pytest.raises(ValueError, match="equal counts"):
        rates.paired_difference(a, b, ["x", "z"])
