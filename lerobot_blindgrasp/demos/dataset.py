"""The demo dataset: LeRobotDataset v3 at 20 fps, state-only, the shared schema (`spec.dataset_features()`) plus
per-episode metadata features, constant within the episode: `episode.outcome`, `episode.randomization` (the Table II
draw and the object's start xy) and `episode.seed`; the object is in the task string. Features, because LeRobot's
tools drop unknown columns and info.json keys; their per-episode stats (min = max) let `episode_table()` read every
episode without its frames. Merging with glove demos needs the three removed first (`MERGE_HINT`).
"""

from __future__ import annotations

import contextlib
import os
import shutil
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.compat import skip_empty_image_embedding
from lerobot_blindgrasp.demos.curation import CurationResult
from lerobot_blindgrasp.rollout.loop import RANDOMIZATION_NAMES, Episode
from lerobot_blindgrasp.sim import objects

# robot_type of every blindgrasp dataset, sim or real: `merge` refuses datasets whose robot_type differs, so the
# real gripper's LeRobot robot type must carry this name too.
ROBOT_TYPE = "blindgrasp_gripper"
FPS = spec.CONTROL_HZ

OUTCOME_NAMES: tuple[str, ...] = (
    "success",
    "curation_passed",
    "left_workspace",
    "longest_hold_s",
    "force_sum_n",
    "rollout_steps",
)
SEED_NAMES: tuple[str, ...] = ("env_seed", "env_episode")
EPISODE_FEATURES: dict[str, dict] = {
    "episode.outcome": {"dtype": "float32", "shape": (len(OUTCOME_NAMES),), "names": list(OUTCOME_NAMES)},
    "episode.randomization": {
        "dtype": "float32",
        "shape": (len(RANDOMIZATION_NAMES),),
        "names": list(RANDOMIZATION_NAMES),
    },
    "episode.seed": {"dtype": "int64", "shape": (len(SEED_NAMES),), "names": list(SEED_NAMES)},
}
METADATA_FEATURE_NAMES: tuple[str, ...] = tuple(EPISODE_FEATURES)
MERGE_HINT = (
    "lerobot-edit-dataset --repo_id {repo_id} --root {root} --new_repo_id {repo_id}_schema "
    "--new_root {root}_schema "
    '--operation.type remove_feature --operation.feature_names "{names}"'
)


def demo_features() -> dict:
    return {**spec.dataset_features(), **EPISODE_FEATURES}


def create(root: Path, repo_id: str):
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    # video_backend is irrelevant without cameras; naming it skips LeRobot's torchcodec probe and its warning.
    return LeRobotDataset.create(
        repo_id,
        fps=FPS,
        features=demo_features(),
        root=root,
        robot_type=ROBOT_TYPE,
        use_videos=False,
        video_backend="pyav",
    )


def resume(root: Path, repo_id: str):
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    ds = LeRobotDataset.resume(repo_id, root=root, video_backend="pyav")
    problems = check_schema(ds.meta.features, ds.meta.fps, ds.meta.robot_type)
    if problems:
        ds.finalize()
        raise ValueError(f"{root} is not a blindgrasp demo dataset: " + "; ".join(problems))
    return ds


def check_schema(features: dict, fps: int, robot_type: str | None, want: dict | None = None) -> list[str]:
    """Why a dataset of these features, fps and robot type does not hold `want` (default: the demo schema) at 20
    fps as a blindgrasp robot; [] when it does."""
    problems = []
    for key, ft in (want or demo_features()).items():
        have = features.get(key)
        if have is None:
            problems.append(f"missing feature {key!r}")
        elif (
            have["dtype"] != ft["dtype"]
            or tuple(have["shape"]) != tuple(ft["shape"])
            or list(have["names"]) != list(ft["names"])
        ):
            problems.append(f"feature {key!r} differs from the spec")
    if fps != FPS:
        problems.append(f"fps {fps} != {FPS}")
    if robot_type != ROBOT_TYPE:
        problems.append(f"robot_type {robot_type!r} != {ROBOT_TYPE!r}")
    return problems


