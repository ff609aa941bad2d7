"""Training on glove data: a recording made with lerobot-record against the emulated gripper and glove, then
`blindgrasp-train-glove` at smoke size on it alone (`glove_smoke`) and merged with a tiny sim demo set
(`sim_plus_glove_smoke`), each ending in a real lerobot-train checkpoint that LeRobot loads back.

lerobot-record and lerobot-teleoperate run as docs/bringup.md writes them, with the emulators' ports and a
test-sized session appended. The gripper and the glove are calibrated in-process (the real robot and teleoperator
classes with a scripted operator; lerobot-calibrate itself is covered by test_hw_cli.py), into the calibration
folder the CLIs read.
"""

from __future__ import annotations

import dataclasses
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest
from emulators.glove_sender import GloveEmulator, free_udp_port
from emulators.harness import BIN, cli_env
from emulators.rig import LATENCY_TIMER_MS, GripperRig

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.pipeline import glove_train
from lerobot_blindgrasp.presets.glove import GLOVE_PRESETS

pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[2]
BRINGUP = ROOT / "docs" / "bringup.md"
REPO_ID = "local/blindgrasp_glove"  # docs/bringup.md's
TASK = "grasp and lift the medium cylinder a"
GRIPPER_ID, OPERATOR_ID = "lab_gripper", "alice"  # the ids the guide calibrates and records with


def _as_documented(program: str) -> list[str]:
    """The guide's own command line (docs/bringup.md), to be run from the repository root."""
    from doc_commands import commands_of

    [cmd] = [c for c in commands_of(BRINGUP) if c.argv[0] == program]
    assert f"--robot.id={GRIPPER_ID}" in cmd.argv and f"--teleop.id={OPERATOR_ID}" in cmd.argv, cmd
    return [str(BIN / program), *cmd.argv[1:]]


def _emulator_args(rig: GripperRig, port: int) -> list[str]:
    """What a documented command needs to run on the emulators (later flags win in draccus)."""
    return [
        f"--robot.port={rig.dxl.port}",
        f"--robot.force_sensor.port={rig.force.port}",
        "--robot.force_sensor.tare_s=0.2",
        f"--robot.latency_timer_ms={LATENCY_TIMER_MS}",
        # The timing and staleness stops are tested in test_hazards_host_timing.py and test_hazards_force_frame.py; here a loaded CI host that starves
        # the emulators' threads for a few hundred ms must not end the recording (overruns are still warned).
        "--robot.max_overrun_s=0",
        "--robot.force_sensor.stale_timeout_s=2.0",
        f"--teleop.port={port}",
        "--teleop.disconnect_timeout_s=5.0",
    ]


def _calibrate(home: Path, glove: GloveEmulator, monkeypatch) -> None:
    from lerobot_blindgrasp.robots.blindgrasp_gripper import BlindgraspGripper
    from lerobot_blindgrasp.teleoperators.manus_glove import ManusGlove, ManusGloveConfig

    with GripperRig() as rig:
        rig.hand_move(spec.HOME_POSE)
        monkeypatch.setattr("builtins.input", rig.calibration_inputs())
        cfg = rig.robot_config(home / "calibration" / "robots" / "blindgrasp_gripper")
        robot = BlindgraspGripper(dataclasses.replace(cfg, id=GRIPPER_ID))
        robot.connect()
        robot.disconnect()

    def operator(prompt: str = "") -> str:
        glove.closure = 0.0 if "OPEN HAND" in prompt else 1.0
        time.sleep(0.05)
        return ""

    monkeypatch.setattr("builtins.input", operator)
    teleop = ManusGlove(
        ManusGloveConfig(
            id=OPERATOR_ID,
            port=glove.addr[1],
            calibration_s=0.2,
            calibration_dir=home / "calibration" / "teleoperators" / "manus_glove",
        )
    )
    teleop.connect()
    teleop.disconnect()


@pytest.fixture(scope="module")
def recording(tmp_path_factory) -> tuple[Path, dict, int]:
    """docs/bringup.md's lerobot-record on a fresh rig (the calibration file is written back), cut to two 2 s
    episodes into a temporary folder."""
    home = tmp_path_factory.mktemp("glove_station")
    env = cli_env(home)
    port = free_udp_port()
    with pytest.MonkeyPatch.context() as mp, GloveEmulator(port) as glove:
        _calibrate(home, glove, mp)
    root = home / "blindgrasp_glove"
    with GripperRig() as rig, GloveEmulator(port) as glove:
        rig.hand_move(spec.HOME_POSE)
        rig.place_object()
        glove.closure_fn = lambda t: 0.5 - 0.5 * np.cos(2.5 * t)
        cmd = [*_as_documented("lerobot-record"), *_emulator_args(rig, port), f"--dataset.root={root}",
               "--dataset.episode_time_s=2", "--dataset.reset_time_s=0.5", "--dataset.num_episodes=2",
               "--play_sounds=false"]  # fmt: skip
        res = subprocess.run(cmd, env=env, cwd=ROOT, capture_output=True, text=True, timeout=240)
        assert res.returncode == 0, res.stderr[-4000:]
    return root, env, port


