"""`blindgrasp-publish` up to the network call: the placeholder project URL refuses the push, and with a real one
every shipped model and the demo dataset are staged with their cards (one install section, the install line from
[project.urls] Source, links that leave the model's folder made absolute), then the uploads go where
`project.HUB_REPOS` says, as the dataset push is tested (tests/demos/test_demos_collect.py). Without `--demos` the command
collects the demo set itself."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from lerobot_blindgrasp import presets, project, shipped
from lerobot_blindgrasp.cards import dataset_cards as cards
from lerobot_blindgrasp.cards import links, model_cards
from lerobot_blindgrasp.demos import provenance
from lerobot_blindgrasp.hub import publish

REAL = "https://code.example.org/lab/lerobot_blindgrasp"  # stands in for a public home in the tests only
MODELS = [name for name, (kind, _) in project.HUB_REPOS.items() if kind == "model"]


@pytest.fixture(scope="module")
def demos(tmp_path_factory) -> Path:
    """The demo set one dry run of `blindgrasp-publish` collects when given none: one curated episode of each of two
    objects, with the shipped student's teacher and demo settings (seconds)."""
    stage = tmp_path_factory.mktemp("publish") / "stage"
    publish.main(["--namespace=you", "--dry_run=true", "--demo_episodes=1",
                  "--demo_objects=sphere_medium,capsule_medium", f"--staging_dir={stage}"])  # fmt: skip
    out = stage / "demos"
    prov = provenance.load_provenance(out)
    assert prov["objects"] == ["sphere_medium", "capsule_medium"] and prov["curation"]["enabled"]
    recipe = presets.PRESETS[publish.DEMO_RECIPE]
    assert prov["randomization"]["joint_calibration_rad"] == recipe.demos.joint_calibration_rad > 0
    assert Path(prov["teacher"]["checkpoint"]).parent == shipped.path(recipe.teacher.shipped_folder)
    return out


def test_the_placeholder_url_refuses_the_push(demos, tmp_path, capsys):
    assert project.is_placeholder(project.source_url())  # the repository's own [project.urls] today
    with pytest.raises(SystemExit) as exc:
        publish.main(["--namespace=you", f"--demos={demos}", f"--staging_dir={tmp_path / 'stage'}"])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "[project.urls]" in err and "placeholder" in err
    assert not (tmp_path / "stage").exists()  # refused before anything was staged

    # A dry run previews the cards, placeholder and all, and says that an upload would refuse.
    publish.main(["--namespace=you", f"--demos={demos}", f"--staging_dir={tmp_path / 'stage'}", "--dry_run=true"])
    captured = capsys.readouterr()
    assert "an upload refuses" in captured.err and "dry run: nothing uploaded" in captured.out
    for name in MODELS:
        staged = (tmp_path / "stage" / name / "README.md").read_text()
        assert project.PLACEHOLDER_HOST not in staged and "not set yet" in staged  # no card names a fake location
        assert "python -m build" in staged  # the install line names the one install that works: a built wheel
        _links_resolve_on_the_hub(staged, tmp_path / "stage" / name, absolute_base=None)


