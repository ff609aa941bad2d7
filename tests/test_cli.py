"""draccus configs for the blindgrasp-* commands: new spellings, YAML configs, deprecated argparse spellings."""

from __future__ import annotations

from pathlib import Path

import pytest

from lerobot_blindgrasp.cli import parse_config, translate_legacy_args
from lerobot_blindgrasp.teacher.train import TrainTeacherConfig


def test_draccus_spellings_and_yaml_config(tmp_path):
    cfg = parse_config(TrainTeacherConfig, ["--output_dir=runs/t", "--preset=quick", "--no_incentive=true"])
    assert cfg.output_dir == Path("runs/t") and cfg.preset == "quick" and cfg.no_incentive and cfg.export
    yaml = tmp_path / "t.yaml"
    yaml.write_text("output_dir: runs/y\npreset: quick\niterations: 7\nexport: false\n")
    cfg = parse_config(TrainTeacherConfig, ["--config_path", str(yaml), "--iterations=9"])
    assert cfg.output_dir == Path("runs/y") and cfg.iterations == 9 and not cfg.export  # flags override the file


def test_legacy_argparse_spellings_still_work_with_a_deprecation_note(capsys):
    old = ["--preset", "quick", "--output-dir", "runs/t", "--num-envs", "36", "--no-incentive", "--no-export"]
    new, notes = translate_legacy_args(TrainTeacherConfig, old)
    assert new == ["--preset", "quick", "--output_dir", "runs/t", "--num_envs", "36", "--no_incentive=true",
                   "--export=false"]
    assert len(notes) == 4
    cfg = parse_config(TrainTeacherConfig, old)
    assert cfg.num_envs == 36 and cfg.no_incentive and not cfg.export
    assert "deprecated flag spelling" in capsys.readouterr().err


def test_bad_input_is_one_clear_line():
    with pytest.raises(SystemExit, match="unknown teacher preset 'bogus'"):
        parse_config(TrainTeacherConfig, ["--preset=bogus", "--output_dir=x"])
    with pytest.raises(SystemExit, match="--output_dir is required"):
        parse_config(TrainTeacherConfig, ["--preset=quick"])


def test_every_command_accepts_its_release_0_1_spellings(capsys):
    """The exact argv that pipeline.py and the recorded commands in docs/results pass, on each command's config."""
    from lerobot_blindgrasp.bench.sim import BenchSimConfig
    from lerobot_blindgrasp.demos import collect
    from lerobot_blindgrasp.hub import push
    from lerobot_blindgrasp.teacher import evaluate, export

    cfg = parse_config(
        collect.CollectConfig,
        ["--teacher", "runs/t", "--out", "runs/d", "--repo-id", "me/d", "--episodes-per-object", "3",
         "--max-rollouts-per-object", "9", "--num-envs", "18", "--seed", "1099511627777", "--no-progress",
         "--deterministic", "--no-curation", "--resume"],
        collect.LEGACY,
    )  # fmt: skip
    assert (cfg.teacher, cfg.output_dir, cfg.repo_id) == (Path("runs/t"), Path("runs/d"), "me/d")
    assert (cfg.episodes_per_object, cfg.max_rollouts_per_object, cfg.num_envs) == (3, 9, 18)
    assert not (cfg.progress or cfg.stochastic or cfg.curation.enabled) and cfg.resume
    cfg = parse_config(collect.CollectConfig, ["--out", "d", "--repo-id", "me/d", "--trim-at-criteria"], collect.LEGACY)
    assert cfg.curation.trim_to_success and cfg.curation.enabled and cfg.stochastic

    cfg = parse_config(
        evaluate.EvalTeacherConfig,
        ["runs/t", "--episodes", "4", "--objects", "sphere_small,capsule_small", "--seed", "1003", "--modes",
         "deterministic", "--out", "runs/t/eval"],
        evaluate.LEGACY,
    )  # fmt: skip
    assert (cfg.teacher, cfg.output_dir, cfg.episodes, cfg.seed) == (Path("runs/t"), Path("runs/t/eval"), 4, 1003)
    assert cfg.mode_names == ("deterministic",) and cfg.objects == "sphere_small,capsule_small"

    cfg = parse_config(export.ExportTeacherConfig, ["runs/t", "models/t", "--overwrite-card"], export.LEGACY)
    assert (cfg.source, cfg.output_dir, cfg.overwrite_card) == (Path("runs/t"), Path("models/t"), True)

    cfg = parse_config(
        push.PushDatasetConfig, ["runs/d", "--repo-id", "me/d", "--tag", "a", "--operator", "alice", "--tag", "b"],
        push.LEGACY,
    )  # fmt: skip
    assert (cfg.root, cfg.tags, cfg.operators) == (Path("runs/d"), ["a", "b"], ["alice"])

    cfg = parse_config(BenchSimConfig, ["--num-envs", "36", "--threads", "1", "2", "--json"])
    assert (cfg.num_envs, cfg.threads, cfg.json) == (36, [1, 2], True)
    assert "deprecated flag spelling" in capsys.readouterr().err


def test_new_spellings_pass_through_untouched():
    from lerobot_blindgrasp.bench.sim import BenchSimConfig
    from lerobot_blindgrasp.teacher import evaluate

    argv = ["--teacher=runs/t", "--episodes", "4", "--progress", "false", "--output_dir=o"]
    assert translate_legacy_args(evaluate.EvalTeacherConfig, argv, evaluate.LEGACY) == (argv, [])
    argv = ["--threads=[1,2]", "--backend", "batch"]
    assert translate_legacy_args(BenchSimConfig, argv) == (argv, [])
    with pytest.raises(SystemExit, match="unknown mode"):
        parse_config(evaluate.EvalTeacherConfig, ["--modes=greedy"])


def test_commands_with_positionals_parse_their_flags_with_draccus(capsys):
    from lerobot_blindgrasp.analysis.diversity import DiversityConfig
    from lerobot_blindgrasp.analysis.progress import ProgressConfig
    from lerobot_blindgrasp.cli import parse_config_and_positionals

    argv = ["out.png", "a=runs/a", "--until=500", "runs/b", "--metrics=Metrics/x,Metrics/y"]
    cfg, args = parse_config_and_positionals(ProgressConfig, argv)
    assert args == ["out.png", "a=runs/a", "runs/b"]
    assert cfg.until == 500 and cfg.metric_tags == ["Metrics/x", "Metrics/y"]
    # draccus's own `--flag value` spelling: the value is no positional
    cfg, args = parse_config_and_positionals(ProgressConfig, ["--until", "7", "out.png", "runs/a"])
    assert cfg.until == 7 and args == ["out.png", "runs/a"] and cfg.metric_tags == []
    cfg, args = parse_config_and_positionals(DiversityConfig, ["x=demos/x", "--at_s=0.5", "demos/y"])
    assert cfg.at_s == 0.5 and args == ["x=demos/x", "demos/y"]
    assert parse_config_and_positionals(DiversityConfig, ["demos/y"])[0].at_s == 3.0
    assert capsys.readouterr().err == ""  # the documented spellings are no deprecated ones
    with pytest.raises(SystemExit):
        parse_config_and_positionals(ProgressConfig, ["out.png", "runs/a", "--unknown=1"])
