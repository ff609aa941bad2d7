"""How varied a demo set is: the spread of grasp poses across episodes, and how much the commands jitter.

    python -m lab.diagnosis.diversity --datasets=[LABEL=DATASET_ROOT,...] [--at_s=3.0]

The paper credits the stochastic teacher with "trajectory diversity". Two numbers separate the two kinds a demo set
can have, per object, averaged with equal weight over the objects it holds:
- **grasp-pose spread**: the standard deviation across episodes of each joint position `at_s` seconds into the
  episode (mid-grasp), averaged over the 9 joints (rad). Different grasps raise it.
- **command jitter**: the mean absolute change of the commanded joint targets from one control step to the next
  (rad). Per-step exploration noise raises it without changing the grasp.
Read with LeRobot's own loader, so any dataset the collector (or `lerobot-record`) wrote works.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.cli import parse_config


def diversity(root: str | Path, at_s: float = 3.0) -> dict:
    """{'objects': {object: {...}}, 'grasp_pose_spread_rad', 'command_jitter_rad', 'episodes'} of one dataset."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    from lerobot_blindgrasp.demos.dataset import object_from_task

    root = Path(root)
    info = json.loads((root / "meta" / "info.json").read_text())
    ds = LeRobotDataset(f"local/{root.name}", root=root)  # local files only: no Hub access
    cols = ds.hf_dataset.with_format("numpy")
    q = np.asarray(cols["observation.state"])[:, : spec.NUM_JOINTS]
    action = np.asarray(cols["action"])
    episode = np.asarray(cols["episode_index"])
    frame = np.asarray(cols["frame_index"])
    task = np.asarray(cols["task_index"])
    names = {
        int(i): object_from_task(t) for t, i in zip(ds.meta.tasks.index, ds.meta.tasks["task_index"], strict=True)
    }
    at_frame = round(at_s * info["fps"])
    per_object = {}
    for t in np.unique(task):
        rows = task == t
        mid = rows & (frame == at_frame)
        # Step-to-step change within an episode only: the first frame of each episode has no predecessor.
        same_episode = (episode[1:] == episode[:-1]) & rows[1:]
        per_object[names.get(int(t), str(t))] = {
            "episodes": int(len(np.unique(episode[rows]))),
            "grasp_pose_spread_rad": float(q[mid].std(axis=0).mean()) if mid.sum() > 1 else float("nan"),
            "command_jitter_rad": float(np.abs(np.diff(action, axis=0))[same_episode].mean()),
        }
    vals = list(per_object.values())
    return {
        "objects": per_object,
        "episodes": sum(v["episodes"] for v in vals),
        "grasp_pose_spread_rad": float(np.nanmean([v["grasp_pose_spread_rad"] for v in vals])),
        "command_jitter_rad": float(np.mean([v["command_jitter_rad"] for v in vals])),
        "at_s": at_s,
    }


@dataclass
class DiversityConfig:
    # The demo sets, each `[LABEL=]DATASET_ROOT` (label: the root when not given), one table row each
    datasets: list[str] = field(default_factory=list)
    at_s: float = 3.0  # seconds into each episode at which the grasp-pose spread is measured (mid-grasp)


def main(argv: list[str] | None = None) -> None:
    cfg = parse_config(DiversityConfig, argv)
    args = cfg.datasets
    if not args:
        raise SystemExit("error: give the demo sets: --datasets=[LABEL=DATASET_ROOT,...]")
    lines = [
        f"| dataset | episodes | grasp-pose spread at {cfg.at_s:g} s (rad) | command jitter (rad/step) |",
        "|---|---:|---:|---:|",
    ]
    for arg in args:
        label, _, root = arg.rpartition("=")
        d = diversity(root, cfg.at_s)
        lines.append(
            f"| {label or root} | {d['episodes']} | {d['grasp_pose_spread_rad']:.3f} | "
            f"{d['command_jitter_rad']:.3f} |"
        )
    print("\n".join(lines))


if __name__ == "__main__":
    main()
