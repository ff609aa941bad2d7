"""`blindgrasp-bench --bench.type=teacher --bench.profile_update=true`: the PPO update split into rsl-rl's parts
(issue 48's teacher-loop figures)."""

from __future__ import annotations

import pytest


@pytest.mark.slow
def test_the_ppo_update_is_split_into_rsl_rls_parts(capsys):
    from lerobot_blindgrasp.bench.teacher import UPDATE_PARTS, BenchTeacherConfig, run

    r = run(
        BenchTeacherConfig(preset="quick", num_envs=18, iterations=1, threads=1, profile_update=True, json=True)
    )
    parts = r["update_parts"]
    assert set(parts) == {*UPDATE_PARTS, "rest", "total_s"} and parts["total_s"] > 0
    shares = [parts[p] for p in (*UPDATE_PARTS, "rest")]
    assert all(0 <= s <= 1 for s in shares) and sum(shares) == pytest.approx(1, abs=0.05)
    assert parts["forward"] > 0 and parts["backward"] > 0 and parts["optimizer_step"] > 0  # the parts were found
    assert r["update_s_per_it"] > 0  # the timed iteration ran without the profiler
