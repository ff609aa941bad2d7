"""`blindgrasp-publish` up to the network call: the placeholder project URL refuses the push, and with a real one
every shipped model and the demo dataset are staged with their cards (install line, the code's location), then
the uploads go where `project.HUB_REPOS` says, as the dataset push is tested (tests/test_demos_collect.py)."""

from __future__ import annotations

from pathlib import Path

import pytest

from lerobot_blindgrasp import shipped, spec
from lerobot_blindgrasp.demos import collection, curation
from lerobot_blindgrasp.demos.config import CollectConfig
from lerobot_blindgrasp.hub import cards, project, publish
from lerobot_blindgrasp.teacher.policy import default_teacher

REAL = "https://code.example.org/lab/lerobot_blindgrasp"  # stands in for a public home in the tests only


@pytest.fixture(scope="module")
def demos(tmp_path_factory) -> Path:
    """Two uncurated episodes of two objects from the shipped teacher: a real demo dataset, made in seconds."""
    out = tmp_path_factory.mktemp("publish") / "demos"
    collection.collect(CollectConfig(teacher=default_teacher(), output_dir=out, repo_id="test/demos",
                               objects="sphere_medium,capsule_medium",
                               episodes_per_object=1, num_envs=2, seed=spec.DEMO_SEED + 11,
                               curation=curation.NO_CURATION, progress=False))  # fmt: skip
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
    staged = (tmp_path / "stage" / "student_cpu" / "README.md").read_text()
    assert project.PLACEHOLDER_HOST not in staged and "not set yet" in staged  # no card names a fake location


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
    student = (stage / "student_cpu" / "README.md").read_text()
    assert "pip install lerobot_policy_blindgrasp" in student
    assert f"--policy.path={ids['student_cpu'][1]}" in student
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
