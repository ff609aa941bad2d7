"""`blindgrasp-repair-dataset --root=DIR`: bring a crashed LeRobotDataset back to every complete episode. A writer
that dies before `finalize()` leaves footerless parquet files, episode rows that never reached meta/episodes and
counts for frames that are gone, and LeRobot refuses the folder. The metadata is rebuilt from the data (`rebuild_meta`)
for every whole episode, or, in a demo collection, for those of its last checkpoint, which its tally and seeds
describe. Every write is atomic: a killed repair is run again; on a consistent dataset it changes nothing.
"""

from __future__ import annotations

import itertools
import logging
import sys
from dataclasses import dataclass, field
from pathlib import Path

from lerobot_blindgrasp import durable
from lerobot_blindgrasp.cli import parse_config

from . import provenance, rebuild_meta


@dataclass
class RepairReport:
    root: Path
    kept_episodes: int = 0
    kept_frames: int = 0
    lost_episodes: list[int] = field(default_factory=list)  # claimed by info.json beyond the kept ones
    removed: list[str] = field(default_factory=list)  # temp files of killed atomic writes
    rebuilt: rebuild_meta.Rebuilt | None = None  # None: the metadata already said exactly the kept episodes

    @property
    def changed(self) -> bool:
        return bool(self.removed or self.rebuilt)

    def summary(self) -> str:
        lost = self.lost_episodes
        lines = [
            f"{self.root}: kept {self.kept_episodes} episodes ({self.kept_frames} frames)"
            + (f"; lost {len(lost)} episode(s) {_ranges(lost)}" if lost else "; nothing lost")
        ]
        lines += self.rebuilt.lines(self.root) if self.rebuilt else []
        lines += [f"  removed   {f}" for f in self.removed]
        if not self.changed:
            lines.append("  the dataset was consistent; nothing was changed")
        return "\n".join(lines)


def _ranges(indices: list[int]) -> str:
    """[0, 1, 2, 5] -> "[0-2, 5]"."""
    step = itertools.count()
    runs = [list(g) for _, g in itertools.groupby(indices, lambda i: i - next(step))]
    return "[" + ", ".join(str(r[0]) if len(r) == 1 else f"{r[0]}-{r[-1]}" for r in runs) + "]"


def repair(root: str | Path, dry_run: bool = False) -> RepairReport:
    """Repair `root` in place (see the module docstring); with dry_run, only say what would change."""
    root = Path(root)
    limit = None
    if provenance.is_collection(root):  # resume from the last checkpoint: the episodes with a meta/episodes row
        rows = set(rebuild_meta.episode_rows(root)[0])
        limit = next(k for k in itertools.count() if k not in rows)
    done = rebuild_meta.rebuild(root, dry_run=dry_run, limit=limit)
    temps = sorted(p for p in root.rglob(f".*{durable.TEMP_MARK}*") if p.is_file())
    if not dry_run:
        for p in temps:
            p.unlink(missing_ok=True)
    return RepairReport(
        root,
        kept_episodes=done.episodes,
        kept_frames=done.frames,
        lost_episodes=list(range(done.episodes, done.claimed)),
        removed=[str(p.relative_to(root)) for p in temps],
        rebuilt=done if done.changed else None,
    )


@dataclass
class RepairConfig:
    """Bring a crashed LeRobotDataset (blindgrasp-collect-demos, lerobot-record) back to every complete episode, so
    that it loads and recording can resume: metadata LeRobot had not written yet is rebuilt from the data files,
    cut data is set aside in <root>.set-aside/."""

    root: Path | None = None  # the dataset folder (the one holding meta/ and data/)
    dry_run: bool = False  # only say what would be kept, lost, set aside and rewritten

    def __post_init__(self):
        if self.root is None:
            raise ValueError("--root is required (the dataset folder holding meta/ and data/)")
        self.root = Path(self.root)


def main(argv=None) -> None:
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    cfg = parse_config(RepairConfig, argv)
    if not (cfg.root / "meta").is_dir():
        print(f"error: {cfg.root} is not a LeRobotDataset folder (no meta/)", file=sys.stderr)
        raise SystemExit(2)
    try:
        report = repair(cfg.root, dry_run=cfg.dry_run)
    except (rebuild_meta.RebuildError, durable.WriteError) as e:
        print(f"error: {e}", file=sys.stderr)
        raise SystemExit(2) from None
    print(("dry run: " if cfg.dry_run else "") + report.summary())


if __name__ == "__main__":
    main()
