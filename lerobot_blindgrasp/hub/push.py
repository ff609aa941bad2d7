"""`blindgrasp-push-dataset`: upload a blindgrasp dataset folder (sim teacher demos, or a glove recording made with
`--dataset.push_to_hub=false`) to the Hugging Face Hub with its card. The dataset is loaded and its card written to
README.md first, so a broken folder fails before any upload; LeRobot's `push_to_hub` then uploads the folder.
"""

from __future__ import annotations

import json
import sys
from dataclasses import dataclass, field
from pathlib import Path

from lerobot_blindgrasp.cards import dataset_cards as cards
from lerobot_blindgrasp.cli import parse_config
from lerobot_blindgrasp.demos import provenance, records
from lerobot_blindgrasp.project import REPO_ID_PATTERN


class PushError(Exception):
    pass


def upload_plan(root: Path) -> dict:
    """What the upload will send (LeRobot's push_to_hub ignores images/): file count and size."""
    files = sorted(p.relative_to(root) for p in root.rglob("*") if p.is_file())
    files = [p for p in files if p.parts[0] != "images"]
    return {"files": [str(p) for p in files], "bytes": sum((root / p).stat().st_size for p in files)}


def prepare(
    root: Path,
    repo_id: str,
    kind: str | None = None,
    license: str = cards.DEFAULT_LICENSE,
    tags: list[str] | None = None,
    operators: list[str] | None = None,
    notes: str = "",
):
    """Load the dataset, write README.md; returns (dataset, push_to_hub kwargs, plan). No network."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    root = Path(root)
    if not REPO_ID_PATTERN.match(repo_id):
        raise PushError(f"--repo_id must look like USER/NAME, got {repo_id!r}")
    if not (root / "meta" / "info.json").is_file():
        raise PushError(f"{root} is not a LeRobot dataset folder (no meta/info.json)")
    if json.loads((root / "meta" / "info.json").read_text()).get("total_episodes", 0) == 0:
        raise PushError(f"{root} has no episodes yet; nothing to upload")
    try:
        kwargs = push_card_kwargs(root, repo_id, kind, license, tags, operators, notes)
    except (FileNotFoundError, ValueError) as e:
        raise PushError(str(e)) from None
    cards.write_card(root, repo_id, kwargs)
    ds = LeRobotDataset(repo_id, root=root, video_backend="pyav")  # reads local files only
    push_kwargs = {k: v for k, v in kwargs.items() if not k.startswith("_")}
    return ds, push_kwargs, upload_plan(root)


def detect_kind(root: Path) -> str:
    """'sim' for folders written by blindgrasp-collect-demos, else 'glove' (a lerobot-record dataset)."""
    return "sim" if provenance.is_collection(root) else "glove"


def push_card_kwargs(
    root: Path, repo_id: str, kind=None, license=cards.DEFAULT_LICENSE, tags=None, operators=None, notes=""
):
    """The card's arguments for either kind of dataset (detected when not given)."""
    if (kind or detect_kind(root)) == "sim":
        return records.sim_card_kwargs(root, repo_id, license=license, extra_tags=tags)
    return cards.glove_card_kwargs(root, repo_id, operators, notes, license=license, extra_tags=tags)


def push(ds, push_kwargs: dict, private: bool | None = None, branch: str | None = None) -> None:
    """The network part: LeRobot's own upload, with our card arguments."""
    ds.push_to_hub(branch=branch, private=private, **push_kwargs)


def _network_errors() -> tuple[type[BaseException], ...]:
    import httpx

    # huggingface_hub raises OfflineModeIsEnabled (a ConnectionError) under HF_HUB_OFFLINE=1, HfHubHTTPError
    # (an OSError) for HTTP failures and missing tokens, and httpx transport errors for unreachable endpoints.
    return (OSError, httpx.TransportError)


@dataclass
class PushDatasetConfig:
    """Upload a blindgrasp dataset folder (sim teacher demos or glove teleoperation) to the Hub with its card."""

    root: Path | None = None  # dataset folder (LeRobotDataset root)
    repo_id: str | None = None  # USER/NAME on the Hub
    kind: str | None = None  # card kind: sim or glove (default: detect; sim when collection.json is there)
    license: str = cards.DEFAULT_LICENSE  # Hub license identifier
    tags: list[str] = field(default_factory=list)  # extra card tags
    operators: list[str] = field(default_factory=list)  # glove operators, for the glove card
    notes: str = ""  # free text for the glove card's protocol section
    private: bool = False  # create the Hub repo as private
    branch: str | None = None  # Hub branch to push to (default: main)
    dry_run: bool = False  # prepare the card and stop before the network

    def __post_init__(self):
        if self.root is None:
            raise ValueError("--root is required (the dataset folder)")
        if self.repo_id is None:
            raise ValueError("--repo_id is required (USER/NAME on the Hub)")
        if self.kind is not None and self.kind not in cards.TEMPLATES:
            raise ValueError(f"--kind must be one of {sorted(cards.TEMPLATES)}, got {self.kind!r}")
        self.root = Path(self.root).expanduser()


def push_dataset(cfg: PushDatasetConfig) -> str | None:
    """Prepare (card, checks) and upload. Returns the dataset URL, or None for a dry run. Raises PushError for a
    folder that cannot be pushed, and the network errors of `_network_errors()` for a failed upload."""
    ds, kwargs, plan = prepare(cfg.root, cfg.repo_id, cfg.kind, cfg.license, cfg.tags, cfg.operators, cfg.notes)
    print(
        f"{cfg.root}: {ds.meta.total_episodes} episodes, {ds.meta.total_frames} frames; card written to "
        f"{cfg.root / cards.CARD_NAME}; {len(plan['files'])} files ({plan['bytes'] / 1e6:.1f} MB) to upload "
        f"to https://huggingface.co/datasets/{cfg.repo_id}"
    )
    if cfg.dry_run:
        print("dry run: nothing uploaded")
        return None
    push(ds, kwargs, private=cfg.private or None, branch=cfg.branch)
    return f"https://huggingface.co/datasets/{cfg.repo_id}"


def main(argv=None) -> None:
    cfg = parse_config(PushDatasetConfig, argv)
    try:
        url = push_dataset(cfg)
    except PushError as e:
        print(f"error: {e}", file=sys.stderr)
        raise SystemExit(2) from None
    except _network_errors() as e:
        print(
            f"error: upload to the Hub failed ({type(e).__name__}: {e}).\n"
            f"Nothing in {cfg.root} was changed except README.md; check the network and `hf auth login`, then "
            "run the same command again.",
            file=sys.stderr,
        )
        raise SystemExit(1) from None
    if url:
        print(f"pushed: {url}")


if __name__ == "__main__":
    main()
