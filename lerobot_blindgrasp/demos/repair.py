"""`blindgrasp-repair-dataset --root=DIR`: bring a crashed LeRobotDataset back to every complete episode.

    blindgrasp-repair-dataset --root=runs/demos_cpu            # repair in place, say what was kept and lost
    blindgrasp-repair-dataset --root=runs/demos_cpu --dry_run=true

A LeRobot v3 writer that dies before `finalize()` leaves footerless parquet files, episode rows that never reached
meta/episodes, and counts in `info.json` / `stats.json` for frames that are gone; LeRobot then refuses the folder.
When the data holds finished episodes that meta/episodes lacks, the metadata is first rebuilt from the data
(`rebuild_meta`), except in a demo collection (collection.json), which resumes from its last checkpoint. Then the
repair keeps episodes 0..k-1, the longest prefix whose metadata row, frames and video files agree (video content is
not checked), rewrites or removes the files holding later ones, and re-derives tasks.parquet (if unreadable),
stats.json (LeRobot's `aggregate_stats` of the kept episodes' stats) and `info.json`, last. Every write is atomic:
a repair killed half-way is run again; on a consistent dataset it changes nothing.
"""

from __future__ import annotations

import itertools
import json
import logging
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from lerobot_blindgrasp import durable
from lerobot_blindgrasp.cli import parse_config

from . import provenance, rebuild_meta
from .rebuild_meta import TASKS, chunk_file, footer_ok

INFO = Path("meta/info.json")
STATS = Path("meta/stats.json")


class RepairError(Exception):
    """The folder cannot be repaired automatically (no readable info.json: the features are unknown)."""


@dataclass
class RepairReport:
    root: Path
    episodes_claimed: int = 0  # info.json's total_episodes before the repair
    kept_episodes: int = 0
    kept_frames: int = 0
    lost_episodes: list[int] = field(default_factory=list)  # indices seen anywhere beyond the kept prefix
    removed: list[str] = field(default_factory=list)  # files deleted (unreadable or holding only lost episodes)
    rewritten: list[str] = field(default_factory=list)  # files rewritten without the lost episodes, or re-derived
    first_problem: str = ""  # why the prefix ends where it does ("" when every episode checks out)
    rebuilt: rebuild_meta.Rebuilt | None = None  # the metadata rebuilt from the data first (`rebuild_meta`)

    @property
    def changed(self) -> bool:
        return bool(self.removed or self.rewritten or self.rebuilt)

    def summary(self) -> str:
        lost = self.lost_episodes
        lines = [
            f"{self.root}: kept {self.kept_episodes} episodes ({self.kept_frames} frames)"
            + (f"; lost {len(lost)} episode(s) {_ranges(lost)}" if lost else "; nothing lost")
        ]
        if self.first_problem:
            lines.append(f"  the verified prefix ends at episode {self.kept_episodes}: {self.first_problem}")
        lines += self.rebuilt.lines(self.root) if self.rebuilt else []
        lines += [f"  removed   {f}" for f in self.removed]
        lines += [f"  rewrote   {f}" for f in self.rewritten]
        if not self.changed:
            lines.append("  the dataset was consistent; nothing was changed")
        return "\n".join(lines)


def _ranges(indices: list[int]) -> str:
    """[0, 1, 2, 5] -> "[0-2, 5]"."""
    step = itertools.count()
    runs = [list(g) for _, g in itertools.groupby(indices, lambda i: i - next(step))]
    return "[" + ", ".join(str(r[0]) if len(r) == 1 else f"{r[0]}-{r[-1]}" for r in runs) + "]"