def episode_buffer(ep: Episode, cut: CurationResult, episode_index: int) -> dict:
    """An episode for `LeRobotDataset.save_episode(episode_data=...)`: whole arrays, no add_frame per frame."""
    n = cut.keep_steps
    task = objects.get_object(ep.object_name).task
    outcome = np.array(
        [ep.success, cut.passed, ep.left_workspace, cut.longest_hold_s, cut.force_sum_n, ep.length],
        dtype=np.float32,
    )
    return {
        "size": n,
        "task": [task] * n,
        spec.STATE_KEY: ep.state[:n].astype(np.float32, copy=False),
        spec.ACTION_KEY: ep.action[:n].astype(np.float32, copy=False),
        "episode.outcome": np.broadcast_to(outcome, (n, outcome.size)),
        "episode.randomization": np.broadcast_to(
            ep.randomization.astype(np.float32), (n, len(RANDOMIZATION_NAMES))
        ),
        "episode.seed": np.broadcast_to(np.array([ep.env_seed, ep.env_episode], dtype=np.int64), (n, 2)),
        # LeRobot's default columns: timestamp and frame_index as add_frame would compute them; index and
        # task_index are overwritten by save_episode.
        "timestamp": (np.arange(n) / FPS).astype(np.float32),
        "frame_index": np.arange(n, dtype=np.int64),
        "episode_index": episode_index,
        "index": np.zeros(n, dtype=np.int64),
        "task_index": np.zeros(n, dtype=np.int64),
    }


def write_episode(ds, ep: Episode, cut: CurationResult, fast: bool = True) -> int:
    """Append one kept episode; returns the number of frames written."""
    with skip_empty_image_embedding() if fast else contextlib.nullcontext():
        ds.save_episode(episode_data=episode_buffer(ep, cut, ds.meta.total_episodes))
    return cut.keep_steps


def object_from_task(task: str) -> str | None:
    """The catalogue object a task string names (None for tasks that are not ours, e.g. edited ones)."""
    return next((name for name, o in objects.CATALOGUE.items() if o.task == task), None)


def episode_table(root: str | Path):
    """One row per episode (pandas): episode_index, task, object, length and every metadata value, read from
    meta/episodes only (fast on large datasets); pick episodes for `LeRobotDataset(..., episodes=[...])` with it."""
    import pandas as pd

    files = sorted(Path(root, "meta", "episodes").glob("chunk-*/file-*.parquet"))
    if not files:
        raise FileNotFoundError(f"no episode metadata under {Path(root, 'meta', 'episodes')}")
    raw = pd.concat([pd.read_parquet(f) for f in files], ignore_index=True).sort_values("episode_index")
    out = pd.DataFrame(
        {
            "episode_index": raw["episode_index"].to_numpy(),
            "task": [t[0] for t in raw["tasks"]],
            "length": raw["length"].to_numpy(),
        }
    )
    out["object"] = [object_from_task(t) for t in out["task"]]
    for key, ft in EPISODE_FEATURES.items():
        col = f"stats/{key}/min"
        if col not in raw:
            continue
        values = np.stack(raw[col].to_numpy())
        for j, name in enumerate(ft["names"]):
            out[name] = values[:, j].astype(np.int64 if ft["dtype"] == "int64" else np.float64)
    for flag in ("success", "curation_passed", "left_workspace"):
        if flag in out:
            out[flag] = out[flag] > 0.5
    return out.reset_index(drop=True)


def aggregate(repo_ids: list[str], roots: list[Path], repo_id: str, dest: Path) -> None:
    """Merge datasets into `dest` (built beside it) with LeRobot's `aggregate_datasets`, mergeable again: LeRobot
    0.6.1 offsets each appended row's `meta/episodes/{chunk,file}_index` from the source's own, so a source with
    several episodes files leaves rows naming files that do not exist. Each row is set to the file that holds it."""
    import pyarrow as pa
    import pyarrow.parquet as pq
    from lerobot.datasets.aggregate import aggregate_datasets

    from lerobot_blindgrasp.demos.rebuild_meta import chunk_file

    with built_beside(Path(dest)) as out:
        aggregate_datasets(list(repo_ids), repo_id, roots=[Path(r) for r in roots], aggr_root=out)
        for f in sorted(Path(out, "meta", "episodes").glob("chunk-*/file-*.parquet")):
            table = pq.read_table(f)  # pyarrow, not pandas: the rest of the schema goes back unchanged
            where = dict(zip(("chunk_index", "file_index"), chunk_file(f), strict=True))
            if all(set(table[f"meta/episodes/{k}"].to_pylist()) == {v} for k, v in where.items()):
                continue
            for k, v in where.items():
                col = f"meta/episodes/{k}"
                column = pa.array([v] * table.num_rows, table.schema.field(col).type)
                table = table.set_column(table.schema.get_field_index(col), table.schema.field(col), column)
            pq.write_table(table, f)


@contextlib.contextmanager
def built_beside(dest: Path) -> Iterator[Path]:
    """A fresh folder beside `dest` that replaces it, fsynced, once the block ends without an error: a kill midway
    leaves no folder that looks finished, and the next try starts over."""
    from lerobot_blindgrasp import durable

    tmp = dest.with_name(f".{dest.name}{durable.TEMP_MARK}build")
    shutil.rmtree(tmp, ignore_errors=True)
    yield tmp
    durable.fsync_tree(tmp)
    shutil.rmtree(dest, ignore_errors=True)
    os.replace(tmp, dest)
    durable.fsync_dir(dest.parent)
