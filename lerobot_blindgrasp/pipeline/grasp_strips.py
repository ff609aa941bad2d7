"""Frame strips of successful student grasps, one row per object shape, from lerobot-eval's own videos.

lerobot-eval renders the first episodes of every task and lists them in `eval_info.json` (`video_paths` beside
`successes`, in episode order). For each shape this picks one successful rendered episode, medium size first, and
lays a few of its frames across the episode. Decoding uses PyAV, which LeRobot's dataset extra installs.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from lerobot_blindgrasp import durable, spec
from lerobot_blindgrasp.sim import objects
from lerobot_blindgrasp.sim.objects import object_for_task_id

SIZE_PREFERENCE = ("medium", "large", "small")  # the medium objects are the paper's headline set


def successful_videos(eval_info: dict) -> dict[str, list[Path]]:
    """Object name -> videos of its successful episodes that exist on disk (episode k is video k)."""
    out: dict[str, list[Path]] = {}
    for task in eval_info.get("per_task", []):
        m = task.get("metrics", {})
        ok = [Path(p) for p, s in zip(m.get("video_paths", []), m.get("successes", []), strict=False) if s]
        ok = [p for p in ok if p.exists()]
        if ok:
            out[object_for_task_id(int(task["task_id"]))] = ok
    return out


def pick_per_class(videos: dict[str, list[Path]]) -> dict[str, tuple[str, Path]]:
    """Shape -> (object, video): for each shape, the first successful video, medium size first."""
    picked: dict[str, tuple[str, Path]] = {}
    for size in SIZE_PREFERENCE:
        for name, paths in videos.items():
            o = objects.get_object(name)
            shape = o.geometry.split("_")[0]  # cuboid_a and cuboid_b are one class
            if o.size_label == size and shape not in picked:
                picked[shape] = (name, paths[0])
    return dict(sorted(picked.items()))


def read_frames(video: Path, n: int) -> tuple[list[np.ndarray], np.ndarray]:
    """n RGB frames evenly spaced over the video (first and last included), and their frame indices.

    The container's frame count picks the indices up front, so decoding stops at the last one and only the picked
    frames are converted to RGB; a video whose container gives no count, or a wrong one, is decoded whole."""
    import av  # lerobot[dataset] dependency; imported here so the report works without any video

    with av.open(str(video)) as container:
        total = container.streams.video[0].frames  # 0: the container does not say
        if total > 0 and n > 0:
            idx = np.linspace(0, total - 1, n).round().astype(int)
            picked: dict[int, np.ndarray] = {}
            decoded = container.decode(video=0)
            for k, frame in enumerate(decoded):
                if k in idx:
                    picked[k] = frame.to_ndarray(format="rgb24")
                if k == idx[-1]:
                    break
            # With n > 1 the last index is the last frame: no frame may follow it, or the count was wrong. With
            # n == 1 the index is 0 whatever the count.
            if len(picked) == len(set(idx.tolist())) and (n == 1 or next(decoded, None) is None):
                return [picked[i] for i in idx], idx
    with av.open(str(video)) as container:
        frames = [f.to_ndarray(format="rgb24") for f in container.decode(video=0)]
    if not frames:
        raise ValueError(f"{video} has no frames")
    idx = np.linspace(0, len(frames) - 1, n).round().astype(int)
    return [frames[i] for i in idx], idx


def write_grasp_strips(
    eval_info: dict, out_png: Path, frames_per_row: int = 5, fps: float = spec.CONTROL_HZ
) -> Path | None:
    """One PNG: a row of frames per shape. Returns None when no successful episode was rendered."""
    picked = pick_per_class(successful_videos(eval_info))
    if not picked:
        return None
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = len(picked)
    fig, axes = plt.subplots(rows, frames_per_row, figsize=(2.2 * frames_per_row, 1.75 * rows), squeeze=False)
    for r, (_shape, (name, video)) in enumerate(picked.items()):
        frames, idx = read_frames(video, frames_per_row)
        for c, (img, t) in enumerate(zip(frames, idx / fps, strict=True)):
            ax = axes[r][c]
            ax.imshow(img)
            ax.set_xticks([])
            ax.set_yticks([])
            ax.set_title(f"t = {t:.1f} s", fontsize=7)
            if c == 0:
                ax.set_ylabel(name.replace("_", " "), fontsize=8)
    fig.suptitle("Successful student grasps (lerobot-eval videos), one per shape", fontsize=9)
    fig.tight_layout()
    out_png.parent.mkdir(parents=True, exist_ok=True)
    with durable.atomic_path(out_png) as tmp:
        fig.savefig(tmp, dpi=100)
    plt.close(fig)
    return out_png
