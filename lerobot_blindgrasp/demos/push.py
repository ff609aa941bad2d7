"""`blindgrasp-push-dataset`: upload a blindgrasp dataset folder to the Hugging Face Hub with its card.

    blindgrasp-push-dataset runs/demos_cpu --repo-id me/blindgrasp_demos_cpu
    blindgrasp-push-dataset ~/glove_demos --repo-id me/blindgrasp_glove --kind glove --operator alice

Works for sim teacher demos (`blindgrasp-collect-demos` output, detected by its collection.json) and for glove
teleoperation datasets recorded with `lerobot-record` (record them with `--dataset.push_to_hub=false`, then push
them with this command to get the glove card). Everything is prepared locally first: the dataset is loaded (so a
broken folder fails here, not half-way through an upload) and its card is written to README.md. Then LeRobot's own
`LeRobotDataset.push_to_hub` uploads the folder, pushes the same card and tags the `v3.0` revision. `--dry-run`
stops before the network.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from lerobot_blindgrasp.demos import cards
from lerobot_blindgrasp.demos.collect import REPO_ID_PATTERN

# Not uploaded by LeRobot's push_to_hub (it ignores images/; state-only datasets have none anyway).
_IGNORED_DIRS = ("images",)


class PushError(Exception):
    pass


def upload_plan(root: Path) -> dict:
    """What the upload will send: file count and size, for the user and for tests."""
    files = [p for p in root.rglob("*") if p.is_file() and p.relative_to(root).parts[0] not in _IGNORED_DIRS]
    return {
        "files": sorted(str(p.relative_to(root)) for p in files),
        "bytes": sum(p.stat().st_size for p in files),
    }


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
        raise PushError(f"--repo-id must look like USER/NAME, got {repo_id!r}")
    if not (root / "meta" / "info.json").is_file():
        raise PushError(f"{root} is not a LeRobot dataset folder (no meta/info.json)")
    if json.loads((root / "meta" / "info.json").read_text()).get("total_episodes", 0) == 0:
        raise PushError(f"{root} has no episodes yet; nothing to upload")
    try:
        kwargs = cards.card_kwargs(
            root, repo_id, kind=kind, license=license, extra_tags=tags, operators=operators, notes=notes
        )
    except (FileNotFoundError, ValueError) as e:
        raise PushError(str(e)) from None
    card = cards.build_card(kwargs, repo_id)
    cards.validate(str(card))
    card.save(root / cards.CARD_NAME)
    ds = LeRobotDataset(repo_id, root=root, video_backend="pyav")  # reads local files only
    push_kwargs = {k: v for k, v in kwargs.items() if not k.startswith("_")}
    return ds, push_kwargs, upload_plan(root)


def push(ds, push_kwargs: dict, private: bool | None = None, branch: str | None = None) -> None:
    """The network part: LeRobot's own upload, with our card arguments."""
    ds.push_to_hub(branch=branch, private=private, **push_kwargs)


def _network_errors() -> tuple[type[BaseException], ...]:
    import httpx

    # huggingface_hub raises OfflineModeIsEnabled (a ConnectionError) under HF_HUB_OFFLINE=1, HfHubHTTPError
    # (an OSError) for HTTP failures and missing tokens, and httpx transport errors for unreachable endpoints.
    return (OSError, httpx.TransportError)


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(
        prog="blindgrasp-push-dataset", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("root", type=Path, help="dataset folder (LeRobotDataset root)")
    p.add_argument("--repo-id", required=True, help="USER/NAME on the Hub")
    p.add_argument("--kind", choices=sorted(cards.TEMPLATES), default=None, help="card kind (default: detect)")
    p.add_argument("--license", default=cards.DEFAULT_LICENSE)
    p.add_argument("--tag", action="append", default=[], dest="tags", help="extra card tag (repeatable)")
    p.add_argument("--operator", action="append", default=[], dest="operators", help="glove operator (repeatable)")
    p.add_argument("--notes", default="", help="free text for the glove card's protocol section")
    p.add_argument("--private", action="store_true")
    p.add_argument("--branch", default=None)
    p.add_argument("--dry-run", action="store_true", help="prepare the card and stop before the network")
    return p.parse_args(argv)


def main(argv=None) -> None:
    args = parse_args(argv)
    try:
        ds, kwargs, plan = prepare(
            args.root, args.repo_id, args.kind, args.license, args.tags, args.operators, args.notes
        )
    except PushError as e:
        print(f"error: {e}", file=sys.stderr)
        raise SystemExit(2) from None
    print(
        f"{args.root}: {ds.meta.total_episodes} episodes, {ds.meta.total_frames} frames; card written to "
        f"{args.root / cards.CARD_NAME}; {len(plan['files'])} files ({plan['bytes'] / 1e6:.1f} MB) to upload "
        f"to https://huggingface.co/datasets/{args.repo_id}"
    )
    if args.dry_run:
        print("dry run: nothing uploaded")
        return
    try:
        push(ds, kwargs, private=args.private or None, branch=args.branch)
    except _network_errors() as e:
        print(
            f"error: upload to the Hub failed ({type(e).__name__}: {e}).\n"
            f"Nothing in {args.root} was changed except README.md; check the network and `hf auth login`, then "
            "run the same command again.",
            file=sys.stderr,
        )
        raise SystemExit(1) from None
    print(f"pushed: https://huggingface.co/datasets/{args.repo_id}")


if __name__ == "__main__":
    main()
