"""The policy is an input too (`policy_contract.py`): a checkpoint trained for another robot
is refused before any servo takes torque, with a message naming what differs and the file it was read from.

The checkpoints are the shipped student's own files (config with its `trained_for`, processors, normalizer
statistics, weights, train config) with one fact changed, or without `trained_for` and with a training dataset's
`meta/info.json` as LeRobot writes it."""

from __future__ import annotations

import json
import logging
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from emulators.harness import BIN, cli_env

from lerobot_blindgrasp import policy_contract, spec
from lerobot_blindgrasp.demos.dataset import ROBOT_TYPE
from lerobot_blindgrasp.policy_contract import PolicyMismatchError
from lerobot_blindgrasp.robots.blindgrasp_gripper import BlindgraspGripper

SHIPPED = Path(__file__).resolve().parents[2] / "models" / "student_cpu"
ROBOT = policy_contract.gripper_contract(ROBOT_TYPE, 20, "--env.fps")


def _info(root: Path, *, robot_type=ROBOT_TYPE, fps=20, state=spec.STATE_NAMES, action=spec.ACTION_NAMES) -> None:
    features = {
        "observation.state": {"dtype": "float32", "shape": [spec.STATE_DIM], "names": None if state is None else list(state)},
        "action": {"dtype": "float32", "shape": [len(spec.ACTION_NAMES)], "names": None if action is None else list(action)},
    }  # fmt: skip
    (root / "meta").mkdir(parents=True, exist_ok=True)
    (root / "meta" / "info.json").write_text(
        json.dumps({"robot_type": robot_type, "fps": fps, "features": features})
    )


def _edit(path: Path, change) -> None:
    data = json.loads(path.read_text())
    change(data)
    path.write_text(json.dumps(data))


def _checkpoint(
    tmp_path: Path,
    *,
    action_dim: int = spec.ACTION_DIM,
    trained_for: dict | None = None,
    dataset: dict | None = None,
) -> Path:
    """The shipped student's checkpoint files with one fact changed: `trained_for` (what config.json says it was
    trained for) updated with `trained_for`, or, with `dataset`, removed (a checkpoint from before it was recorded)
    and its training dataset's meta/info.json written at tmp/data."""
    ckpt = tmp_path / "pretrained_model"
    shutil.copytree(SHIPPED, ckpt)

    def config(cfg):
        cfg["output_features"]["action"]["shape"] = [action_dim]
        if dataset is not None:
            del cfg["trained_for"]
        else:
            cfg["trained_for"].update(trained_for or {})

    def train(train):
        train["dataset"]["root"] = str(tmp_path / "data")
        train["dataset"]["repo_id"] = "test/missing"

    _edit(ckpt / "config.json", config)
    _edit(ckpt / "train_config.json", train)
    if dataset is not None:
        _info(tmp_path / "data", **dataset)
    return ckpt


def test_a_checkpoint_for_this_robot_passes(tmp_path):
    assert policy_contract.checkpoint_problems(_checkpoint(tmp_path), ROBOT) == ([], [])
    assert policy_contract.checkpoint_problems(_checkpoint(tmp_path / "old", dataset={}), ROBOT) == ([], [])


def test_another_hands_checkpoint_is_refused_naming_names_type_and_file(tmp_path):
    other = [f"allegro_j{i}.pos" for i in range(9)] + ["f0", "f1", "f2"]
    ckpt = _checkpoint(tmp_path, trained_for={"robot_type": "allegro_hand", "state_names": other,
                                              "action_names": other[:9]})  # fmt: skip
    with pytest.raises(PolicyMismatchError) as e:
        policy_contract.check_checkpoint(ckpt, ROBOT)
    text = str(e.value)
    assert f"robot type 'allegro_hand' in {ckpt / 'config.json'} (trained_for (the sim demo schema" in text
    assert "the robot is 'blindgrasp_gripper'" in text
    assert "'observation.state' names ['allegro_j0.pos'" in text and "'action' names" in text
    assert "Nothing was moved" in text


def test_a_state_in_another_order_is_refused(tmp_path):
    swapped = [spec.STATE_NAMES[1], spec.STATE_NAMES[0], *spec.STATE_NAMES[2:]]
    bad, _ = policy_contract.checkpoint_problems(
        _checkpoint(tmp_path, trained_for={"state_names": swapped}), ROBOT
    )
    assert len(bad) == 1 and bad[0].startswith(f"'observation.state' names {swapped} in ")
    assert bad[0].endswith(f"the robot's are {list(spec.STATE_NAMES)} (names and order)")


