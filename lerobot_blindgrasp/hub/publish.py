"""`blindgrasp-publish`: push the shipped teachers, the shipped student and a demo dataset to the Hugging Face Hub,
each with its card and the code's location, in one command. Everything is checked before the first network call:
`[project.urls]` names the real public home, each model loads, each card renders into the staging folder, and the
dataset is prepared. Without `--demos`, a small curated set is collected there with the shipped student's demo
settings (`DEMO_RECIPE`); a rerun with the same `--staging_dir` resumes it.
"""

from __future__ import annotations

import shutil
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

from lerobot_blindgrasp import durable, project, shipped
from lerobot_blindgrasp.cards import model_cards
from lerobot_blindgrasp.cli import parse_config
from lerobot_blindgrasp.hub import push
from lerobot_blindgrasp.project import REPO_ID_PATTERN

# Files of a shipped model folder that belong on the Hub (the student's are all of LeRobot's pretrained_model).
_TEACHER_FILES = ("teacher.safetensors", "teacher_config.json", "README.md", "eval/*")
# The preset of the shipped student: a collected demo set uses its teacher and its demos' calibration offset.
DEMO_RECIPE = "quick_blind_targeted"
_ENVS_PER_OBJECT = 10  # parallel rollouts per object while collecting (the pipeline's 180 for 18 objects)


def stage_model(name: str, repo_id: str, staging: Path) -> Path:
    """Copy the Hub files of shipped model `name` to `staging/name` with its rendered card; returns that folder."""
    src = shipped.path(name)
    if name.startswith("teacher"):  # the model loads, before anything is staged
        from lerobot_blindgrasp.teacher.policy import TeacherPolicy

        TeacherPolicy(src)
        patterns = _TEACHER_FILES
    else:
        from lerobot.configs.policies import PreTrainedConfig

        PreTrainedConfig.from_pretrained(src)
        patterns = ("*",)
    out = staging / name
    if out.exists():
        shutil.rmtree(out)
    for pattern in patterns:
        for f in src.glob(pattern):
            if f.is_file() and f.name != "README.md":
                (out / f.relative_to(src)).parent.mkdir(parents=True, exist_ok=True)
                shutil.copyfile(f, out / f.relative_to(src))
    durable.atomic_write_text(out / "README.md", model_cards.render_model_card(src, repo_id))
    return out


@dataclass
class PublishConfig:
    """Push the shipped teachers, the shipped student and a demo dataset to the Hub, each with its card."""

    namespace: str | None = None  # Hub user or organization the repos go under (names: hub/project.py HUB_REPOS)
    # the demo dataset folder to push (blindgrasp-collect-demos output); default: collect one into the staging folder
    demos: Path | None = None
    demo_episodes: int = 2  # without --demos: curated episodes per object to collect
    demo_objects: str = "all"  # without --demos: 'all', 'medium' or a comma list of objects
    private: bool = False  # create the repos as private
    dry_run: bool = False  # check and stage everything, then stop before the network
    staging_dir: Path | None = None  # where the cards (and collected demos) go (default: a temporary folder)

    def __post_init__(self):
        if not self.namespace:
            raise ValueError("--namespace is required (your Hub user or organization)")
        for _, name in project.HUB_REPOS.values():
            if not REPO_ID_PATTERN.match(f"{self.namespace}/{name}"):
                raise ValueError(f"--namespace={self.namespace!r} does not make a Hub repo id")
        if self.demo_episodes < 1:
            raise ValueError(f"--demo_episodes must be >= 1, got {self.demo_episodes}")
        from lerobot_blindgrasp.sim import objects

        self.n_demo_objects = len(objects.resolve_objects(self.demo_objects))  # a bad name fails here, not later
        self.demos = Path(self.demos).expanduser() if self.demos is not None else None


