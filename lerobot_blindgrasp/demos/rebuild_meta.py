"""A LeRobot dataset's metadata rebuilt from its data files, for the episodes whose frames are all there (no image or
video features). LeRobot 0.6.1 writes episode rows only every `metadata_buffer_size` (10) episodes or at `finalize()`.
`rebuild(root)` takes every complete row group (`parquet_salvage`), cut to the longest prefix of whole episodes (and
to `limit`), feeds it to LeRobot's `LeRobotDatasetMetadata` in a staging folder and moves the files in atomically,
`info.json` last; replaced files go to `<root>.set-aside/`.
"""

from __future__ import annotations

import json
import os
import shutil
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from lerobot_blindgrasp import durable

from .parquet_salvage import MAGIC, salvage

EPISODES = Path("meta/episodes")
TASKS = Path("meta/tasks.parquet")
STATS = Path("meta/stats.json")


class RebuildError(Exception):
    """The metadata cannot be rebuilt from the data (features unknown, or held in files outside the data)."""


@dataclass
class Rebuilt:
    episodes: int = 0  # kept
    frames: int = 0
    claimed: int = 0  # info.json's total_episodes before
    changed: bool = False  # False: the metadata already said exactly this, nothing was done
    set_aside: list[str] = field(default_factory=list)  # what was moved to <root>.set-aside/, and why
    rewritten: list[str] = field(default_factory=list)

    def lines(self, root: Path) -> list[str]:
        out = [f"  rebuilt the metadata from the data: {self.episodes} finished episodes ({self.frames} frames)"]
        out += [f"  rewrote   {f}" for f in self.rewritten]
        out += [f"  set aside {f} -> {root.name}.set-aside/" for f in self.set_aside]
        return out


def _info(root: Path):
    from lerobot.datasets.io_utils import load_info

    try:
        return load_info(root)
    except (OSError, ValueError, KeyError, TypeError) as e:
        raise RebuildError(f"{root / 'meta/info.json'} is unreadable ({type(e).__name__}: {e})") from None


def _template(features: dict):
    """A one-row arrow table with the schema LeRobot's writer gives these features (`_save_episode_data`)."""
    import datasets
    from lerobot.datasets.feature_utils import get_hf_features_from_features

    hf = get_hf_features_from_features(features)
    row = {}
    for key in hf:
        ft = features[key]
        value = np.zeros(tuple(ft["shape"]), dtype=ft["dtype"])
        row[key] = [value.reshape(()).item() if tuple(ft["shape"]) == (1,) else value]
    return datasets.Dataset.from_dict(row, features=hf).with_format("arrow")[:]


def footer_ok(path: Path) -> bool:
    """Whether pyarrow opens the parquet file (False without a footer, or unreadable for any other reason)."""
    import pyarrow.parquet as pq

    try:
        pq.ParquetFile(path)
        return True
    except Exception:  # noqa: BLE001  (ArrowInvalid for a missing footer, OSError for I/O: unreadable either way)
        return False


def chunk_file(path: Path) -> tuple[int, int]:
    """(chunk index, file index) of `.../chunk-CCC/file-FFF.parquet`."""
    return int(path.parent.name.split("-")[-1]), int(path.stem.split("-")[-1])


def read_data(
    root: Path, features: dict, columns: list[str] | None = None
) -> list[tuple[Path, object, bool, int]]:
    """(path, complete rows, had a footer, bytes after the last complete row group) for each data file."""
    import io

    import pyarrow.parquet as pq

    template, out = None, []
    for p in sorted((root / "data").glob("chunk-*/file-*.parquet")):
        if footer_ok(p):
            out.append((p, pq.read_table(p, columns=columns), True, 0))
            continue
        template = _template(features) if template is None else template
        buf = p.read_bytes()
        fixed, _, cut = salvage(buf, template) if buf[:4] == MAGIC else (None, 0, len(buf))
        table = pq.read_table(io.BytesIO(fixed)) if fixed else template.slice(0, 0)
        out.append((p, table.select(columns or table.column_names), False, cut))
    return out