def test_a_checkpoint_trained_at_another_rate_is_refused(tmp_path):
    bad, _ = policy_contract.checkpoint_problems(_checkpoint(tmp_path, trained_for={"fps": 10}), ROBOT)
    assert len(bad) == 1 and bad[0].startswith("fps 10 in ") and bad[0].endswith("the loop runs at 20 (--env.fps)")
    bad, _ = policy_contract.checkpoint_problems(_checkpoint(tmp_path / "old", dataset={"fps": 10}), ROBOT)
    assert bad == [f"fps 10 in {tmp_path / 'old/data/meta/info.json'}, the loop runs at 20 (--env.fps)"]


def test_the_wrong_action_size_says_action(tmp_path):
    bad, _ = policy_contract.checkpoint_problems(_checkpoint(tmp_path, action_dim=8), ROBOT)
    assert bad == [
        f"'action' shape (8,) in {tmp_path / 'pretrained_model/config.json'} (output_features), the robot has (9,)"
    ]


def test_a_camera_input_the_robot_does_not_have_is_refused(tmp_path):
    """An extra `observation.images.*` input: LeRobot's checks of the config pass it (shapes only)."""
    ckpt = _checkpoint(tmp_path)
    _edit(ckpt / "config.json", lambda c: c["input_features"].update(
        {"observation.images.top": {"type": "VISUAL", "shape": [3, 96, 96]}}))  # fmt: skip
    bad, _ = policy_contract.checkpoint_problems(ckpt, ROBOT)
    assert bad == [f"input_features ['observation.images.top'] in {ckpt / 'config.json'}: the robot has only "
                   "'observation.state' there (no camera)"]  # fmt: skip


def test_a_checkpoint_trained_with_another_env_is_refused(tmp_path):
    ckpt = _checkpoint(tmp_path)
    _edit(ckpt / "train_config.json", lambda t: t.update(env={"type": "aloha", "fps": 50}))
    bad, _ = policy_contract.checkpoint_problems(ckpt, ROBOT)
    assert f"env type 'aloha' in {ckpt / 'train_config.json'}, this robot's envs are" in bad[0]
    assert bad[1].startswith("fps 50 in ") and len(bad) == 2


def test_relative_actions_sent_to_a_target_robot_are_refused(tmp_path):
    ckpt = _checkpoint(tmp_path)
    _edit(ckpt / "policy_preprocessor.json",
          lambda p: p["steps"].insert(0, {"registry_name": "relative_actions_processor", "config": {}}))  # fmt: skip
    bad, _ = policy_contract.checkpoint_problems(ckpt, ROBOT)
    assert len(bad) == 1 and bad[0].startswith("'action' meaning:") and "absolute joint targets" in bad[0]
    bad, _ = policy_contract.checkpoint_problems(
        _checkpoint(tmp_path / "d", trained_for={"action_meaning": "deltas (rad)"}), ROBOT
    )
    assert len(bad) == 1 and bad[0].startswith("'action' meaning 'deltas (rad)' in ")


def test_an_unverifiable_checkpoint_is_refused_unless_overridden(tmp_path, caplog):
    """No trained_for and no dataset metadata on this machine: refused by default, run with a warning when the
    operator says so (`--robot.allow_unverified_policy=true`)."""
    ckpt = _checkpoint(tmp_path, dataset={})
    shutil.rmtree(tmp_path / "data")
    with pytest.raises(PolicyMismatchError, match=r"cannot be verified .* has no trained_for, and the training "
                       r"dataset's meta/info.json .* not found.*allow_unverified_policy=true"):  # fmt: skip
        policy_contract.check_checkpoint(ckpt, ROBOT)
    with caplog.at_level(logging.WARNING):
        policy_contract.check_checkpoint(ckpt, ROBOT, allow_unverified=True)
    assert "could not verify robot type, fps and feature names" in caplog.text


def test_dataset_metadata_without_feature_names_does_not_pass_silently(tmp_path):
    bad, unverified = policy_contract.checkpoint_problems(
        _checkpoint(tmp_path, dataset={"state": None, "action": None}), ROBOT
    )
    info = tmp_path / "data/meta/info.json"
    assert bad == [] and unverified == [
        f"'observation.state' names: not in {info}",
        f"'action' names: not in {info}",
    ]


