"""`python -m lab.bench --bench.type=policy` and `--bench.type=build` run end to end (at a small size) and report a
consistent result."""

from __future__ import annotations

import json

import pytest
import torch

from lab.bench import main
from lab.bench.build_bench import BenchBuildConfig, run


def test_policy_bench_json(capsys):
    previous = torch.get_num_threads()
    try:
        main(
            [
                "--bench.type=policy",
                "--bench.size=quick",
                "--bench.steps=35",
                "--bench.rounds=1",
                "--bench.json=true",
            ]
        )
    finally:
        torch.set_num_threads(previous)  # the bench pins torch to one thread, as it measures
    result = json.loads(capsys.readouterr().out)
    assert result["size"] == "quick" and result["threads"] == 1
    # The fast path was checked against the plain path on every step, padded start included.
    assert result["max_abs_diff_fast_vs_plain"] < 1e-5
    assert 0 < result["flops_per_step_fast"] < result["flops_per_step"]
    for clock in ("wall", "cpu"):
        entry = result[clock]
        assert entry["model_gemm_gflops"] > 0 and entry["peak_gemm_gflops"] > 0
        assert entry["fast"]["p50_ms"] <= entry["fast"]["p95_ms"]
        assert entry["floor_ms"] == pytest.approx(result["flops_per_step"] / entry["model_gemm_gflops"] / 1e6)
    assert isinstance(result["target_met"], bool)


def test_policy_bench_table(capsys):
    previous = torch.get_num_threads()
    try:
        main(["--bench.type=policy", "--bench.size=quick", "--bench.steps=32", "--bench.rounds=1"])
    finally:
        torch.set_num_threads(previous)
    table = capsys.readouterr().out
    assert "| select_action (fast) |" in table and "floor: FLOPs / model-GEMM throughput" in table


@pytest.mark.parametrize("backend", ["batch", "warp"])
def test_the_build_bench_times_each_count_and_says_the_load(backend):
    """Env construction timed per env count, on both backends, at tiny counts."""
    cfg = BenchBuildConfig(num_envs=[4, 8], backend=backend, device="cpu", repeats=2, warmup_envs=4, json=True)
    result = run(cfg)
    assert result["backend"] == backend and [r["num_envs"] for r in result["rows"]] == [4, 8]
    for r in result["rows"]:
        assert len(r["builds"]) == 2 and r["seconds"] == min(b["seconds"] for b in r["builds"]) > 0
        assert r["envs_per_s"] == pytest.approx(r["num_envs"] / r["seconds"])
        assert r["device"] == "cpu" and all(b["load_before"] >= 0 for b in r["builds"])
    with pytest.raises(ValueError, match="backend"):
        BenchBuildConfig(backend="gpu")
