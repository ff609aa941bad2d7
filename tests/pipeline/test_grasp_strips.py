"""Frame strips of successful grasps for the pipeline report, from lerobot-eval-style eval_info and mp4 files."""

from pathlib import Path

import av
import numpy as np

from lerobot_blindgrasp.envs.sim_env import object_for_task_id
from lerobot_blindgrasp.pipeline.job_report import (
    pick_per_class,
    read_frames,
    successful_videos,
    write_grasp_strips,
)
from lerobot_blindgrasp.sim import objects


def _video(path: Path, n: int, value_of_frame) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    with av.open(str(path), "w") as c:
        s = c.add_stream("libx264", rate=20)
        s.width, s.height, s.pix_fmt = 64, 48, "yuv420p"
        for k in range(n):
            img = np.full((48, 64, 3), value_of_frame(k), np.uint8)
            for pkt in s.encode(av.VideoFrame.from_ndarray(img, format="rgb24")):
                c.mux(pkt)
        for pkt in s.encode():
            c.mux(pkt)
    return path


def _task(tid: int, successes: list[bool], videos: list[Path]) -> dict:
    return {
        "task_group": "blindgrasp",
        "task_id": tid,
        "metrics": {"successes": successes, "video_paths": [str(v) for v in videos]},
    }


def test_strip_picks_a_successful_medium_episode_per_shape(tmp_path):
    names = list(objects.CATALOGUE)
    tid = {n: i for i, n in enumerate(names)}
    mk = lambda name, k: _video(tmp_path / name / f"eval_episode_{k}.mp4", 10, lambda f: 20 * f)  # noqa: E731
    info = {
        "per_task": [
            # cylinder: large and medium succeed; the medium one is preferred
            _task(tid["cylinder_a_large"], [True], [mk("cylinder_a_large", 0)]),
            _task(
                tid["cylinder_b_medium"], [False, True], [mk("cylinder_b_medium", 0), mk("cylinder_b_medium", 1)]
            ),
            # sphere: only the small one succeeds, so it is shown
            _task(tid["sphere_small"], [True], [mk("sphere_small", 0)]),
            # capsule: the success is an unrendered episode (no video) -> no capsule row
            _task(tid["capsule_medium"], [False, True], [mk("capsule_medium", 0)]),
        ]
    }
    assert object_for_task_id(tid["sphere_small"]) == "sphere_small"
    vids = successful_videos(info)
    assert set(vids) == {"cylinder_a_large", "cylinder_b_medium", "sphere_small"}
    picked = pick_per_class(vids)
    assert list(picked) == ["cylinder", "sphere"]
    assert picked["cylinder"][0] == "cylinder_b_medium" and picked["cylinder"][1].name == "eval_episode_1.mp4"

    frames, idx = read_frames(picked["cylinder"][1], 4)
    assert list(idx) == [0, 3, 6, 9] and frames[0].shape == (48, 64, 3)
    assert frames[0].mean() < frames[-1].mean()  # evenly spaced over the episode, in order

    png = write_grasp_strips(info, tmp_path / "strips.png", frames_per_row=4)
    assert png is not None and png.stat().st_size > 1000


def test_no_successful_rendered_episode_gives_no_strip(tmp_path):
    info = {"per_task": [_task(0, [False], [_video(tmp_path / "v.mp4", 3, lambda f: 0)])]}
    assert write_grasp_strips(info, tmp_path / "s.png") is None
    assert not (tmp_path / "s.png").exists()


class _CountingContainer:
    """av.open's container, counting the frames decoded and converted, `stated_frames` overrides its count."""

    def __init__(self, container, log: dict, stated_frames: int | None):
        self._c, self._log, self._stated = container, log, stated_frames

    def __enter__(self):
        self._c.__enter__()
        return self

    def __exit__(self, *exc):
        return self._c.__exit__(*exc)

    @property
    def streams(self):
        if self._stated is None:
            return self._c.streams
        stream = type("Stream", (), {"frames": self._stated})()
        return type("Streams", (), {"video": [stream]})()

    def decode(self, **kw):
        for f in self._c.decode(**kw):
            self._log["decoded"] += 1
            yield _CountingFrame(f, self._log)


class _CountingFrame:
    def __init__(self, frame, log):
        self._f, self._log = frame, log

    def to_ndarray(self, **kw):
        self._log["converted"] += 1
        return self._f.to_ndarray(**kw)


def test_read_frames_converts_only_the_picked_frames_and_matches_a_full_decode(tmp_path, monkeypatch):
    video = _video(tmp_path / "v.mp4", 10, lambda f: 20 * f)
    with av.open(str(video)) as c:
        everything = [f.to_ndarray(format="rgb24") for f in c.decode(video=0)]
    real_open = av.open
    for stated in (None, 0, 7, 13):  # the container's own count, none, too few, too many
        log = {"decoded": 0, "converted": 0}
        monkeypatch.setattr(av, "open", lambda p, *a, **k: _CountingContainer(real_open(p, *a, **k), log, stated))  # noqa: B023 (used in this iteration)
        for n in (1, 2, 4, 10, 15):
            log.update(decoded=0, converted=0)
            frames, idx = read_frames(video, n)
            ref = np.linspace(0, 9, n).round().astype(int)
            assert list(idx) == list(ref)
            assert all(np.array_equal(a, everything[i]) for a, i in zip(frames, ref, strict=True))
            if stated is None:  # the count is right: only the picked frames are converted, and n = 1 stops at once
                assert log["converted"] == len(set(ref.tolist()))
                assert log["decoded"] == (1 if n == 1 else 10)
