"""`python -m lab.bench --bench.type=paper` (what scripts/gpu_run.sh runs on a GPU), at a tiny env count on the CPU
backend: every stage runs, the JSON is written, and its headline holds the issue's four figures."""

import json

import pytest

from lab.bench.paper_bench import BenchPaperConfig, headline, run


def test_the_paper_bench_runs_every_stage_and_writes_one_json(tmp_path):
    out = tmp_path / "paper.json"
    cfg = BenchPaperConfig(
        backend="batch", num_envs=18, iterations=1, env_steps=3, env_blocks=1, demo_s=3.0, output=out, json=True
    )
    result = run(cfg)
    assert json.loads(out.read_text()) == json.loads(json.dumps(result))
    stages = result["stages"]
    assert set(stages) == {"warmup", "loop", "demos"}
    assert not [k for k, v in stages.items() if "error" in v], stages
    assert result["preset"] == "paper" and result["num_envs"] == 18 and result["machine"]["gpu"] is None
    ppo = stages["loop"]["ppo"]
    assert ppo["preset"] == "paper" and ppo["iterations"] == 1 and ppo["hidden_dims"] == [512, 256, 128]
    head = result["headline"]
    assert head["env_steps_per_s_with_training"] == ppo["loop_env_steps_per_s"] > 0
    assert head["collection_over_raw_physics"] == ppo["collect_over_raw"] > 0
    assert head["collection_overhead_ms_per_step"] == ppo["overhead_ms_per_step"]
    assert head["update_over_collection"] == ppo["update_over_collect"] > 0
    assert head["table_iii_hours"] == pytest.approx(9000 * 24 * 4500 / ppo["loop_env_steps_per_s"] / 3600)
    # The collector was stopped as Ctrl-C stops it (exit 130), after its env was built and it had stepped.
    demos = stages["demos"]
    assert demos["stop_reason"] == "interrupted" and demos["exit_code"] == 130 and demos["env_steps"] > 0
    assert head["curated_demos_per_s"] == demos["kept"] / demos["collecting_s"]
    # A second call (a machine's per-call limit) re-runs one stage into the same JSON and keeps the others.
    again = run(BenchPaperConfig(backend="batch", num_envs=18, stages=["warmup"], output=out, json=True))
    assert again["stages"]["loop"] == stages["loop"] and again["stages"]["demos"] == stages["demos"]
    assert (
        again["headline"] == head and json.loads(out.read_text())["stages"]["warmup"] == again["stages"]["warmup"]
    )


def test_a_stage_not_run_is_not_measured():
    head = headline({})
    assert set(head) >= {
        "env_steps_per_s_with_training",
        "collection_over_raw_physics",
        "update_over_collection",
        "curated_demos_per_s",
    }
    assert all(v is None for v in head.values())
    with pytest.raises(ValueError, match="stages"):
        BenchPaperConfig(stages=["warmup", "gpu"])


def test_the_onemodel_stage_runs_only_when_named_and_only_on_warp():
    """The GPU run names it (scripts/gpu_run.sh); on the batch backend it has nothing to compare."""
    assert "onemodel" not in BenchPaperConfig().stages
    result = run(BenchPaperConfig(backend="batch", num_envs=18, stages=["onemodel"], json=True))
    assert set(result["stages"]) == {"onemodel"} and "skipped" in result["stages"]["onemodel"]
    head = result["headline"]
    assert head["groups_raw_control_steps_per_s"] is None and head["one_model_raw_control_steps_per_s"] is None
