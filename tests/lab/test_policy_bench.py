"""`python -m lab.bench --bench.type=policy` runs end to end (at a small size) and reports a consistent result."""

from __future__ import annotations

import json

import pytest
import torch

from lab.bench import main


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