def whole_prefix(files: list) -> list[dict]:
    """The episodes 0..k-1 whose frames are all in the data, in order: [{index, length, file, rows, from}]."""
    episodes, next_index = [], 0
    for path, table, _, _ in files:
        ep, idx, fi = (table[c].to_numpy() for c in ("episode_index", "index", "frame_index"))
        for e in dict.fromkeys(ep.tolist()):
            rows = np.flatnonzero(ep == e)
            n = len(rows)
            in_order = e == len(episodes) and np.array_equal(idx[rows], np.arange(next_index, next_index + n))
            if not (in_order and np.array_equal(fi[rows], np.arange(n))):
                return episodes
            episodes.append({"index": int(e), "length": n, "file": path, "rows": rows, "from": next_index})
            next_index += n
    return episodes


def episode_rows(root: Path) -> tuple[list[int], bool]:
    """The episode indices of the rows in meta/episodes' readable files, and whether every file there is readable."""
    import pyarrow.parquet as pq

    rows, readable = [], True
    for p in sorted((root / EPISODES).glob("chunk-*/file-*.parquet")):
        if footer_ok(p):
            rows += pq.read_table(p, columns=["episode_index"])["episode_index"].to_pylist()
        else:
            readable = False
    return rows, readable


def _needed(root: Path, info, files: list, done: Rebuilt) -> bool:
    """False when the dataset already says exactly `done`'s episodes: every data file whole and holding only them,
    one episode row each, info.json's counts, a readable tasks.parquet and stats.json."""
    if any(not ok or cut for _, _, ok, cut in files) or sum(t.num_rows for _, t, _, _ in files) != done.frames:
        return True
    if done.episodes and not footer_ok(root / TASKS):
        return True  # `_tasks` then says why it cannot be rebuilt
    rows, readable = episode_rows(root)
    counts = (info.total_episodes, info.total_frames)
    if not readable or sorted(rows) != list(range(done.episodes)) or counts != (done.episodes, done.frames):
        return True
    try:
        json.loads((root / STATS).read_text())
        return False
    except (OSError, ValueError):
        return done.episodes > 0  # LeRobot writes no stats.json before the first episode


def _stats(table, rows, features: dict) -> dict:
    from lerobot.datasets.compute_stats import compute_episode_stats

    data = {}
    for key, ft in features.items():
        if key in table.column_names:
            values = table[key].take(rows).to_pylist()
            data[key] = np.asarray(values, dtype=ft["dtype"]).reshape(len(rows), *tuple(ft["shape"]))
            if tuple(ft["shape"]) == (1,):
                data[key] = data[key].reshape(len(rows))
    return compute_episode_stats(data, {k: features[k] for k in data})


def _tasks(root: Path) -> list[str]:
    import pandas as pd

    try:
        tasks = pd.read_parquet(root / TASKS)
    except Exception as e:  # noqa: BLE001  (a cut or missing file: the task strings are nowhere else)
        raise RebuildError(
            f"{root / TASKS} is unreadable ({type(e).__name__}); the task texts are only there"
        ) from None
    return [t for t, _ in sorted(zip(tasks.index, tasks["task_index"]), key=lambda x: x[1])]


def _stage(root: Path, staging: Path, info, files: list, episodes: list, tasks: list[str]) -> None:
    """LeRobot's own metadata writer, fed the kept episodes, writes the new meta/ into `staging`."""
    from lerobot.datasets.dataset_metadata import LeRobotDatasetMetadata

    meta = LeRobotDatasetMetadata.create(
        repo_id="local/rebuild",
        fps=info.fps,
        features=info.features,
        robot_type=info.robot_type,
        root=staging,
        use_videos=False,
        chunks_size=info.chunks_size,
        data_files_size_in_mb=info.data_files_size_in_mb,
    )
    meta.save_episode_tasks(tasks)
    tables = {p: t for p, t, _, _ in files}
    for e in episodes:
        table = tables[e["file"]]
        rows = e["rows"]
        task_of = sorted({tasks[i] for i in table["task_index"].take(rows).to_pylist()})
        chunk, file = chunk_file(e["file"])
        where = {"data/chunk_index": chunk, "data/file_index": file}
        where.update(dataset_from_index=e["from"], dataset_to_index=e["from"] + e["length"])
        meta.save_episode(e["index"], e["length"], task_of, _stats(table, rows, info.features), where)
    meta.finalize()


