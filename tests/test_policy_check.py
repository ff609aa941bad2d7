"""The policy is an input too (`robots/blindgrasp_gripper/policy_check.py`): a checkpoint trained for another robot
is refused before any servo takes torque, with a message naming what differs and the file it was read from.

The checkpoints are the shipped student's own files (config, processors, train config) with one fact changed, and
a training dataset's `meta/info.json` as LeRobot writes it."""

from __future__ import annotations

import json
import logging
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from emulators.fixtures import rig, robot  # noqa: F401  (fixtures)
from emulators.harness import BIN, cli_env

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.demos.dataset import ROBOT_TYPE
from lerobot_blindgrasp.robots.blindgrasp_gripper import BlindgraspGripper, policy_check
from lerobot_blindgrasp.robots.blindgrasp_gripper.errors import PolicyMismatchError

SHIPPED = Path(__file__).resolve().parents[1] / "models" / "student_cpu"
ROBOT = policy_check.gripper_contract(ROBOT_TYPE, 20, "--env.fps")


def _info(root: Path, *, robot_type=ROBOT_TYPE, fps=20, state=spec.STATE_NAMES, action=spec.ACTION_NAMES) -> None:
    features = {
        "observation.state": {"dtype": "float32", "shape": [len(state)], "names": list(state)},
        "action": {"dtype": "float32", "shape": [len(action)], "names": list(action)},
    }
    (root / "meta").mkdir(parents=True, exist_ok=True)
    (root / "meta" / "info.json").write_text(
        json.dumps({"robot_type": robot_type, "fps": fps, "features": features})
    )


def _checkpoint(tmp_path: Path, *, action_dim: int = spec.ACTION_DIM, dataset: dict | None = None) -> Path:
    """The shipped student's checkpoint files, trained (says its train config) on the dataset at tmp/data."""
    ckpt = tmp_path / "pretrained_model"
    shutil.copytree(SHIPPED, ckpt)
    cfg = json.loads((ckpt / "config.json").read_text())
    cfg["output_features"]["action"]["shape"] = [action_dim]
    (ckpt / "config.json").write_text(json.dumps(cfg))
    train = json.loads((ckpt / "train_config.json").read_text())
    train["dataset"]["root"] = str(tmp_path / "data")
    train["dataset"]["repo_id"] = "test/missing"
    (ckpt / "train_config.json").write_text(json.dumps(train))
    _info(tmp_path / "data", **(dataset or {}))
    return ckpt


def test_a_checkpoint_for_this_robot_passes(tmp_path):
    assert policy_check.problems(_checkpoint(tmp_path), ROBOT) == ([], [])


def test_another_hands_checkpoint_is_refused_naming_names_type_and_file(tmp_path):
    other = tuple(f"allegro_j{i}.pos" for i in range(9)) + ("f0", "f1", "f2")
    ckpt = _checkpoint(tmp_path, dataset={"robot_type": "allegro_hand", "state": other, "action": other[:9]})
    with pytest.raises(PolicyMismatchError) as e:
        policy_check.check(ckpt, ROBOT)
    text = str(e.value)
    info = str(tmp_path / "data" / "meta" / "info.json")
    assert f"robot type 'allegro_hand' in {info}, the robot is 'blindgrasp_gripper'" in text
    assert "'observation.state' names ['allegro_j0.pos'" in text and "'action' names" in text
    assert "Nothing was moved" in text


def test_a_state_in_another_order_is_refused(tmp_path):
    swapped = (spec.STATE_NAMES[1], spec.STATE_NAMES[0], *spec.STATE_NAMES[2:])
    bad, _ = policy_check.problems(_checkpoint(tmp_path, dataset={"state": swapped}), ROBOT)
    info = tmp_path / "data/meta/info.json"
    assert bad == [
        f"'observation.state' names {list(swapped)} in {info}, the robot's are {list(spec.STATE_NAMES)} (names and order)"
    ]


def test_a_checkpoint_trained_at_another_rate_is_refused(tmp_path):
    bad, _ = policy_check.problems(_checkpoint(tmp_path, dataset={"fps": 10}), ROBOT)
    assert bad == [f"fps 10 in {tmp_path / 'data/meta/info.json'}, the loop runs at 20 (--env.fps)"]


def test_the_wrong_action_size_says_action(tmp_path):
    bad, _ = policy_check.problems(_checkpoint(tmp_path, action_dim=8), ROBOT)
    assert bad == [
        f"'action' shape (8,) in {tmp_path / 'pretrained_model/config.json'} (output_features), the robot has (9,)"
    ]