def test_publish_stages_every_card_then_stops_at_the_network(demos, tmp_path, monkeypatch, capsys):
    import huggingface_hub.constants

    monkeypatch.setattr(project, "urls", lambda: {"Homepage": REAL, "Source": REAL})
    stage = tmp_path / "stage"
    publish.main(["--namespace=you", f"--demos={demos}", f"--staging_dir={stage}", "--dry_run=true"])
    out = capsys.readouterr().out
    assert "dry run" in out
    ids = publish.repo_ids("you")
    assert {kind for kind, _ in ids.values()} == {"model", "dataset"}
    for name, (kind, repo_id) in ids.items():
        assert f"https://huggingface.co/{'datasets/' if kind == 'dataset' else ''}{repo_id}" in out
        card = (demos / cards.CARD_NAME if kind == "dataset" else stage / name / "README.md").read_text()
        assert REAL in card and "lerobot_policy_blindgrasp" in card, name
    for name in MODELS:
        card = (stage / name / "README.md").read_text()
        _one_install_section(card, name)
        assert f'pip install "lerobot_policy_blindgrasp @ git+{REAL}"' in card, name
        _links_resolve_on_the_hub(card, stage / name, absolute_base=f"{REAL}/blob/main/")
    student = (stage / "student_cpu" / "README.md").read_text()
    assert student.count(f"lerobot-eval --policy.path={ids['student_cpu'][1]} ") == 1
    assert "--policy.path=models/student_cpu" not in student
    shipped_files = {p.relative_to(shipped.path("student_cpu")) for p in shipped.path("student_cpu").rglob("*")}
    assert {p.relative_to(stage / "student_cpu") for p in (stage / "student_cpu").rglob("*")} == shipped_files
    assert {p.name for p in (stage / "teacher_cpu_bc").iterdir()} == {
        "teacher.safetensors", "teacher_config.json", "README.md", "eval"}  # fmt: skip

    # Not a dry run: offline, the first network call (creating the first model repo) fails with a clear message.
    monkeypatch.setattr(huggingface_hub.constants, "HF_HUB_OFFLINE", True)
    with pytest.raises(SystemExit) as exc:
        publish.main(["--namespace=you", f"--demos={demos}", f"--staging_dir={stage}"])
    assert exc.value.code == 1 and "upload to the Hub failed" in capsys.readouterr().err


def test_publish_uploads_each_staged_folder_to_its_repo(demos, tmp_path, monkeypatch):
    from huggingface_hub import HfApi
    from huggingface_hub.hf_api import RepoUrl

    monkeypatch.setattr(project, "urls", lambda: {"Homepage": REAL, "Source": REAL})
    sent = {}
    monkeypatch.setattr(
        HfApi, "create_repo", lambda self, repo_id, **kw: RepoUrl(f"https://huggingface.co/{repo_id}")
    )
    monkeypatch.setattr(HfApi, "upload_folder", lambda self, *, repo_id, folder_path, **kw: sent.update(
        {repo_id: sorted(p.name for p in Path(folder_path).iterdir())}))  # fmt: skip
    monkeypatch.setattr(publish.push, "push", lambda ds, kwargs, private=None: sent.update(
        {ds.repo_id: kwargs["dataset_description"]}))  # fmt: skip
    urls = publish.publish(publish.PublishConfig(namespace="lab", demos=demos, staging_dir=tmp_path / "s"))
    ids = publish.repo_ids("lab")
    assert set(sent) == {rid for _, rid in ids.values()} and set(urls) == set(ids)
    assert "model.safetensors" in sent[ids["student_cpu"][1]]
    assert "README.md" in sent[ids["teacher_cpu_bc_calib"][1]]
    assert REAL in sent[ids["demos"][1]]  # the dataset card's body names the code's location


def test_each_source_card_holds_its_one_generated_install_section():
    """The section `blindgrasp-publish` rewrites is, in the source card, exactly what `install_section` makes
    locally: the card and the renderer cannot drift apart, and no second install block sits beside it."""
    for name in MODELS:
        text = (shipped.path(name) / "README.md").read_text(encoding="utf-8")
        start, end = model_cards.section_of(text, name)
        assert text[start:end] == model_cards.install_section(name, shipped.path(name)), (
            f"models/{name}/README.md: replace its install section with model_cards.install_section({name!r})"
        )
        _one_install_section(text, name)


def _one_install_section(card: str, name: str) -> None:
    assert card.count(model_cards.HEADING) == 1, name
    assert len(re.findall(r"^pip install ", card, flags=re.M)) == 1, name
    assert "\nUse it:" not in card and "Run it in simulation" not in card, name  # the old second blocks


def _links_resolve_on_the_hub(card: str, folder: Path, absolute_base: str | None) -> None:
    """Every link of a staged card: relative ones resolve inside the uploaded folder; absolute ones into the code's
    own tree are built from [project.urls] and name a file the repository has."""
    root = Path(__file__).resolve().parents[2]
    for _, _, target in links.LINK.findall(card):
        if links.is_relative(target):
            assert (folder / target.split("#")[0]).exists(), (folder.name, target)
        elif absolute_base and target.startswith(absolute_base):
            assert (root / target.removeprefix(absolute_base).split("#")[0]).exists(), target
        else:
            assert project.PLACEHOLDER_HOST not in target, target
    if absolute_base:
        assert absolute_base in card
