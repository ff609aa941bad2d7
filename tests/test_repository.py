"""What every clone carries: a small tree, shipped and recorded models as safetensors, no training state.

Training checkpoints (optimizer state, pickled) and TensorBoard event files belong to a run, not to the product:
runs keep them locally or on a git tag, and what a doc or a user loads is an exported actor
(`blindgrasp-export-teacher`).
Skipped outside a git checkout (an sdist or wheel has no tracked-file list).
"""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
# The whole tracked tree, so that every clone stays quick; today's is ~15 MB: the shipped models, the research
# record's checkpoints, and the twin's per-trial logs.
MAX_TREE_BYTES = 20_000_000
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
    bad = [
        p.relative_to(ROOT)
        for p in _tracked()
        if p.suffix in TRAINING_STATE or p.name.startswith("events.out.tfevents")
    ]
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


# The product face: a README a newcomer reads in five minutes, links that resolve, one place for the code's URL.
README = ROOT / "README.md"
MAX_README_LINES = 150


def _project_urls() -> dict[str, str]:
    import tomllib

    return tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["urls"]


def test_the_readme_is_a_short_product_page():
    text = README.read_text(encoding="utf-8")
    assert len(text.splitlines()) <= MAX_README_LINES, f"README.md has {len(text.splitlines())} lines"
    # The two commands, with the exact invocation .ci/run and the guides use.
    assert "bash scripts/main.sh" in text and "bash scripts/test.sh" in text
    assert "exec bash scripts/test.sh" in (ROOT / ".ci" / "run").read_text()
    for section in ("## Install", "## Headline numbers", "## The shipped student in one command",
                    "## The real gripper in seven commands", "## Training your own", "## Documentation",
                    "## Layout", "CITATION.cff"):  # fmt: skip
        assert section in text, section
    assert "docs/bringup.md" in text and "docs/results.md" in text
    image = re.search(r"!\[[^\]]*\]\(([^)]+\.png)\)", text)
    assert image and (ROOT / image.group(1)).is_file()
    assert _project_urls()["Source"] in text  # the README names the code's location from [project.urls]


def _links(doc: Path) -> list[str]:
    return [m.group(1).split("#")[0] for m in re.finditer(r"\]\(([^)\s]+)\)", doc.read_text(encoding="utf-8"))
            if not re.match(r"^([a-z]+:|#)", m.group(1))]  # fmt: skip


def test_every_relative_link_in_the_readme_guides_records_and_cards_resolves():
    docs = [README, ROOT / "CHANGELOG.md", *(ROOT / "docs").glob("*.md"),
            *(ROOT / "docs" / "research").glob("*.md"), *(ROOT / "models").glob("*/README.md")]  # fmt: skip
    broken = [f"{d.relative_to(ROOT)} -> {link}" for d in docs if d.is_file() for link in _links(d)
              if not (d.parent / link).exists()]  # fmt: skip
    assert not broken, broken


def test_the_research_record_is_marked_as_history_and_current_results_are_apart():
    index = (ROOT / "docs" / "research" / "index.md").read_text(encoding="utf-8")
    assert "history" in index.splitlines()[0].lower() and "../results.md" in index
    listed = set(_links(ROOT / "docs" / "research" / "index.md"))
    pages = {p.name for p in (ROOT / "docs" / "research").glob("*.md")} - {"index.md"}
    assert pages <= listed, f"research pages missing from its index: {sorted(pages - listed)}"
    assert not list((ROOT / "docs" / "results").glob("teacher_cpu*.md"))  # the dated pages left docs/results/
    assert (ROOT / "docs" / "results.md").is_file()


def test_citation_and_changelog_name_the_paper_release_and_code():
    import yaml

    from lerobot_blindgrasp import __version__
    from lerobot_blindgrasp.hub import cards

    cff = yaml.safe_load((ROOT / "CITATION.cff").read_text(encoding="utf-8"))
    assert cff["cff-version"] == "1.2.0" and cff["version"] == __version__ and cff["authors"]
    assert cff["repository-code"] == _project_urls()["Source"]
    paper = cff["preferred-citation"]
    assert paper["title"] in " ".join(cards.PAPER.split())
    assert [a["family-names"] for a in paper["authors"]] == ["Lee", "Choi", "Kim", "Nam", "Jeong"]
    assert f"## [{__version__}]" in (ROOT / "CHANGELOG.md").read_text(encoding="utf-8")