def test_lerobot_train_records_what_the_policy_was_trained_for(tmp_path):
    """make_policy, as lerobot-train calls it with the training dataset's metadata: config.json then says what the
    checkpoint was trained for, and the robot's check passes on it with no dataset at hand."""
    from lerobot.datasets import LeRobotDatasetMetadata
    from lerobot.policies.factory import make_policy

    from lerobot_blindgrasp.policies.blindgrasp_transformer import BlindgraspTransformerConfig

    meta = LeRobotDatasetMetadata.create("test/tiny", 20, spec.dataset_features(), robot_type=ROBOT_TYPE,
                                         root=tmp_path / "data", use_videos=False)  # fmt: skip
    cfg = BlindgraspTransformerConfig(size="quick", n_layers=1, embed_dim=32, head_hidden_dims=[32], device="cpu")
    policy = make_policy(cfg, ds_meta=meta)
    policy.save_pretrained(tmp_path / "ckpt")
    for name in ("policy_preprocessor.json", "policy_postprocessor.json", "train_config.json"):
        shutil.copy(SHIPPED / name, tmp_path / "ckpt" / name)
    _edit(tmp_path / "ckpt" / "train_config.json", lambda t: t["dataset"].update(root=None, repo_id="test/gone"))
    for name in SHIPPED.glob("policy_*.safetensors"):
        shutil.copy(name, tmp_path / "ckpt" / name.name)
    facts = json.loads((tmp_path / "ckpt" / "config.json").read_text())["trained_for"]
    assert facts["robot_type"] == ROBOT_TYPE and facts["fps"] == 20 and facts["source"].endswith("test/tiny")
    assert facts["state_names"] == list(spec.STATE_NAMES) and facts["action_names"] == list(spec.ACTION_NAMES)
    assert policy_contract.checkpoint_problems(tmp_path / "ckpt", ROBOT) == ([], [])


def test_send_action_refuses_unknown_keys_as_it_refuses_missing_ones(rig, robot):
    before = dict(rig.dxl.instruction_counts)
    action = {**dict.fromkeys(spec.ACTION_NAMES, 0.0), "extra_j99.pos": 0.1}
    with pytest.raises(KeyError, match=r"unknown keys \['extra_j99.pos'\].*Nothing was sent"):
        robot.send_action(action)
    assert rig.dxl.instruction_counts == before and robot.is_connected


def test_a_mismatch_on_the_command_line_is_refused_before_the_ports_open(rig, tmp_path, monkeypatch):
    """lerobot-rollout (or any CLI) with --policy.path: the robot checks it at connect, before a byte is sent."""
    ckpt = _checkpoint(tmp_path, trained_for={"fps": 10})
    monkeypatch.setattr(sys, "argv", ["lerobot-rollout", f"--policy.path={ckpt}", "--fps=10"])
    robot = BlindgraspGripper(rig.robot_config(tmp_path / "cal"))
    with pytest.raises(PolicyMismatchError, match=r"--fps=10 but the robot's loop_hz is 20"):
        robot.connect()
    assert rig.dxl.instruction_counts == {} and not robot.is_connected


def test_the_robot_checks_the_checkpoint_its_config_was_parsed_with_not_the_argv_at_connect(
    rig, tmp_path, monkeypatch
):
    """The command line is read once, where the config is parsed (`compat.read_command_line`): what the process's
    argv says by the time `connect()` runs changes nothing."""
    ckpt = _checkpoint(tmp_path, trained_for={"fps": 10})
    monkeypatch.setattr(sys, "argv", ["lerobot-rollout", f"--policy.path={ckpt}", "--fps=20"])
    config = rig.robot_config(tmp_path / "cal")
    assert (config.command_line.policy_path, config.command_line.fps) == (str(ckpt), 20.0)
    monkeypatch.setattr(sys, "argv", ["lerobot-rollout"])
    robot = BlindgraspGripper(config)
    with pytest.raises(PolicyMismatchError, match=r"fps 10 in .*config.json \(trained_for"):
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
    ckpt = _checkpoint(tmp_path, trained_for={"fps": 10})
    cmd = [
        str(BIN / "python"), "-m", "lerobot_blindgrasp.deploy.run_policy", "--strategy.type=base",
        f"--policy.path={ckpt}", "--policy.device=cpu", "--device=cpu", "--robot.type=blindgrasp_gripper",
        f"--robot.port={rig.dxl.port}", "--robot.id=rig", f"--robot.force_sensor.port={rig.force.port}",
        "--fps=20", "--duration=1", "--task=grasp", "--play_sounds=false",
    ]  # fmt: skip
    out = subprocess.run(cmd, env=cli_env(tmp_path), capture_output=True, text=True, timeout=180)
    assert out.returncode != 0
    assert f"fps 10 in {ckpt / 'config.json'} (trained_for" in out.stdout + out.stderr
    assert "the loop runs at 20 (--fps)" in out.stdout + out.stderr
    assert rig.dxl.instruction_counts == {} and not rig.dxl.any_torque()
