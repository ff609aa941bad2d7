"""End to end with LeRobot's own CLIs: lerobot-train a tiny `blindgrasp_transformer`, then lerobot-eval it in sim.

Both run as real subprocesses with no plugin flags (discovery through the `lerobot_policy_blindgrasp`
distribution), offline, headless. The dataset is a few scripted lifts recorded through the eval env itself, so its
`observation.state` / `action` are exactly what the env emits and accepts.
"""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest
from emulators.harness import BIN, tiny_student_train

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.envs.sim_env import task_id
from lerobot_blindgrasp.sim import gym_env, objects, randomization
from lerobot_blindgrasp.sim.scripted import PinchLiftScript
from lerobot_blindgrasp.sim.viewer import grasp_geometry

pytestmark = pytest.mark.slow  # ~40 s: two CLI subprocesses and 4 rendered 10 s episodes

OBJECTS = ("cylinder_a_medium", "sphere_small")
TRAIN_STEPS = 4


def _env() -> dict[str, str]:
    return {
        **os.environ,
        "HF_HUB_OFFLINE": "1",  # nothing may download
        "HF_DATASETS_OFFLINE": "1",
        "MUJOCO_GL": "egl",
        "WANDB_MODE": "disabled",
        "OMP_NUM_THREADS": "1",  # a shared 2-core machine
    }


def _run(cmd: list[str], timeout: int) -> subprocess.CompletedProcess:
    res = subprocess.run(cmd, env=_env(), capture_output=True, text=True, timeout=timeout)
    assert res.returncode == 0, f"{cmd[0]} failed:\n{res.stdout[-3000:]}\n{res.stderr[-6000:]}"
    return res


def _make_dataset(root: Path, repo_id: str) -> None:
    """Two short scripted lifts per object, recorded as lerobot-record would (state before, target after)."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    ds = LeRobotDataset.create(repo_id, fps=spec.CONTROL_HZ, features=spec.dataset_features(), root=root,
                               use_videos=False)  # fmt: skip
    for k, name in enumerate(OBJECTS):
        env = gym_env.BlindGraspGymEnv(name, dr=randomization.CENTRED_EVAL_DR, render_mode=None)
        for seed in range(2):
            obs, _ = env.reset(seed=10 * k + seed)
            script = PinchLiftScript(*grasp_geometry(name))
            for t in range(40):
                target = script.target(t).astype(np.float32)
                ds.add_frame({spec.STATE_KEY: obs["agent_pos"], spec.ACTION_KEY: target,
                              "task": objects.get_object(name).task})  # fmt: skip
                obs, *_ = env.step(target)
            ds.save_episode()
    ds.finalize()


@pytest.fixture(scope="module")
def checkpoint(tmp_path_factory) -> Path:
    tmp = tmp_path_factory.mktemp("cli")
    repo_id = "local/blindgrasp_tiny"
    _make_dataset(tmp / "dataset", repo_id)
    out = tmp / "train"
    _run(
        tiny_student_train(repo_id, tmp / "dataset", out, TRAIN_STEPS, "--log_freq=1"),
        timeout=300,
    )
    ckpt = out / "checkpoints" / f"{TRAIN_STEPS:06d}" / "pretrained_model"
    assert (ckpt / "config.json").is_file() and (ckpt / "model.safetensors").is_file()
    return ckpt


def test_lerobot_eval_reports_per_object_success(checkpoint, tmp_path):
    out = tmp_path / "eval"
    _run(
        [
            str(BIN / "lerobot-eval"),
            f"--policy.path={checkpoint}",
            "--env.type=blindgrasp",
            f"--env.task={','.join(OBJECTS)}",
            "--eval.n_episodes=2",
            "--eval.batch_size=2",
            "--policy.device=cpu",
            f"--output_dir={out}",
        ],
        timeout=400,
    )
    info = json.loads((out / "eval_info.json").read_text())

    # One per_task entry per object, keyed by the object's stable task_id, each with its 2 episodes.
    per_task = {t["task_id"]: t for t in info["per_task"]}
    assert sorted(per_task) == sorted(task_id(n) for n in OBJECTS)
    for entry in per_task.values():
        assert entry["task_group"] == "blindgrasp"
        m = entry["metrics"]
        assert len(m["successes"]) == 2 and all(isinstance(s, bool) for s in m["successes"])
        assert len(m["sum_rewards"]) == 2 and all(np.isfinite(m["sum_rewards"]))
        # Videos render headless: lerobot-eval writes the episodes it rendered as mp4 files.
        assert len(m["video_paths"]) == 2 and all(Path(p).stat().st_size > 1000 for p in m["video_paths"])
    for agg in (info["per_group"]["blindgrasp"], info["overall"]):
        assert agg["n_episodes"] == 2 * len(OBJECTS)
        assert 0.0 <= agg["pc_success"] <= 100.0
    # A few optimizer steps on 160 frames do not make a grasping policy: the honest outcome is failure.
    assert info["overall"]["pc_success"] == 0.0
