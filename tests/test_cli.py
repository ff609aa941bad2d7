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