def test_relative_actions_sent_to_a_target_robot_are_refused(tmp_path):
    ckpt = _checkpoint(tmp_path)
    pre = json.loads((ckpt / "policy_preprocessor.json").read_text())
    pre["steps"].insert(0, {"registry_name": "relative_actions_processor", "config": {}})
    (ckpt / "policy_preprocessor.json").write_text(json.dumps(pre))
    bad, _ = policy_check.problems(ckpt, ROBOT)
    assert len(bad) == 1 and bad[0].startswith("'action' meaning:") and "absolute joint targets" in bad[0]


def test_missing_dataset_metadata_is_reported_as_unverified(tmp_path, caplog):
    ckpt = _checkpoint(tmp_path)
    shutil.rmtree(tmp_path / "data")
    with caplog.at_level(logging.WARNING):
        policy_check.check(ckpt, ROBOT)
    assert "could not verify robot type, fps and feature names" in caplog.text


def test_send_action_refuses_unknown_keys_as_it_refuses_missing_ones(rig, robot):
    before = dict(rig.dxl.instruction_counts)
    action = {**dict.fromkeys(spec.ACTION_NAMES, 0.0), "extra_j99.pos": 0.1}
    with pytest.raises(KeyError, match=r"unknown keys \['extra_j99.pos'\].*Nothing was sent"):
        robot.send_action(action)
    assert rig.dxl.instruction_counts == before and robot.is_connected


def test_a_mismatch_on_the_command_line_is_refused_before_the_ports_open(rig, tmp_path, monkeypatch):
    """lerobot-rollout (or any CLI) with --policy.path: the robot checks it at connect, before a byte is sent."""
    ckpt = _checkpoint(tmp_path, dataset={"fps": 10})
    monkeypatch.setattr(sys, "argv", ["lerobot-rollout", f"--policy.path={ckpt}", "--fps=10"])
    robot = BlindgraspGripper(rig.robot_config(tmp_path / "cal"))
    with pytest.raises(PolicyMismatchError, match=r"--fps=10 but the robot's loop_hz is 20"):
        robot.connect()
    assert rig.dxl.instruction_counts == {} and not robot.is_connected


def test_lerobot_eval_refuses_a_mismatching_checkpoint_before_any_torque(rig, tmp_path):
    ckpt = _checkpoint(tmp_path, action_dim=8)
    cmd = [
        str(BIN / "lerobot-eval"),
        f"--policy.path={ckpt}",
        "--env.type=blindgrasp_real",
        "--env.robot.type=blindgrasp_gripper",
        f"--env.robot.port={rig.dxl.port}",
        f"--env.robot.force_sensor.port={rig.force.port}",
        "--env.robot.id=rig",
        "--env.task=foam_brick",
        "--env.success_mode=force",
        "--eval.n_episodes=1",
        "--eval.batch_size=1",
        "--eval.use_async_envs=false",
        f"--output_dir={tmp_path / 'eval'}",
    ]
    out = subprocess.run(cmd, env=cli_env(tmp_path), capture_output=True, text=True, timeout=180)
    assert out.returncode != 0
    assert "'action' shape (8,)" in out.stdout + out.stderr and "size mismatch" not in out.stdout + out.stderr
    assert rig.dxl.instruction_counts == {} and not rig.dxl.any_torque()  # not one packet reached the servos


def test_blindgrasp_rollout_refuses_a_policy_trained_at_another_rate_before_any_torque(rig, tmp_path):
    """blindgrasp-rollout: checked before LeRobot's rollout context loads the policy or connects the robot."""
    ckpt = _checkpoint(tmp_path, dataset={"fps": 10})
    cmd = [
        str(BIN / "python"), "-m", "lerobot_blindgrasp.robots.blindgrasp_gripper.rollout", "--strategy.type=base",
        f"--policy.path={ckpt}", "--policy.device=cpu", "--device=cpu", "--robot.type=blindgrasp_gripper",
        f"--robot.port={rig.dxl.port}", "--robot.id=rig", f"--robot.force_sensor.port={rig.force.port}",
        "--fps=20", "--duration=1", "--task=grasp", "--play_sounds=false",
    ]  # fmt: skip
    out = subprocess.run(cmd, env=cli_env(tmp_path), capture_output=True, text=True, timeout=180)
    assert out.returncode != 0
    assert f"fps 10 in {tmp_path / 'data/meta/info.json'}, the loop runs at 20 (--fps)" in out.stdout + out.stderr
    assert rig.dxl.instruction_counts == {} and not rig.dxl.any_torque()
