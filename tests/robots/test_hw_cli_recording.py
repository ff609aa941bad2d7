"""A recording never loses a finished episode: lerobot-record with the emulated gripper and glove, cut by a real
SIGKILL and by a real full disk (a small tmpfs), then `blindgrasp-repair-dataset`, LeRobot's own loader and
`lerobot-record --resume=true`; and the free-space refusal before an episode starts (`recording_space.py`)."""

from __future__ import annotations

import json
import os
import re
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest
from dynamixel_sdk.robotis_def import INST_SYNC_WRITE as SYNC_WRITE
from emulators.glove_sender import GloveEmulator
from emulators.harness import BIN, Operator
from emulators.rig import GripperRig
from test_hw_cli import REPO_ID, _record_cmd, _run

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.robots.blindgrasp_gripper.recording_space import episode_bytes

pytestmark = pytest.mark.slow
EPISODE_S = 0.5  # 10 frames at 20 Hz: short, and several control periods to cut into


@pytest.fixture
def small_disk(tmp_path):
    """A real filesystem of 1 MiB, enough for the episodes and small enough to fill in a moment."""
    disk = tmp_path / "disk"
    disk.mkdir()
    mounted = (
        os.geteuid() == 0
        and subprocess.run(
            ["mount", "-t", "tmpfs", "-o", "size=1024k", "tmpfs", str(disk)], capture_output=True
        ).returncode
        == 0
    )
    if not mounted:
        pytest.skip("needs root to mount a 1 MiB tmpfs (a real full disk); mount was not permitted here")
    yield disk
    subprocess.run(["umount", "-l", str(disk)], capture_output=True)


def _fill(disk: Path) -> Path:
    """Write zeros until the filesystem refuses: ENOSPC, as a disk that fills during an episode."""
    filler = disk / "filler"
    fd = os.open(filler, os.O_WRONLY | os.O_CREAT)
    try:
        while True:
            os.write(fd, b"\0" * 4096)
    except OSError as e:
        assert e.errno == 28, e
    finally:
        os.close(fd)
    return filler


def _into_episode(rig: GripperRig, op: Operator, n: int) -> None:
    """Wait for episode n's announcement, then for 3 more control periods: its start check has run."""
    op.expect(f"Recording episode {n}", timeout_s=120)
    counts = rig.dxl.instruction_counts
    base = counts.get(SYNC_WRITE, 0)
    deadline = time.monotonic() + 60
    while counts.get(SYNC_WRITE, 0) < base + 3:
        assert op.proc.poll() is None and time.monotonic() < deadline, op.text[-3000:]
        time.sleep(0.01)


def _repair(root: Path, env: dict) -> str:
    res = _run([str(BIN / "blindgrasp-repair-dataset"), f"--root={root}"], env)
    return res.stdout


def _loaded_lengths(root: Path) -> list[int]:
    """Episode lengths as LeRobot's own loader reads them, checked against the frames it returns."""
    from lerobot.datasets import LeRobotDataset

    ds = LeRobotDataset(REPO_ID, root=root)
    per_episode = np.bincount([int(ds[i]["episode_index"]) for i in range(len(ds))], minlength=ds.num_episodes)
    lengths = [int(n) for n in ds.meta.episodes["length"]]
    assert per_episode.tolist() == lengths and ds.num_frames == sum(lengths)
    return lengths


def _size(root: Path) -> int:
    return sum(p.stat().st_size for p in root.rglob("*") if p.is_file())


def _resume_one_more(port: int, root: Path, env: dict, before: list[int]) -> None:
    """`lerobot-record --resume=true` records one more episode after the repaired ones, which stay as they were.
    What that episode adds to the folder is within the free-space estimate (`recording_space.episode_bytes`)."""
    size = _size(root)
    with GripperRig() as rig, GloveEmulator(port) as glove:
        rig.hand_move(spec.HOME_POSE)
        glove.closure = 0.3
        _run([*_record_cmd(rig, glove, root, episodes=1, episode_s=EPISODE_S), "--resume=true"], env)
        assert not rig.dxl.any_torque()
    after = _loaded_lengths(root)
    assert after[: len(before)] == before and len(after) == len(before) + 1
    features = {k: {**v, "shape": tuple(v["shape"])} for k, v in _features(root).items()}
    assert 0 < _size(root) - size <= episode_bytes(features, spec.CONTROL_HZ, EPISODE_S)