def inspect(root: Path) -> tuple[dict, RepairReport, dict]:
    """Find the verified prefix without changing anything. Returns (info, report, plan): the files to remove and
    the files to rewrite without the episodes from k on."""
    root = Path(root)
    try:
        info = json.loads((root / INFO).read_text())
        features = info["features"]
    except (OSError, ValueError, KeyError) as e:
        raise RepairError(
            f"{root / INFO} is missing or unreadable ({type(e).__name__}: {e}), so the dataset's features are "
            "unknown. Copy meta/info.json from a dataset recorded with the same robot and settings, then run "
            "this again (the episode counts in it are re-derived)."
        ) from None
    report = RepairReport(root=root, episodes_claimed=int(info.get("total_episodes", 0)))
    remove: list[Path] = [p for p in root.rglob(f".*{durable.TEMP_MARK}*") if p.is_file()]
    meta_tables = _read_tables(root / "meta" / "episodes", None, remove)
    data_tables = _read_tables(root / "data", ["episode_index", "index"], remove)
    episodes: dict[int, dict] = {}
    for table in meta_tables.values():
        for row in table.select([c for c in table.column_names if not c.startswith("stats/")]).to_pylist():
            episodes.setdefault(int(row["episode_index"]), row)
    frames: dict[tuple[int, int], dict[int, np.ndarray]] = {}
    for p, table in data_tables.items():
        ep, idx = table["episode_index"].to_numpy(), table["index"].to_numpy()
        frames[chunk_file(p)] = {int(e): idx[ep == e] for e in np.unique(ep)}
    k, next_from = _verified_prefix(root, info, features, episodes, frames, report)
    report.kept_episodes, report.kept_frames = k, next_from
    seen = set(episodes) | {e for per_file in frames.values() for e in per_file}
    report.lost_episodes = sorted(e for e in seen | set(range(report.episodes_claimed)) if e >= k)
    rewrite: list[Path] = []
    for p, table in [*meta_tables.items(), *data_tables.items()]:
        lost = table["episode_index"].to_numpy() >= k
        if lost.all():
            remove.append(p)
        elif lost.any():
            rewrite.append(p)
    return info, report, {"remove": remove, "rewrite": rewrite}


def _read_tables(folder: Path, columns: list[str] | None, unreadable: list[Path]) -> dict:
    """The readable parquet files of a dataset folder (path -> table); the unreadable ones go to `unreadable`."""
    import pyarrow.parquet as pq

    tables = {}
    for p in sorted(folder.glob("chunk-*/file-*.parquet")):
        if not footer_ok(p):
            unreadable.append(p)
        else:
            tables[p] = pq.read_table(p, columns=columns)
    return tables


def _verified_prefix(
    root: Path, info: dict, features: dict, episodes: dict, frames: dict, report
) -> tuple[int, int]:
    """(episodes, frames) of the longest prefix whose metadata, frames and videos agree; the first disagreement
    goes to `report.first_problem`."""
    video_keys = [k for k, ft in features.items() if ft.get("dtype") == "video"]
    k, next_from = 0, 0
    while True:
        row = episodes.get(k)
        if row is None:
            later = itertools.chain(episodes, *frames.values())  # every episode index seen anywhere
            beyond = k < report.episodes_claimed or any(e >= k for e in later)
            report.first_problem = f"episode {k} has no readable meta/episodes row" if beyond else ""
            return k, next_from
        idx = frames.get((int(row["data/chunk_index"]), int(row["data/file_index"])), {}).get(k)
        length, lo, hi = int(row["length"]), int(row["dataset_from_index"]), int(row["dataset_to_index"])
        if idx is None:
            report.first_problem = f"episode {k}'s frames are not in a readable data file"
            return k, next_from
        if not (lo == next_from and hi - lo == length == len(idx) and np.array_equal(idx, np.arange(lo, hi))):
            report.first_problem = f"episode {k}'s frames do not match its metadata ({len(idx)} of {length} rows)"
            return k, next_from
        missing = [vk for vk in video_keys if not _video_file(root, info, row, vk).is_file()]
        if missing:
            report.first_problem = f"episode {k}'s video files are missing ({', '.join(missing)})"
            return k, next_from
        next_from = hi
        k += 1


def _video_file(root: Path, info: dict, row: dict, key: str) -> Path:
    return root / info.get("video_path").format(
        video_key=key,
        chunk_index=int(row[f"videos/{key}/chunk_index"]),
        file_index=int(row[f"videos/{key}/file_index"]),
    )