@pytest.fixture(scope="module")
def sim_demos(tmp_path_factory) -> Path:
    """Two curated episodes of one object from the shipped teacher (blindgrasp-collect-demos, in-process)."""
    from lerobot_blindgrasp.demos import collection_loop
    from lerobot_blindgrasp.demos.config import CollectConfig

    out = tmp_path_factory.mktemp("sim") / "demos"
    collection_loop.collect_demos(CollectConfig(output_dir=out, repo_id="local/tiny_sim", episodes_per_object=2,
                               objects="cylinder_a_medium", num_envs=2, threads=1, progress=False))  # fmt: skip
    return out


def _train(cfg: glove_train.GloveTrainConfig, env: dict, monkeypatch) -> Path:
    for k, v in env.items():  # lerobot-train inherits the offline, isolated environment
        monkeypatch.setenv(k, v)
    return glove_train.train_on_glove(cfg)


def _loads_as_a_policy(checkpoint: Path) -> None:
    from lerobot.policies.factory import get_policy_class

    policy = get_policy_class("blindgrasp_transformer").from_pretrained(checkpoint)
    assert list(policy.config.input_features) == [spec.STATE_KEY]
    assert policy.config.input_features[spec.STATE_KEY].shape == (spec.STATE_DIM,)


def test_the_presets_name_what_they_train_on():
    assert not GLOVE_PRESETS["glove"].sim_demos and GLOVE_PRESETS["sim_plus_glove"].sim_demos
    for p in GLOVE_PRESETS.values():
        assert p.deviations and p.student.size in ("cpu", "quick")
    with pytest.raises(ValueError, match="--sim_demos"):
        glove_train.GloveTrainConfig(preset="sim_plus_glove", glove=[Path("g")], output_dir=Path("o"))
    with pytest.raises(ValueError, match="glove recordings only"):
        glove_train.GloveTrainConfig(glove=[Path("g")], output_dir=Path("o"), sim_demos=Path("s"))


def test_glove_recording_trains_a_student(recording, tmp_path, monkeypatch):
    root, env, _ = recording
    assert glove_train.merge_schema_problems(root) == []
    cfg = glove_train.GloveTrainConfig(preset="glove_smoke", glove=[root], output_dir=tmp_path / "glove")
    checkpoint = _train(cfg, env, monkeypatch)
    _loads_as_a_policy(checkpoint)
    assert not (tmp_path / "glove" / "dataset").exists()  # one source: trained on the recording itself


def test_sim_demos_plus_glove_merge_and_train(recording, sim_demos, tmp_path, monkeypatch, capsys):
    from lerobot.datasets import LeRobotDataset

    root, env, _ = recording
    glove = LeRobotDataset(REPO_ID, root=root)
    sim = LeRobotDataset("local/tiny_sim", root=sim_demos)
    cfg = glove_train.GloveTrainConfig(preset="sim_plus_glove_smoke", glove=[root], sim_demos=sim_demos,
                                       output_dir=tmp_path / "mix")  # fmt: skip
    checkpoint = _train(cfg, env, monkeypatch)
    merged = LeRobotDataset(cfg.repo_id, root=tmp_path / "mix" / "dataset")
    copies = GLOVE_PRESETS["sim_plus_glove_smoke"].glove_copies
    assert merged.num_episodes == sim.num_episodes + copies * glove.num_episodes
    assert len(merged) == len(sim) + copies * len(glove)
    assert set(merged.meta.tasks.index) == {TASK} | set(sim.meta.tasks.index)
    assert not [k for k in merged.meta.features if k.startswith("episode.")]  # the sim metadata was removed
    # The last frames are the glove recording's, unchanged by the merge.
    last_merged, last_glove = merged[len(merged) - 1], glove[len(glove) - 1]
    np.testing.assert_array_equal(last_merged[spec.STATE_KEY].numpy(), last_glove[spec.STATE_KEY].numpy())
    _loads_as_a_policy(checkpoint)
    assert "lerobot-train --policy.type=blindgrasp_transformer --policy.size=quick" in capsys.readouterr().out


def test_a_folder_of_another_schema_is_named_before_anything_is_written(recording, tmp_path):
    root, _, _ = recording
    cfg = glove_train.GloveTrainConfig(preset="glove_smoke", glove=[root, tmp_path / "nothing"],
                                       output_dir=tmp_path / "out")  # fmt: skip
    with pytest.raises(SystemExit, match="nothing is not a LeRobotDataset folder"):
        glove_train.train_on_glove(cfg)
    assert not (tmp_path / "out").exists()


def test_lerobot_teleoperate_drives_the_gripper_from_the_glove(recording):
    """docs/bringup.md's lerobot-teleoperate, whole (for 2 s), on the station the recording used."""
    _, env, port = recording
    with GripperRig() as rig, GloveEmulator(port) as glove:
        rig.hand_move(spec.HOME_POSE)
        glove.closure_fn = lambda t: 0.5 - 0.5 * np.cos(2.5 * t)
        cmd = [*_as_documented("lerobot-teleoperate"), *_emulator_args(rig, port), "--teleop_time_s=2"]
        res = subprocess.run(cmd, env=env, cwd=ROOT, capture_output=True, text=True, timeout=240)
        assert res.returncode == 0, res.stderr[-4000:]
        assert rig.dxl.instruction_counts.get(0x83, 0) >= 10  # goal sync writes at up to 20 Hz for 2 s
        assert not rig.dxl.any_torque()