def test_a_sigkill_after_the_first_episode_loses_nothing_finished(station, tmp_path):
    """SIGKILL at episode 1's start: LeRobot has written episode 0's frames (footerless file) and info.json, but
    its episode row is still in memory. The repair rebuilds it; the loader then sees episode 0 whole."""
    _, env, port = station
    root = tmp_path / "ds"
    with GripperRig() as rig, GloveEmulator(port) as glove:
        rig.hand_move(spec.HOME_POSE)
        glove.closure = 0.3
        op = Operator(_record_cmd(rig, glove, root, episodes=3, episode_s=EPISODE_S), env)
        _into_episode(rig, op, 1)
        op.proc.kill()
        op.wait(30)
    claimed = json.loads((root / "meta/info.json").read_text())
    assert claimed["total_episodes"] == 1 and not list((root / "meta").glob("episodes/*/*.parquet"))
    out = _repair(root, env)
    assert "rebuilt the metadata from the data: 1 finished episodes" in out and "no footer" in out, out
    lengths = _loaded_lengths(root)
    assert lengths == [claimed["total_frames"]]  # every frame LeRobot counted for episode 0
    assert "nothing was changed" in _repair(root, env)  # a second repair is a no-op
    _resume_one_more(port, root, env, lengths)


def test_a_disk_that_fills_during_an_episode_loses_nothing_finished(station, small_disk):
    """The disk fills during episode 1: its save fails (ENOSPC), finalize() leaves the episode metadata 0 bytes
    long, the torque goes off. Once space is freed, the repair keeps every whole episode, sets the cut bytes
    aside, and recording resumes."""
    _, env, port = station
    root = small_disk / "ds"
    with GripperRig() as rig, GloveEmulator(port) as glove:
        rig.hand_move(spec.HOME_POSE)
        glove.closure = 0.3
        op = Operator(_record_cmd(rig, glove, root, episodes=2, episode_s=EPISODE_S), env)
        _into_episode(rig, op, 1)
        filler = _fill(small_disk)
        assert op.wait(120) != 0 and "No space left on device" in op.text, op.text[-3000:]
        assert not rig.dxl.any_torque()
    meta_files = list((root / "meta").glob("episodes/*/*.parquet"))
    assert [p.stat().st_size for p in meta_files] == [0]  # what LeRobot 0.6.1 leaves (docs/upstream/)
    claimed = json.loads((root / "meta/info.json").read_text())
    filler.unlink()  # the operator frees space
    out = _repair(root, env)
    assert "an unfinished write" in out, out
    assert (small_disk / "ds.set-aside" / "data/chunk-000/file-000.parquet").is_file()
    lengths = _loaded_lengths(root)
    # Every episode LeRobot counted in info.json before the disk failed it, frame for frame. How far episode 1's
    # save got depends on the slack in the files' last pages (its frames, then info.json, may still fit): an
    # episode whose frames are whole is kept even when LeRobot never counted it, and the report says how many.
    counted = claimed["total_episodes"]
    assert counted >= 1 and len(lengths) in (counted, counted + 1) and len(lengths) <= 2
    assert sum(lengths[:counted]) == claimed["total_frames"]
    assert f"rebuilt the metadata from the data: {len(lengths)} finished episodes ({sum(lengths)} frames)" in out
    _resume_one_more(port, root, env, lengths)


def test_no_episode_starts_without_room_for_it(station, small_disk):
    """A 600 s episode needs more than the 1 MiB disk has: refused at its start with the numbers, torque off."""
    _, env, port = station
    root = small_disk / "ds"
    with GripperRig() as rig, GloveEmulator(port) as glove:
        rig.hand_move(spec.HOME_POSE)
        glove.closure = 0.3
        op = Operator(_record_cmd(rig, glove, root, episodes=1, episode_s=600), env)
        try:
            assert op.wait(120) != 0, op.text[-3000:]
        finally:
            op.proc.kill()
        assert not rig.dxl.any_torque()
    m = re.search(r"Refused to start the next recording episode: (\d+) bytes free on the filesystem of (\S+) "
                  r"\(dataset (\S+)\), the episode needs up to (\d+) bytes", op.text)  # fmt: skip
    assert m, op.text[-3000:]
    free, where, dataset, need = int(m[1]), m[2], m[3], int(m[4])
    features = {k: {**v, "shape": tuple(v["shape"])} for k, v in _features(root).items()}
    assert need == episode_bytes(features, spec.CONTROL_HZ, 600) and free < 1024 * 1024 < need
    assert Path(where) == root and Path(dataset) == root
    assert "Torque is off on all servos" in op.text


def _features(root: Path) -> dict:
    return json.loads((root / "meta/info.json").read_text())["features"]