def repair(root: str | Path, dry_run: bool = False) -> RepairReport:
    """Repair `root` in place (see the module docstring); with dry_run, only say what would change."""
    import pyarrow.compute as pc
    import pyarrow.parquet as pq

    root = Path(root)
    # A demo collection resumes from its last checkpoint (`records.py`): its metadata is not rebuilt.
    rebuilt = None if provenance.is_collection(root) else rebuild_meta.rebuild(root, dry_run=dry_run)
    if rebuilt and dry_run:
        return RepairReport(root, kept_episodes=rebuilt.episodes, kept_frames=rebuilt.frames, rebuilt=rebuilt)
    info, report, plan = inspect(root)
    report.rebuilt = rebuilt
    k = report.kept_episodes
    rel = lambda p: str(Path(p).relative_to(root))  # noqa: E731
    report.removed = [rel(p) for p in plan["remove"]]
    report.rewritten = [rel(p) for p in plan["rewrite"]]
    tasks_ok = (root / TASKS).is_file() and footer_ok(root / TASKS)
    stats_ok = _json_ok(root / STATS) if k else not (root / STATS).exists()
    counts = (info.get("total_episodes"), info.get("total_frames"))
    needs_meta = report.changed or counts != (k, report.kept_frames) or not tasks_ok or not stats_ok
    if needs_meta:
        report.rewritten += [str(p) for p in (TASKS, STATS, INFO) if p != TASKS or not tasks_ok]
    if dry_run or not needs_meta:
        return report

    for p in plan["rewrite"]:
        table = pq.read_table(p)
        kept = table.filter(pc.less(table["episode_index"], k))
        with durable.atomic_path(p) as tmp:
            pq.write_table(kept, tmp, compression="snappy", use_dictionary=True)
    for p in plan["remove"]:
        p.unlink(missing_ok=True)
    meta = _kept_meta(root, k)
    if not tasks_ok:
        _rebuild_tasks(root, meta)
    _write_stats(root, meta, info["features"])
    n_tasks = len(pq.read_table(root / TASKS)) if (root / TASKS).is_file() else 0
    info.update(
        total_episodes=k,
        total_frames=report.kept_frames,
        total_tasks=n_tasks,
        splits={"train": f"0:{k}"} if k else {},
    )
    durable.atomic_write_json(root / INFO, info, indent=4)  # last: LeRobot trusts these counts
    return report


def _json_ok(path: Path) -> bool:
    try:
        json.loads(path.read_text())
        return True
    except (OSError, ValueError):
        return False


def _kept_meta(root: Path, k: int):
    import pandas as pd

    files = sorted((root / "meta" / "episodes").glob("chunk-*/file-*.parquet"))
    if not files:
        return pd.DataFrame()
    meta = pd.concat([pd.read_parquet(f) for f in files], ignore_index=True)
    return meta[meta["episode_index"] < k].sort_values("episode_index").reset_index(drop=True)


def _rebuild_tasks(root: Path, meta) -> None:
    """tasks.parquet from the kept episodes: each frame's task_index, paired with its episode's task string."""
    import pandas as pd

    pairs: dict[int, str] = {}
    for f in sorted((root / "data").glob("chunk-*/file-*.parquet")):
        d = pd.read_parquet(f, columns=["episode_index", "task_index"]).drop_duplicates()
        for ep, ti in d.itertuples(index=False):
            tasks = meta.loc[meta["episode_index"] == ep, "tasks"]
            if len(tasks) and len(tasks.iloc[0]) == 1:
                pairs.setdefault(int(ti), str(tasks.iloc[0][0]))
    order = sorted(pairs)
    df = pd.DataFrame({"task_index": order}, index=pd.Index([pairs[i] for i in order], name="task"))
    with durable.atomic_path(root / TASKS) as tmp:
        df.to_parquet(tmp)


def _write_stats(root: Path, meta, features: dict) -> None:
    """stats.json re-aggregated from the kept episodes' per-episode stats, the way lerobot-edit-dataset does."""
    from lerobot.datasets.compute_stats import aggregate_stats
    from lerobot.datasets.utils import serialize_dict

    per_episode = []
    for _, row in meta.iterrows():
        stats: dict[str, dict] = {}
        for col, value in row.items():
            if not str(col).startswith("stats/"):
                continue
            name, stat = str(col)[len("stats/") :].rsplit("/", 1)
            if name not in features:
                continue
            arr = np.array(value.tolist() if hasattr(value, "tolist") else value)
            if arr.dtype == object:  # nested (C, 1, 1) image stats come back as arrays of arrays
                arr = np.array([np.asarray(v, dtype=np.float64).reshape(-1)[0] for v in arr]).reshape(-1, 1, 1)
            stats.setdefault(name, {})[stat] = arr
        per_episode.append(stats)
    if not per_episode:  # no episode left: LeRobot expects no stats file rather than an empty one
        (root / STATS).unlink(missing_ok=True)
        return
    durable.atomic_write_json(root / STATS, serialize_dict(aggregate_stats(per_episode)), indent=4)


@dataclass
class RepairConfig:
    """Bring a crashed LeRobotDataset (blindgrasp-collect-demos, lerobot-record) back to every complete episode, so
    that it loads and recording can resume: metadata LeRobot had not written yet is rebuilt from the data files,
    cut data is set aside in <root>.set-aside/."""

    root: Path | None = None  # the dataset folder (the one holding meta/ and data/)
    dry_run: bool = False  # only say what would be kept, lost, removed and rewritten

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
    except (RepairError, rebuild_meta.RebuildError, durable.WriteError) as e:
        print(f"error: {e}", file=sys.stderr)
        raise SystemExit(2) from None
    print(("dry run: " if cfg.dry_run else "") + report.summary())


if __name__ == "__main__":
    main()
