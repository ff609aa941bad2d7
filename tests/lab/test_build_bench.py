"""`python -m lab.bench --bench.type=build`: env construction timed per env count, on both backends, at tiny counts."""

import pytest

from lab.bench.build_bench import BenchBuildConfig, run


@pytest.mark.parametrize("backend", ["batch", "warp"])
def test_the_build_bench_times_each_count_and_says_the_load(backend):
    cfg = BenchBuildConfig(num_envs=[4, 8], backend=backend, device="cpu", repeats=2, warmup_envs=4, json=True)
    result = run(cfg)
    assert result["backend"] == backend and [r["num_envs"] for r in result["rows"]] == [4, 8]
    for r in result["rows"]:
        assert len(r["builds"]) == 2 and r["seconds"] == min(b["seconds"] for b in r["builds"]) > 0
        assert r["envs_per_s"] == pytest.approx(r["num_envs"] / r["seconds"])
        assert r["device"] == "cpu" and all(b["load_before"] >= 0 for b in r["builds"])
    with pytest.raises(ValueError, match="backend"):
        BenchBuildConfig(backend="gpu")
