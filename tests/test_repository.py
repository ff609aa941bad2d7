"""What every clone carries: a small tree, shipped and recorded models as safetensors, no training state.

Training checkpoints (optimizer state, pickled) and TensorBoard event files belong to a run, not to the product:
runs keep them locally or on a git tag, and what a doc or a user loads is an exported actor
(`blindgrasp-export-teacher`).
Skipped outside a git checkout (an sdist or wheel has no tracked-file list).
"""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
# The whole tracked tree, so that every clone stays quick; today's is ~12 MB, most of it the shipped student.
MAX_TREE_BYTES = 15_000_000
TRAINING_STATE = (".pt", ".pth", ".ckpt")


def _tracked() -> list[Path]:
    if shutil.which("git") is None or not (ROOT / ".git").exists():
        pytest.skip("not a git checkout")
    out = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True).stdout
    return [ROOT / p for p in out.decode().split("\0") if p]


def test_the_tracked_tree_stays_small():
    files = [p for p in _tracked() if p.is_file()]  # a tracked file deleted in the working tree is not a clone's
    sizes = sorted(((p.stat().st_size, p.relative_to(ROOT)) for p in files), reverse=True)
    total = sum(s for s, _ in sizes)
    assert total < MAX_TREE_BYTES, f"tracked tree {total / 1e6:.1f} MB; largest: {sizes[:5]}"


def test_no_training_state_or_event_files_are_tracked():
    bad = [p.relative_to(ROOT) for p in _tracked()
           if p.suffix in TRAINING_STATE or p.name.startswith("events.out.tfevents")]
    assert not bad, f"export these (blindgrasp-export-teacher) or keep them out of the tree: {bad}"


def test_shipped_and_recorded_teachers_are_exported_actors_that_load():
    from lerobot_blindgrasp.teacher.policy import TeacherPolicy

    folders = [*(ROOT / "models").glob("teacher_*"), *(ROOT / "docs" / "research" / "checkpoints").glob("*_*")]
    assert len(folders) >= 2
    for folder in folders:
        assert {p.suffix for p in folder.glob("*.*")} <= {".safetensors", ".json", ".md"}, folder
        teacher = TeacherPolicy(folder)
        assert teacher.checkpoint.name == "teacher.safetensors"
        if folder.parent.name == "checkpoints":  # <run>_<iteration>: the folder says which checkpoint it is
            assert folder.name.endswith(f"_{teacher.iteration}"), folder
