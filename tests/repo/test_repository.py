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

ROOT = Path(__file__).resolve().parents[2]
# The whole tracked tree, so that every clone stays quick: the shipped models and the twin's per-trial logs are most
# of it (the research record lives at a git tag, docs/research.md).
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


def test_shipped_teachers_are_exported_actors_that_load():
    from lerobot_blindgrasp.teacher.policy import TeacherPolicy

    folders = list((ROOT / "models").glob("teacher_*"))
    assert len(folders) >= 2
    for folder in folders:
        assert {p.suffix for p in folder.glob("*.*")} <= {".safetensors", ".json", ".md"}, folder
        teacher = TeacherPolicy(folder)
        assert teacher.checkpoint.name == "teacher.safetensors"


# The product face: a README a newcomer reads in five minutes, links that resolve, one place for the code's URL.
README = ROOT / "README.md"
MAX_README_LINES = 150
RESEARCH = ROOT / "docs" / "research.md"  # what the dated record taught; the record is at a git tag
MAX_RESEARCH_LINES = 90


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


def _markdown() -> list[Path]:
    """Every markdown file a clone carries (outside a git checkout: every one under the root but the venv's)."""
    if shutil.which("git") is not None and (ROOT / ".git").exists():
        return [p for p in _tracked() if p.suffix == ".md" and p.is_file()]
    return [p for p in ROOT.rglob("*.md") if not {".venv", "build", "outputs", "runs"} & set(p.parts)]


def test_every_relative_link_and_image_in_the_tracked_markdown_resolves():
    docs = _markdown()
    assert README in docs and RESEARCH in docs
    broken = [f"{d.relative_to(ROOT)} -> {link}" for d in docs for link in _links(d)
              if not (d.parent / link).exists()]  # fmt: skip
    assert not broken, broken


def test_the_research_records_tags_are_made_by_its_one_command(tmp_path):
    """The copy-paste block of docs/research.md, run in a copy of this history without tags, makes every tag of its
    table on the commit the table names, and the old paths the pages restore from are there."""
    if shutil.which("git") is None or not (ROOT / ".git").exists():
        pytest.skip("not a git checkout")
    git = ["git", "-C", str(tmp_path / "clone.git")]
    subprocess.run(["git", "clone", "-q", "--bare", "--shared", "--no-tags", str(ROOT), str(tmp_path / "clone.git")],
                   check=True, capture_output=True)  # fmt: skip
    text = RESEARCH.read_text(encoding="utf-8")
    table = dict(re.findall(r"^\| `([\w.-]+)` \| `([0-9a-f]{7,40})` \|", text, flags=re.M))
    if any(subprocess.run([*git, "cat-file", "-e", f"{c}^{{commit}}"]).returncode for c in table.values()):
        pytest.skip("this clone's history lacks the tagged commits (shallow)")
    block = re.search(r"```bash\n(while read .*?)```", text, flags=re.S).group(1)
    for _ in range(2):  # twice: a tag that is already there is skipped, not an error
        subprocess.run(["bash", "-e", "-c", block], cwd=tmp_path / "clone.git", check=True)
    made = {t: subprocess.run([*git, "rev-parse", f"{t}^{{commit}}"], capture_output=True, text=True).stdout.strip()
            for t in table}  # fmt: skip
    assert len(table) == 9 and all(made[t].startswith(c) for t, c in table.items()), (table, made)
    for tag, path in re.findall(r"--source=([\w.-]+) (docs/re\w+/[\w/.-]+|docs/research)\b", text):
        assert subprocess.run([*git, "cat-file", "-e", f"{tag}:{path}"]).returncode == 0, (tag, path)
    # Every page the record's summary names is at the record's tag, where it says.
    for page in set(re.findall(r"`([a-z_]+\.md)`", text)) - {"cpu_portability.md"}:
        path = f"research-record-2026-12-05:docs/research/{page}"
        assert subprocess.run([*git, "cat-file", "-e", path]).returncode == 0, path
    named = set(re.findall(r"git tag `([\w.-]+)`", " ".join(p.read_text(encoding="utf-8") for p in _markdown())))
    assert named <= set(table), f"tags named in the docs but missing from the index: {named - set(table)}"


def test_the_research_record_is_a_short_page_of_history_and_current_results_are_apart():
    """The dated record left the tree for its git tag; what stays is one short page of what it taught."""
    text = RESEARCH.read_text(encoding="utf-8")
    assert "history" in text.splitlines()[0].lower() and "results.md" in _links(RESEARCH)
    assert len(text.splitlines()) <= MAX_RESEARCH_LINES, f"docs/research.md has {len(text.splitlines())} lines"
    if shutil.which("git") is not None and (ROOT / ".git").exists():  # restored from the tag, it stays untracked
        assert not [p for p in _tracked() if p.relative_to(ROOT).parts[:2] == ("docs", "research")]
    assert not list((ROOT / "docs" / "results").glob("teacher_cpu*.md"))  # the dated pages left docs/results/
    assert (ROOT / "docs" / "results.md").is_file()


def test_citation_and_changelog_name_the_paper_release_and_code():
    import yaml

    from lerobot_blindgrasp import __version__
    from lerobot_blindgrasp.cards import dataset_cards as cards

    cff = yaml.safe_load((ROOT / "CITATION.cff").read_text(encoding="utf-8"))
    assert cff["cff-version"] == "1.2.0" and cff["version"] == __version__ and cff["authors"]
    assert cff["repository-code"] == _project_urls()["Source"]
    paper = cff["preferred-citation"]
    assert paper["title"] in " ".join(cards.PAPER.split())
    assert [a["family-names"] for a in paper["authors"]] == ["Lee", "Choi", "Kim", "Nam", "Jeong"]
    changelog = (ROOT / "CHANGELOG.md").read_text(encoding="utf-8")
    released = re.search(rf"^## \[{re.escape(__version__)}\] - (\d{{4}}-\d{{2}}-\d{{2}})$", changelog, flags=re.M)
    assert released and str(cff["date-released"]) == released.group(1)  # dated, and the same date in both
    # Its version links are the code's own address from [project.urls], as the README's is.
    source = _project_urls()["Source"].rstrip("/")
    refs = dict(re.findall(r"^\[([^\]]+)\]: (\S+)$", changelog, flags=re.M))
    assert {"Unreleased", __version__} <= set(refs), refs
    assert refs[__version__] == f"{source}/releases/tag/v{__version__}"
    assert refs["Unreleased"] == f"{source}/compare/v{__version__}...HEAD"
    assert _project_urls()["Changelog"].startswith(source) and _project_urls()["Changelog"].endswith(
        "/CHANGELOG.md"
    )
