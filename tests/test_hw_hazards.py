"""Rows of the hazard analysis (docs/hardware.md, "Hazard analysis") that no other test file holds: the host loop's
timing after a stall, in a loop paced as LeRobot's and in the eval trial, and a second failure during cleanup."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from emulators.fixtures import as_q, rig, robot  # noqa: F401  (fixtures)
from lerobot.utils.robot_utils import precise_sleep

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.envs.real_env import BlindGraspRealEnvConfig
from lerobot_blindgrasp.envs.real_trial import GripperSession, RealGraspEnv

DT = spec.CONTROL_DT


def _sample_times(robot) -> list[float]:
    """When each observation's data was in: the return of get_observation."""
    times: list[float] = []
    observe = robot.get_observation

    def timed():
        obs = observe()
        times.append(time.monotonic())
        return obs

    robot.get_observation = timed
    return times


def _stall(rig, k: int) -> None:
    rig.dxl.reply_delay_s = 0.03 if k in (4, 5) else 0.0  # two steps on a slow bus: ~0.2 s per observation


def test_no_short_step_after_a_stall_in_a_loop_paced_as_lerobots(rig, robot):
    """lerobot-record's and lerobot-rollout's loop: observe, act, sleep the rest of the period from the loop's start.
    After a stalled observation it goes straight on; the robot spaces its samples (`timing.SampleSpacing`)."""
    times = _sample_times(robot)
    for k in range(18):
        start = time.perf_counter()
        rig.dxl.reply_delay_s = 0.04 if k == 5 else 0.0  # the observation alone stalls (> 1 period)
        obs = robot.get_observation()
        rig.dxl.reply_delay_s = 0.0
        robot.send_action(dict(zip(spec.ACTION_NAMES, as_q(obs).tolist(), strict=True)))
        precise_sleep(max(DT - (time.perf_counter() - start), 0.0))
    gaps = np.diff(times)[5:]  # from the stalled observation on
    # The step after the stall was 3-10 ms (a read's time on a loaded host); the spacing keeps >= 0.9 period.
    assert gaps[0] >= 0.8 * DT and gaps.min() >= 0.5 * DT, gaps  # no burst after it either
    assert robot.spacing.waits >= 1


def test_no_short_step_after_a_stall_in_the_eval_trial(rig, tmp_path, monkeypatch):
    monkeypatch.setattr("builtins.input", rig.calibration_inputs())
    cfg = BlindGraspRealEnvConfig(robot=rig.robot_config(tmp_path / "cal"), task="foam_brick", success_mode="force",
                                  unattended_reset_s=0.0, episode_s=5.0)  # fmt: skip
    env = RealGraspEnv(GripperSession(cfg.trial_settings()), "foam_brick")
    try:
        env.reset(seed=0)
        times = _sample_times(env.robot)
        for k in range(16):
            _stall(rig, k)
            env.step(spec.HOME_POSE)
        gaps = np.diff(times)[5:]
        assert gaps[0] >= 0.8 * DT and gaps[1] >= 0.8 * DT and gaps.min() >= 0.5 * DT, gaps
    finally:
        env.close()


def _tmpfs(path: Path, size_kb: int) -> bool:
    if os.geteuid() != 0:
        return False
    path.mkdir(parents=True, exist_ok=True)
    return subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size_kb}k", "tmpfs", str(path)],
                          capture_output=True).returncode == 0  # fmt: skip


def test_a_second_failure_during_cleanup_never_masks_the_first_or_aborts(tmp_path):
    """A disk that fills during demo collection: the stats write fails (the first error), then finalize() fails too
    (the footer write). The run ends with the first error in one message and exit 4, not a chained traceback and
    pyarrow's abort at interpreter shutdown (exit 134)."""
    disk = tmp_path / "small"
    if not _tmpfs(disk, 100):
        pytest.skip("needs root to mount a 100 kB tmpfs (a real full disk)")
    try:
        cmd = [
            sys.executable,
            "-m",
            "lerobot_blindgrasp.demos.collect",
            f"--output_dir={disk / 'demos'}",
            "--repo_id=test/full",
            "--episodes_per_object=4",
            "--num_envs=2",
            "--curation.enabled=false",
            "--objects=cylinder_a_medium,cuboid_a_medium",
            "--progress=false",
            "--threads=1",
            "--checkpoint_s=0",
        ]
        env = {**os.environ, "HF_HUB_OFFLINE": "1", "OMP_NUM_THREADS": "1"}
        out = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=300)
    finally:
        subprocess.run(["umount", "-l", str(disk)], capture_output=True)
    text = out.stdout + out.stderr
    assert out.returncode == 4, text[-3000:]
    assert "Traceback" not in text and "also failed" in text, text[-3000:]
    assert "error: could not write" in text and "the disk is full (ENOSPC)" in text
