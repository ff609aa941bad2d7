"""`blindgrasp-publish`: push the shipped teachers, the shipped student and a demo dataset to the Hugging Face Hub,
each with its card and the code's location.

    blindgrasp-collect-demos --teacher="$(blindgrasp-path --name=teacher_cpu_bc_calib)" --episodes_per_object=2 \\
      --output_dir=runs/demos_publish --repo_id=you/blindgrasp-demos-sim
    blindgrasp-publish --namespace=you --demos=runs/demos_publish --dry_run=true   # everything but the upload
    blindgrasp-publish --namespace=you --demos=runs/demos_publish

The repo names are `project.HUB_REPOS`, under `--namespace`. Everything is checked before the first network call:
`[project.urls]` must name the project's real public home (a card must not send a reader to a placeholder), each
model loads (the teachers through `TeacherPolicy`, the student's `config.json` as LeRobot's policy config), each
model card is rendered into a staging folder with the install line and the code's location, and the dataset is
prepared by `blindgrasp-push-dataset`'s own `prepare` (its card carries the code's location too). Then the models
go up with `HfApi.upload_folder` and the dataset with LeRobot's `push_to_hub`.
"""

from __future__ import annotations

import shutil
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

from lerobot_blindgrasp import durable, shipped
from lerobot_blindgrasp.cli import parse_config
from lerobot_blindgrasp.hub import REPO_ID_PATTERN, project, push

# Files of a shipped model folder that belong on the Hub (the student's are all of LeRobot's pretrained_model).
_TEACHER_FILES = ("teacher.safetensors", "teacher_config.json", "README.md", "eval/*")


def _install_block(name: str, repo_id: str) -> str:
    if name.startswith("teacher"):
        use = (f"hf download {repo_id} --local-dir {name}\n"
               f"blindgrasp-eval-teacher --teacher={name} --episodes=20")  # fmt: skip
    else:
        use = (f"lerobot-eval --policy.path={repo_id} --env.type=blindgrasp --env.task=all \\\n"
               "  --eval.n_episodes=20"
               " --eval.batch_size=20 --eval.use_async_envs=false --policy.device=cpu --seed=1000")  # fmt: skip
    return (
        f"\n## Install and use\n\n```bash\n{project.INSTALL}   # LeRobot plugin: the policy, env, robot and "
        f"glove types\n{use}\n```\n\nThis model also ships inside the package: "
        f"`blindgrasp-path --name={name}` prints its installed folder.\n\n{project.code_line()}\n"
    )


def render_model_card(folder: Path, repo_id: str) -> str:
    """The folder's README.md with the install block after its title and its local path replaced by the repo id."""
    name = folder.name
    text = (folder / "README.md").read_text(encoding="utf-8").replace(f"--policy.path=models/{name}",
                                                                       f"--policy.path={repo_id}")  # fmt: skip
    lines = text.split("\n")
    at = next((i + 1 for i, line in enumerate(lines) if line.startswith("# ")), None)
    if at is None:
        raise ValueError(f"{folder / 'README.md'} has no '# ' title line to put the install block under")
    lines[at:at] = _install_block(name, repo_id).split("\n")
    return "\n".join(lines)


def _check_loads(folder: Path) -> None:
    if folder.name.startswith("teacher"):
        from lerobot_blindgrasp.teacher.policy import TeacherPolicy

        TeacherPolicy(folder)
    else:
        from lerobot.configs.policies import PreTrainedConfig

        PreTrainedConfig.from_pretrained(folder)


def stage_model(name: str, repo_id: str, staging: Path) -> Path:
    """Copy the Hub files of shipped model `name` to `staging/name` with its rendered card; returns that folder."""
    src = shipped.path(name)
    _check_loads(src)
    out = staging / name
    if out.exists():
        shutil.rmtree(out)
    patterns = _TEACHER_FILES if name.startswith("teacher") else ("*",)
    for pattern in patterns:
        for f in src.glob(pattern):
            if f.is_file() and f.name != "README.md":
                (out / f.relative_to(src)).parent.mkdir(parents=True, exist_ok=True)
                shutil.copyfile(f, out / f.relative_to(src))
    durable.atomic_write_text(out / "README.md", render_model_card(src, repo_id))
    return out


@dataclass
class PublishConfig:
    """Push the shipped teachers, the shipped student and a demo dataset to the Hub, each with its card.

    blindgrasp-publish --namespace=you --demos=runs/demos_publish [--dry_run=true]
    """

    namespace: str | None = None  # Hub user or organization the repos go under (names: hub/project.py HUB_REPOS)
    demos: Path | None = None  # the demo dataset folder to push (blindgrasp-collect-demos output)
    private: bool = False  # create the repos as private
    dry_run: bool = False  # check and stage everything, then stop before the network
    staging_dir: Path | None = None  # where the model cards are rendered (default: a temporary folder)

    def __post_init__(self):
        if not self.namespace:
            raise ValueError("--namespace is required (your Hub user or organization)")
        if self.demos is None:
            raise ValueError("--demos is required (a blindgrasp-collect-demos folder; see --help for the command)")
        for _, name in project.HUB_REPOS.values():
            if not REPO_ID_PATTERN.match(f"{self.namespace}/{name}"):
                raise ValueError(f"--namespace={self.namespace!r} does not make a Hub repo id")
        self.demos = Path(self.demos).expanduser()


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
    ds, ds_kwargs, plan = push.prepare(cfg.demos, ids["demos"][1])
    for name, folder in staged.items():
        print(f"{name}: {folder} -> https://huggingface.co/{ids[name][1]}")
    print(f"demos: {cfg.demos} ({ds.meta.total_episodes} episodes, {len(plan['files'])} files) -> "
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
    cfg = parse_config(PublishConfig, argv)
    try:
        urls = publish(cfg)
    except (project.PlaceholderURLError, push.PushError, shipped.ShippedError) as e:
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
