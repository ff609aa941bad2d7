"""`python -m lab.bench --bench.type=teacher`: raw physics timed beside collection, the PPO update's variants on one
rollout, and the update split into rsl-rl's parts (issue 48's teacher-loop figures)."""

from __future__ import annotations

import pytest


@pytest.mark.slow
def test_the_ppo_update_is_split_into_rsl_rls_parts(capsys):
    from lab.bench.teacher_bench import UPDATE_PARTS, BenchTeacherConfig, run

    r = run(
        BenchTeacherConfig(
            preset="quick",
            num_envs=18,
            iterations=2,
            threads=1,
            profile_update=True,
            update_variants=["5x4@1", "5x2@1"],
            variant_rounds=1,
            json=True,
        )
    )
    parts = r["update_parts"]
    assert set(parts) == {*UPDATE_PARTS, "rest", "total_s"} and parts["total_s"] > 0
    shares = [parts[p] for p in (*UPDATE_PARTS, "rest")]
    assert all(0 <= s <= 1 for s in shares) and sum(shares) == pytest.approx(1, abs=0.05)
    assert parts["forward"] > 0 and parts["backward"] > 0 and parts["optimizer_step"] > 0  # the parts were found
    assert r["update_s_per_it"] > 0  # the timed iteration ran without the profiler
    # raw physics was timed after each iteration, beside the collection it is compared with
    assert len(r["per_iteration"]) == 2 and all(row["raw_control_steps_per_s"] > 0 for row in r["per_iteration"])
    assert r["collect_over_raw"] == pytest.approx(r["collect_env_steps_per_s"] / r["raw_control_steps_per_s"])
    variants = r["update_variants"]
    assert [v["variant"] for v in variants] == ["5x4@1", "5x2@1"] and variants[0]["over_first"] == 1
    assert all(v["update_s"] > 0 for v in variants)


def test_an_update_variant_is_epochs_x_minibatches_at_threads():
    from lab.bench.teacher_bench import BenchTeacherConfig, parse_variant

    assert parse_variant("5x4@2") == (5, 4, 2)
    with pytest.raises(ValueError, match="EPOCHSxMINIBATCHES@THREADS"):
        BenchTeacherConfig(preset="quick", update_variants=["5x0@1"])
