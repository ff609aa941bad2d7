"""The recovery of a LeRobot recording without its footers or episode rows, in-process and in seconds (the whole
`lerobot-record` runs are in test_hw_cli_recording.py): the footerless-file reader cut at many byte offsets, the
metadata rebuilt from a writer that was never finalized, and the free-space estimate against real files."""

from __future__ import annotations

import io
import random
import shutil

import numpy as np
import pyarrow.parquet as pq
import pytest

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.demos import rebuild_meta, repair
from lerobot_blindgrasp.demos.parquet_salvage import salvage
from lerobot_blindgrasp.robots.blindgrasp_gripper.recording_space import episode_bytes

TASK = "grasp and lift the medium cylinder a"


def _dataset(root, lengths: list[int], finalize: bool):
    from lerobot.datasets import LeRobotDataset

    ds = LeRobotDataset.create("local/crash", spec.CONTROL_HZ, root=root, features=spec.dataset_features(),
                               use_videos=False)  # fmt: skip
    _episodes(ds, lengths, start=0)
    if finalize:
        ds.finalize()
    return ds


def _episodes(ds, lengths: list[int], start: int) -> None:
    rng = np.random.default_rng(start)  # distinct floats: parquet's dictionary pages at their largest
    for n in lengths:
        for _ in range(n):
            ds.add_frame({spec.STATE_KEY: rng.normal(size=12).astype(np.float32),
                          spec.ACTION_KEY: rng.normal(size=9).astype(np.float32), "task": TASK})  # fmt: skip
        ds.save_episode()


def test_salvage_keeps_exactly_the_complete_row_groups_wherever_the_file_is_cut(tmp_path):
    """A finalized file, cut at every row-group boundary (and one byte either side) and at 200 seeded offsets: the
    reader returns the row groups wholly before the cut, equal to the originals, and sets the rest aside."""
    lengths = [7, 12, 9]
    _dataset(tmp_path / "ds", lengths, finalize=True)
    path = next((tmp_path / "ds" / "data").rglob("*.parquet"))
    whole, meta = path.read_bytes(), pq.ParquetFile(path).metadata
    table = pq.read_table(path)
    starts = [meta.row_group(i).column(0).dictionary_page_offset for i in range(meta.num_row_groups)]
    footer_at = len(whole) - 8 - int.from_bytes(whole[-8:-4], "little")
    ends = [*starts[1:], footer_at]
    cuts = {c + d for c in ends for d in (-1, 0, 1)} | set(random.Random(0).sample(range(4, footer_at), 200))
    template = rebuild_meta._template(_features(tmp_path / "ds"))
    for cut in sorted(cuts):
        fixed, rows, aside = salvage(whole[:cut], template)
        kept = sum(n for n, end in zip(lengths, ends) if end <= cut)
        assert rows == kept, cut
        got = pq.read_table(io.BytesIO(fixed))
        assert got.num_rows == kept and got.equals(table.slice(0, kept)), cut
        assert aside == cut - max([4] + [e for e in ends if e <= cut]), cut


def _features(root) -> dict:
    from lerobot.datasets.io_utils import load_info

    return load_info(root).features


def test_a_writer_never_finalized_keeps_every_saved_episode_and_resumes(tmp_path):
    """The folder as a SIGKILL leaves it after 3 saved episodes (copied while LeRobot's writers are still open):
    footerless data, no episode rows. Repaired, LeRobot loads all 3; resumed, it appends a 4th."""
    from lerobot.datasets import LeRobotDataset

    lengths = [5, 8, 6]
    live = _dataset(tmp_path / "live", lengths, finalize=False)
    crashed = tmp_path / "crashed"
    shutil.copytree(tmp_path / "live", crashed)
    live.finalize()
    with pytest.raises(Exception):  # noqa: B017  (LeRobot's own error for the footerless file, whatever its type)
        LeRobotDataset("local/crash", root=crashed)
    report = repair.repair(crashed)
    assert report.rebuilt is not None and report.kept_episodes == 3, report.summary()
    ds = LeRobotDataset("local/crash", root=crashed)
    assert [int(n) for n in ds.meta.episodes["length"]] == lengths and ds.num_frames == sum(lengths)
    good = LeRobotDataset("local/crash", root=tmp_path / "live")
    for i in (0, sum(lengths) - 1):  # the rebuilt frames and stats are the finalized writer's
        np.testing.assert_array_equal(ds[i][spec.STATE_KEY], good[i][spec.STATE_KEY])
    for key in (spec.STATE_KEY, spec.ACTION_KEY):
        np.testing.assert_allclose(ds.meta.stats[key]["mean"], good.meta.stats[key]["mean"], rtol=1e-6)
    assert not repair.repair(crashed).changed
    resumed = LeRobotDataset.resume("local/crash", root=crashed)
    _episodes(resumed, [4], start=3)
    resumed.finalize()
    assert LeRobotDataset("local/crash", root=crashed).num_episodes == 4


def test_the_estimate_bounds_what_an_episode_adds(tmp_path):
    """`episode_bytes` against the bytes one more finalized episode of distinct floats really adds to the folder."""
    sizes = []
    for n in (1, 2):
        _dataset(tmp_path / f"ds{n}", [40] * n, finalize=True)
        sizes.append(sum(p.stat().st_size for p in (tmp_path / f"ds{n}").rglob("*") if p.is_file()))
    features = _features(tmp_path / "ds2")
    assert 0 < sizes[1] - sizes[0] <= episode_bytes(features, spec.CONTROL_HZ, 40 / spec.CONTROL_HZ)


class _Killed(BaseException):
    """The process dies here: no handler runs (a BaseException that no `except Exception` catches)."""


def _repair_killed_at(root, k: int, monkeypatch) -> bool:
    """Run the repair, killed at its k-th rename or link; True when it finished before that."""
    import os

    real = {name: getattr(os, name) for name in ("replace", "link")}
    calls = [0]

    def dying(name, *args, **kwargs):
        if calls[0] == k:
            raise _Killed
        calls[0] += 1
        return real[name](*args, **kwargs)

    for name in real:
        monkeypatch.setattr(os, name, lambda *a, _n=name, **kw: dying(_n, *a, **kw))
    try:
        repair.repair(root)
        return True
    except _Killed:
        return False
    finally:
        for name, fn in real.items():
            monkeypatch.setattr(os, name, fn)


def test_a_repair_killed_at_any_rename_is_finished_by_running_it_again(tmp_path, monkeypatch):
    """The repair's every rename or link (where its files change) is a kill point: killed at the k-th one, for
    every k, the dataset is finished by the next run and loads with every saved episode."""
    from lerobot.datasets import LeRobotDataset

    lengths = [5, 8]
    live = _dataset(tmp_path / "live", lengths, finalize=False)
    shutil.copytree(tmp_path / "live", tmp_path / "crashed")
    live.finalize()
    k, finished = 0, False
    while not finished:
        root = tmp_path / f"kill{k}"
        shutil.copytree(tmp_path / "crashed", root)
        finished = _repair_killed_at(root, k, monkeypatch)
        repair.repair(root)
        ds = LeRobotDataset("local/crash", root=root)
        assert [int(n) for n in ds.meta.episodes["length"]] == lengths, k
        k += 1
    assert k >= 5  # the data rewrite, the episode rows, stats.json and info.json at least
