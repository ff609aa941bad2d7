"""The main job's demonstration stages: the curated collection (and the uncurated fallback when too few pass), and,
beyond the paper, extra episodes of the objects a preset names, merged with LeRobot's `aggregate_datasets`."""

from __future__ import annotations

import json
import os
import shutil
import time
from pathlib import Path

from lerobot_blindgrasp import durable, presets
from lerobot_blindgrasp.pipeline import recipe
from lerobot_blindgrasp.pipeline.stage import Stage


def collect_stage(
    stage: Stage,
    preset: presets.Preset,
    teacher: Path,
    root: Path,
    repo_id: str,
    first_seed: int,
    curate: bool,
    extra: tuple[str, int] | None = None,
) -> Path:
    name = root.name if extra else "demos" if curate else "demos_uncurated"
    if stage.done(name):
        stage.skip(name, "collected")
        return root
    from lerobot_blindgrasp.demos.collect_cli import EXIT_EMPTY

    # An empty curated set is the caller's (the uncurated fallback). A collection cut short is resumed
    # (recipe.demos_collect adds --resume=true; the collector repairs a crashed folder first).
    cmd = recipe.demos_collect(preset, teacher, root, repo_id, first_seed, curate=curate, extra=extra)
    stage.run(name, cmd, ok=(0, EXIT_EMPTY))
    return root


def targeted_demos(
    stage: Stage,
    preset: presets.Preset,
    teacher: Path,
    out: Path,
    demos: Path,
    repo: str,
    seed: int,
    curated: bool,
) -> tuple[Path, str]:
    """Beyond the paper: the preset's extra episodes of the objects it names (one collection each, curated or not
    as the set the student trains on), merged with that set by LeRobot's `aggregate_datasets`. Returns the merged
    dataset and its repo id."""
    roots, repos = [demos], [repo]
    for k, (name, n) in enumerate(preset.demos.extra_episodes):
        root, extra_repo = out / f"{demos.name}_{name}", f"{repo}_{name}"
        first_seed = recipe.extra_demo_seed(seed, k, curated)
        collect_stage(stage, preset, teacher, root, extra_repo, first_seed, curate=curated, extra=(name, n))
        if kept(root):  # an object the teacher never solved adds nothing (its yield report says so)
            roots.append(root)
            repos.append(extra_repo)
    name = f"{demos.name}_targeted"
    merged, merged_repo = out / name, f"{repo}_merged"
    if stage.done(name):
        stage.skip(name, "merged")
        return merged, merged_repo
    from lerobot_blindgrasp.demos.dataset import aggregate

    # Merged beside the destination, then renamed: a kill mid-merge leaves no folder that looks finished.
    tmp = out / f".{name}{durable.TEMP_MARK}merge"
    shutil.rmtree(tmp, ignore_errors=True)
    t = time.time()
    aggregate(repos, roots, merged_repo, tmp)
    durable.fsync_tree(tmp)
    shutil.rmtree(merged, ignore_errors=True)
    os.replace(tmp, merged)
    durable.fsync_dir(out)
    stage.record["stages"][name] = {
        "command": f"aggregate_datasets({repos})",
        "wall_s": time.time() - t,
        "roots": [str(r) for r in roots],
    }
    stage.complete(name)
    print(f"[pipeline] {name}: merged {len(roots)} datasets into {merged}", flush=True)
    return merged, merged_repo


def kept(root: Path) -> int:
    report = json.loads((root / "yield_report.json").read_text())
    return int(report["total"]["kept"])
