"""Recording through the real stack on the physics twin: the emulated glove drives the twin with lerobot-record,
LeRobot's loader reads the dataset, it has the sim demos' schema and action meaning, and lerobot-train runs on it.

Real CLIs throughout: lerobot-calibrate (glove, and the gripper through blindgrasp-twin-calibrate), lerobot-record,
lerobot-train (a one-layer student, a few steps).
"""

from __future__ import annotations

import json
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest
from emulators.glove_sender import GloveEmulator, free_udp_port
from emulators.harness import BIN, Operator, cli_env, tiny_student_train

from lerobot_blindgrasp import durable, spec

pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[2]
GLOVE_FILE = ROOT / "robot_configs" / "manus_glove.yaml"
REPO_ID = "local/blindgrasp_twin_glove"
EPISODE_S = 3
LATENCY_TIMER_MS = 150  # reply timeout 302 ms: the twin shares a loaded CI machine's CPU with the host


def _run(cmd: list[str], env: dict, timeout: int = 300) -> None:
    res = subprocess.run(cmd, env=env, cwd=ROOT, capture_output=True, text=True, timeout=timeout)
    assert res.returncode == 0, f"{Path(cmd[0]).name} failed:\n{res.stdout[-3000:]}\n{res.stderr[-5000:]}"


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    from lerobot_blindgrasp.twin.command import TwinConfig
    from lerobot_blindgrasp.twin.runner import Twin

    tmp = tmp_path_factory.mktemp("twin_record")
    env = cli_env(tmp)
    with Twin(TwinConfig(socket=str(tmp / "twin.sock"))) as twin, GloveEmulator(free_udp_port()) as glove:
        durable.atomic_write_json(tmp / "ports.json", twin.ports())
        _run([str(BIN / "blindgrasp-twin-calibrate"), f"--ports_json={tmp / 'ports.json'}", "--robot_id=twin",
              f"--calibration_dir={tmp / 'calibration'}", f"--latency_timer_ms={LATENCY_TIMER_MS}", "--force=false"],
             env)  # fmt: skip
        teleop = [f"--teleop=include {GLOVE_FILE}", f"--teleop.port={glove.addr[1]}", "--teleop.id=op"]
        op = Operator([str(BIN / "lerobot-calibrate"), *teleop, "--teleop.calibration_s=0.3"], env)
        for prompt, closure in (("OPEN HAND", 0.0), ("FIST", 1.0)):
            op.expect(prompt)
            glove.closure = closure
            time.sleep(0.1)
            op.answer()
        assert op.wait() == 0, op.text[-3000:]

        twin.physics.place("sphere_medium", 1000)
        glove.closure_fn = lambda t: 0.5 - 0.5 * np.cos(1.5 * t)  # open -> fist -> open, slowly
        ports = twin.ports()
        _run([str(BIN / "lerobot-record"), "--robot.type=blindgrasp_gripper", "--robot.id=twin",
              f"--robot.calibration_dir={tmp / 'calibration'}", f"--robot.port={ports['dynamixel_port']}",
              f"--robot.force_sensor.port={ports['force_port']}", "--robot.force_sensor.tare_s=0.2",
              f"--robot.force_sensor.scale_n_per_count=[{','.join(map(str, ports['scale_n_per_count']))}]",
              f"--robot.latency_timer_ms={LATENCY_TIMER_MS}", "--robot.max_overrun_s=0", *teleop,
              f"--dataset.repo_id={REPO_ID}",
              f"--dataset.root={tmp / 'dataset'}", "--dataset.single_task=grasp and lift the medium sphere",
              f"--dataset.fps={spec.CONTROL_HZ}", f"--dataset.episode_time_s={EPISODE_S}",
              "--dataset.reset_time_s=0.5", "--dataset.num_episodes=2", "--dataset.video=false",
              "--dataset.push_to_hub=false", "--play_sounds=false"], env)  # fmt: skip
        assert not twin.bus.any_torque()
    return tmp


def test_the_twin_recording_has_the_sim_demos_schema_and_action_meaning(recorded):
    from lerobot.datasets import LeRobotDataset

    ds = LeRobotDataset(REPO_ID, root=recorded / "dataset")
    for key, feature in spec.dataset_features().items():  # what sim demos are written with (demos/dataset.py)
        assert ds.features[key]["names"] == feature["names"]
        assert tuple(ds.features[key]["shape"]) == feature["shape"] and ds.features[key]["dtype"] == "float32"
    assert ds.meta.robot_type == "blindgrasp_gripper" and ds.fps == spec.CONTROL_HZ and ds.num_episodes == 2
    frames = [ds[i] for i in range(len(ds))]
    state = np.stack([f[spec.STATE_KEY].numpy() for f in frames])
    action = np.stack([f[spec.ACTION_KEY].numpy() for f in frames])
    assert len(frames) >= 2 * EPISODE_S * spec.CONTROL_HZ * 0.5  # a loaded CPU may drop frames, not half of them
    # Action = absolute joint targets (rad) in the state's frame, as in sim demos: the twin's joints reach them.
    # The abduction joints (J*0) touch nothing, so each follows its target within a few control periods.
    lag = 3
    free = [0, 3, 6]
    follow = np.abs(state[lag:, free] - action[:-lag, free])
    assert np.median(follow) < 0.05, np.median(follow)
    # The glove swept open -> fist: the proximal targets cover most of their range; the squeeze loaded the tips.
    assert action[:, 1].max() - action[:, 1].min() > 0.8
    assert state[:, 9:].max() > 1.0 and state[:, 9:].min() >= 0.0


def test_lerobot_train_runs_on_the_twin_recording(recorded):
    out = recorded / "train"
    _run(tiny_student_train(REPO_ID, recorded / "dataset", out, 2), cli_env(recorded))
    assert (out / "checkpoints" / "000002" / "pretrained_model" / "model.safetensors").is_file()
    cfg = json.loads((out / "checkpoints" / "000002" / "pretrained_model" / "config.json").read_text())
    assert cfg["type"] == "blindgrasp_transformer"