def collect_published_demos(cfg: PublishConfig, out: Path, repo_id: str) -> Path:
    """A small curated demo set in `out`, made as the shipped student's demos were (`DEMO_RECIPE`); resumed when a
    previous publish left it unfinished."""
    from lerobot_blindgrasp import presets
    from lerobot_blindgrasp.demos import collection_loop, provenance
    from lerobot_blindgrasp.demos.config import CollectConfig

    recipe = presets.PRESETS[DEMO_RECIPE]
    n_objects = cfg.n_demo_objects
    collect = CollectConfig(
        teacher=shipped.path(recipe.teacher.shipped_folder), output_dir=out, repo_id=repo_id,
        episodes_per_object=cfg.demo_episodes, objects=cfg.demo_objects,
        joint_calibration_rad=recipe.demos.joint_calibration_rad,
        num_envs=min(recipe.demos.num_envs, _ENVS_PER_OBJECT * n_objects), resume=provenance.is_collection(out),
    )  # fmt: skip
    print(f"demos: {'resuming' if collect.resume else 'collecting'} {cfg.demo_episodes} curated episodes per object ({n_objects} objects) from "
          f"{collect.teacher.name} into {out}", flush=True)  # fmt: skip
    collection_loop.collect_demos(collect, command=f"blindgrasp-publish (preset {DEMO_RECIPE}'s demo settings)")
    return out


def repo_ids(namespace: str) -> dict[str, tuple[str, str]]:
    """name -> (repo type, repo id) for every artifact `blindgrasp-publish` pushes."""
    return {name: (kind, f"{namespace}/{repo}") for name, (kind, repo) in project.HUB_REPOS.items()}


def publish(cfg: PublishConfig) -> dict[str, str]:
    """Check, stage, then (unless a dry run) upload. Returns name -> Hub URL (empty for a dry run). A dry run may
    preview cards that still name the placeholder URL; an upload may not."""
    try:
        project.require_public_urls()
    except project.PlaceholderURLError as e:
        if not cfg.dry_run:
            raise
        print(f"warning: {e}; a dry run stages the cards anyway, an upload refuses", file=sys.stderr)
    ids = repo_ids(cfg.namespace)
    staging = Path(cfg.staging_dir or tempfile.mkdtemp(prefix="blindgrasp_publish_"))
    staged = {name: stage_model(name, rid, staging) for name, (kind, rid) in ids.items() if kind == "model"}
    demos = cfg.demos or collect_published_demos(cfg, staging / "demos", ids["demos"][1])
    ds, ds_kwargs, plan = push.prepare(demos, ids["demos"][1])
    for name, folder in staged.items():
        print(f"{name}: {folder} -> https://huggingface.co/{ids[name][1]}")
    print(f"demos: {demos} ({ds.meta.total_episodes} episodes, {len(plan['files'])} files) -> "
          f"https://huggingface.co/datasets/{ids['demos'][1]}")  # fmt: skip
    if cfg.dry_run:
        print("dry run: nothing uploaded")
        return {}
    from huggingface_hub import HfApi

    api, urls = HfApi(), {}
    for name, folder in staged.items():
        rid = ids[name][1]
        api.create_repo(rid, repo_type="model", private=cfg.private or None, exist_ok=True)
        api.upload_folder(repo_id=rid, folder_path=str(folder), repo_type="model",
                          commit_message=f"Upload {name} (lerobot_blindgrasp)")  # fmt: skip
        urls[name] = f"https://huggingface.co/{rid}"
    push.push(ds, ds_kwargs, private=cfg.private or None)
    urls["demos"] = f"https://huggingface.co/datasets/{ids['demos'][1]}"
    return urls


def main(argv=None) -> None:
    from lerobot_blindgrasp.demos.config import CollectError

    cfg = parse_config(PublishConfig, argv)
    try:
        urls = publish(cfg)
    except (project.PlaceholderURLError, push.PushError, shipped.ShippedError, CollectError) as e:
        print(f"error: {e}", file=sys.stderr)
        raise SystemExit(2) from None
    except push._network_errors() as e:
        print(f"error: upload to the Hub failed ({type(e).__name__}: {e}); check the network and `hf auth login`, "
              "then run the same command again (unchanged files are not sent again)", file=sys.stderr)  # fmt: skip
        raise SystemExit(1) from None
    for name, url in urls.items():
        print(f"pushed {name}: {url}")


if __name__ == "__main__":
    main()
