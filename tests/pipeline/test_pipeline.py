"""The one-command pipeline, end to end with the real CLIs, at the `smoke` size (seconds per stage)."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys

import pytest

from lerobot_blindgrasp import presets, spec


@pytest.mark.slow
def test_smoke_pipeline_runs_every_stage_and_writes_the_report(tmp_path, capsys, monkeypatch):
    out = tmp_path / "p"
    cmd = [sys.executable, "-m", "lerobot_blindgrasp.pipeline.run", "--preset=smoke", f"--output_dir={out}"]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    record = json.loads((out / "pipeline.json").read_text())
    assert {"teacher", "teacher_eval", "demos", "student", "student_eval"} <= set(record["stages"])
    assert "lerobot-train" in record["stages"]["student"]["command"]
    assert "lerobot-eval" in record["stages"]["student_eval"]["command"]
    # Teacher and student ran the same start states: the same evaluation seed in both commands.
    assert f"--seed={spec.EVAL_SEED}" in record["stages"]["teacher_eval"]["command"]
    assert f"--seed={spec.EVAL_SEED}" in record["stages"]["student_eval"]["command"]
    assert "--policy.device=cpu" in record["stages"]["student"]["command"]
    # The targeted extra demos: their own collection of the one object, merged with the demos by LeRobot, and the
    # student trained on the merge; DAgger drives only that object.
    # The tiny teacher curates too few episodes, so the student trains on the uncurated set and its extras.
    base = "demos_uncurated" if "uncurated" in record["student_dataset"] else "demos"
    assert "--objects=cylinder_a_medium" in record["stages"][f"{base}_cylinder_a_medium"]["command"]
    assert f"--dataset.root={out / f'{base}_targeted'}" in record["stages"]["student"]["command"]
    assert "--objects=cylinder_a_medium" in record["stages"]["dagger_1"]["command"]
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    kept = [
        json.loads((out / d / "yield_report.json").read_text())["total"]["kept"]
        for d in (base, f"{base}_cylinder_a_medium")
    ]
    merged = LeRobotDataset("local/m", root=out / f"{base}_targeted")
    assert merged.num_episodes == sum(kept) and kept[1] >= 1
    report = (out / "report.md").read_text()
    assert "trained from scratch in this run" in report  # the smoke preset says which teacher it used
    # One row per evaluated object: rate, Wilson interval and counts for teacher and student, and the pairing.
    row = re.search(r"^\| cylinder_a_medium \|(.*)$", report, re.M)
    assert row and len(re.findall(r"\d+ % \[\d+-\d+\] \([01]/1\)", row.group(1))) == 3
    for fig in ("success_per_object.png", "teacher_curves.png", "student_loss.png", "yield_demos.png"):
        assert (out / "figures" / fig).stat().st_size > 1000
    assert "--preset=cpu" in report and "--preset=paper" in report
    assert "## Deviations from the paper" in report  # the preset's own list, from the registry
    # Re-running skips the finished stages instead of redoing them: the command's entry point in this process (every
    # stage is skipped, so nothing heavy runs here), which spares a second interpreter's imports.
    from lerobot_blindgrasp.pipeline import run

    monkeypatch.setenv("OMP_WAIT_POLICY", os.environ.get("OMP_WAIT_POLICY", "PASSIVE"))  # undone after the test
    capsys.readouterr()
    run.main(cmd[3:])
    assert capsys.readouterr().out.count("skipped") >= 5


def test_step_counts_in_lerobot_logs_parse():
    from lerobot_blindgrasp.pipeline.job_report import parse_step

    assert parse_step("300") == 300
    assert parse_step("1K") == 1000
    assert parse_step("2.5M") == 2_500_000
    with pytest.raises(ValueError):
        parse_step("abc")


def test_presets_are_consistent():
    for p in presets.PRESETS.values():
        assert p.student.size in ("quick", "cpu", "paper")
    # README command 1 starts from the shipped teacher and records results at >= 20 episodes per object.
    quick = presets.PRESETS["quick"]
    assert quick.teacher.shipped and quick.evaluation.episodes_per_object >= 20 and quick.evaluation.task == "all"
    assert not presets.PRESETS["smoke"].teacher.shipped  # CI still trains a (tiny) teacher
    assert presets.PRESETS["paper"].student.device == "cuda"