def _set_aside(root: Path, path: Path, why: str, done: Rebuilt, *, keep: bool = False, dry_run: bool) -> None:
    """Move `path` to <root>.set-aside/ (a rename: no copy on a nearly full disk); with `keep`, link it there and
    leave it in place for an atomic replacement, so that a kill in between never leaves the dataset without it."""
    done.set_aside.append(f"{path.relative_to(root)} ({why})")
    if dry_run:
        return
    dest = root.parent / f"{root.name}.set-aside" / path.relative_to(root)
    dest.parent.mkdir(parents=True, exist_ok=True)
    n = 1
    while dest.exists():
        dest, n = dest.with_name(f"{path.name}.{n}"), n + 1
    if keep:
        os.link(path, dest)
    else:
        path.replace(dest)


def _rewrite_data(root: Path, files: list, episodes: list, done: Rebuilt, dry_run: bool) -> None:
    import pyarrow.parquet as pq

    keep = {e["file"]: max(int(r) for r in e["rows"]) + 1 for e in episodes}
    for path, table, ok, cut in files:
        n = keep.get(path, 0)
        if ok and n == table.num_rows:
            continue
        why = "no footer: its writer was killed" if not ok else f"holds {table.num_rows - n} rows past the prefix"
        why += f"; {cut} bytes after its last complete row group: an unfinished write" if cut else ""
        _set_aside(root, path, why, done, keep=bool(n), dry_run=dry_run)
        if n:
            done.rewritten.append(str(path.relative_to(root)))
        if n and not dry_run:
            with durable.atomic_path(path) as tmp:
                pq.write_table(table.slice(0, n), tmp, compression="snappy", use_dictionary=True)


def rebuild(root: str | Path, dry_run: bool = False, limit: int | None = None) -> Rebuilt:
    """Rebuild `root`'s metadata from its data for its whole episodes, at most `limit` of them, unless it already
    says exactly that (then `changed` is False); with dry_run, only say what would change."""
    root = Path(root)
    info = _info(root)
    if any(ft["dtype"] in ("image", "video") for ft in info.features.values()):
        raise RebuildError(f"{root} has image or video features, whose frames are not in the data files")
    files = read_data(root, info.features, ["episode_index", "index", "frame_index"])  # all a check needs
    episodes = whole_prefix(files)[:limit]
    done = Rebuilt(len(episodes), sum(e["length"] for e in episodes), info.total_episodes)
    done.changed = _needed(root, info, files, done)
    if not done.changed:
        return done
    tasks = _tasks(root)
    staging = root / f".meta{durable.TEMP_MARK}rebuild"
    shutil.rmtree(staging, ignore_errors=True)
    try:
        if not dry_run:  # first: a failure here has changed nothing
            files = read_data(root, info.features)
            _stage(root, staging, info, files, episodes, tasks)
        _rewrite_data(root, files, episodes, done, dry_run)
        for p in sorted((root / EPISODES).glob("chunk-*/file-*.parquet")):
            _set_aside(root, p, "episode rows replaced by the rebuilt ones", done, dry_run=dry_run)
        if dry_run:
            return done
        for src in sorted((staging / EPISODES).glob("chunk-*/file-*.parquet")) + [staging / STATS]:
            if src.is_file():
                with durable.atomic_path(root / src.relative_to(staging)) as tmp:
                    shutil.copyfile(src, tmp)
        if not (staging / STATS).is_file():  # no episode kept: LeRobot expects no stats file
            (root / STATS).unlink(missing_ok=True)
        new = json.loads((staging / "meta/info.json").read_text())
        old = json.loads((root / "meta/info.json").read_text())
        old.update({k: new[k] for k in ("total_episodes", "total_frames", "total_tasks", "splits")})
        durable.atomic_write_json(root / "meta/info.json", old, indent=4)  # last: LeRobot trusts these counts
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return done
