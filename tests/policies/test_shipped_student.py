"""The shipped student (models/student_cpu) is what README's first example evaluates: a self-contained LeRobot
pretrained_model folder that plain `lerobot-eval --env.type=blindgrasp` loads and runs."""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

STUDENT = Path(__file__).resolve().parents[2] / "models" / "student_cpu"


def test_the_shipped_student_is_a_complete_pretrained_model_with_a_card():
    names = {p.name for p in STUDENT.iterdir()}
    assert {
        "config.json",
        "model.safetensors",
        "policy_preprocessor.json",
        "policy_postprocessor.json",
        "train_config.json",
        "README.md",
    } <= names
    assert not any(n.endswith((".pt", ".pkl", ".pth")) for n in names)  # weights as safetensors only
    cfg = json.loads((STUDENT / "config.json").read_text())
    assert cfg["type"] == "blindgrasp_transformer" and cfg["size"] == "cpu"
    card = (STUDENT / "README.md").read_text()
    for needle in ("pip install", "lerobot-train", "lerobot-eval", "seed", "%"):
        assert needle in card, needle


@pytest.mark.slow
def test_lerobot_eval_runs_the_shipped_student(tmp_path):
    # Start state 1001 of the large cylinder B: the student lifted it in the recorded 20-episode eval (card) and
    # alone. (Start state 1000, also lifted in the recorded batch of 20, fails at batch size 1 or 2: the batch
    # changes the transformer's float rounding, and a contact-rich rollout amplifies it.) Only the success is
    # compared, not a float: the episode's summed reward drifts between CPU families while its success holds
    # (docs/results/cpu_portability.md, under stand-ins for other families).
    cmd = [
        sys.executable,
        "-m",
        "lerobot.scripts.lerobot_eval",
        f"--policy.path={STUDENT}",
        "--env.type=blindgrasp",
        "--env.task=cylinder_b_large",
        "--eval.n_episodes=1",
        "--eval.batch_size=1",
        "--policy.device=cpu",
        "--eval.use_async_envs=false",
        "--env.render_stride=50",
        f"--output_dir={tmp_path / 'eval'}",
        "--seed=1001",
    ]
    subprocess.run(
        cmd,
        check=True,
        capture_output=True,
        text=True,
        timeout=600,
        env={**os.environ, "OMP_NUM_THREADS": "1", "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")},
    )
    info = json.loads((tmp_path / "eval" / "eval_info.json").read_text())
    assert info["overall"]["n_episodes"] == 1
    assert info["per_task"][0]["metrics"]["successes"] == [True]
