"""Helpers for tests that drive the emulated hardware: calibrated robots, and CLI subprocesses with an operator."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

from emulators.rig import LATENCY_TIMER_MS
from lerobot_blindgrasp import spec

BIN = Path(sys.executable).parent
ROBOT_LOOP = Path(__file__).resolve().parent / "robot_loop.py"


def tiny_student_train(repo_id: str, root: Path, out: Path, steps: int, *extra: str) -> list[str]:
    """`lerobot-train` of a one-layer blindgrasp student for `steps` steps: end-to-end CLI tests train in seconds."""
    return [
        str(BIN / "lerobot-train"),
        "--policy.type=blindgrasp_transformer",
        "--policy.size=quick",
        "--policy.n_layers=1",
        "--policy.embed_dim=32",
        "--policy.head_hidden_dims=[32]",
        "--policy.n_obs_steps=8",
        "--policy.device=cpu",
        "--policy.push_to_hub=false",
        f"--dataset.repo_id={repo_id}",
        f"--dataset.root={root}",
        f"--output_dir={out}",
        f"--steps={steps}",
        f"--save_freq={steps}",
        "--batch_size=4",
        "--num_workers=0",
        "--wandb.enable=false",
        *extra,
    ]


class ScriptedKeyboard:
    """The operator's keyboard: a test calls `press` the way LeRobot's key listeners call the dispatch they get."""

    def __init__(self, dispatch, controls_help=""):
        self.press = dispatch

    def stop(self):
        pass


def trial_env(robot_config, task: str, keys=None, **settings):
    """A real trial (`RealGraspEnv`) of `task` on the emulated gripper, which the trial's first reset connects:
    `settings` are `--env.*` ones; no `keys`: headless, nobody at a keyboard, as an unattended run."""
    from lerobot_blindgrasp.envs.operator import OperatorKeys
    from lerobot_blindgrasp.envs.real_env import BlindGraspRealEnvConfig
    from lerobot_blindgrasp.envs.real_trial import GripperSession, RealGraspEnv

    keys = keys or OperatorKeys(listener_factory=lambda dispatch, controls_help="": None)
    cfg = BlindGraspRealEnvConfig(robot=robot_config, task=task, **settings)
    return RealGraspEnv(GripperSession(cfg, keys), task)


def cli_env(home: Path) -> dict[str, str]:
    """Offline, isolated environment for LeRobot CLI subprocesses."""
    return {
        **os.environ,
        "HF_HUB_OFFLINE": "1",
        "HF_DATASETS_OFFLINE": "1",
        "HF_HOME": str(home / "hf"),
        "HF_LEROBOT_HOME": str(home / "hf" / "lerobot"),
        "HF_LEROBOT_CALIBRATION": str(home / "calibration"),
        "WANDB_MODE": "disabled",
        "OMP_NUM_THREADS": "1",
        "PYTHONUNBUFFERED": "1",
        "MUJOCO_GL": "egl",
    }


def as_from_a_terminal(cmd: list[str]) -> list[str]:
    """`cmd` started with SIGHUP, SIGINT and SIGTERM at their default disposition, as from a terminal. A process
    inherits ignored signals: under `nohup` or as a shell's background job the test runner ignores SIGHUP or SIGINT,
    and the code under test rightly leaves an ignored signal ignored, so a test that sends one must reset it.
    coreutils' `env` execs the command, so the pid the test signals is the command's."""
    return ["env", "--default-signal=HUP,INT,TERM", *cmd]


class Operator:
    """Runs a CLI whose `input()` prompts an operator: waits for each prompt text, acts, then presses ENTER."""

    def __init__(self, cmd: list[str], env: dict[str, str]):
        self.proc = subprocess.Popen(
            as_from_a_terminal(cmd),
            env=env,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
        )
        self.output = bytearray()
        self._pos = 0
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        while chunk := self.proc.stdout.read1(4096):
            self.output += chunk

    @property
    def text(self) -> str:
        return self.output.decode(errors="replace")

    def expect(self, marker: str, timeout_s: float = 60.0) -> None:
        deadline = time.monotonic() + timeout_s
        needle = marker.encode()
        while (i := self.output.find(needle, self._pos)) < 0:
            if self.proc.poll() is not None or time.monotonic() > deadline:
                raise AssertionError(f"never saw {marker!r}; output:\n{self.text[-4000:]}")
            time.sleep(0.02)
        self._pos = i + len(needle)

    def answer(self, line: str = "") -> None:
        self.proc.stdin.write(line.encode() + b"\n")
        self.proc.stdin.flush()

    def wait(self, timeout_s: float = 120.0) -> int:
        rc = self.proc.wait(timeout=timeout_s)
        self._reader.join(timeout=5)
        return rc


def connect_gripper(rig, tmp_path: Path, monkeypatch, **overrides):
    """A gripper on the rig with the config's `overrides`, calibrated by the scripted operator and connected."""
    from lerobot_blindgrasp.robots.blindgrasp_gripper import BlindgraspGripper

    monkeypatch.setattr("builtins.input", rig.calibration_inputs())
    robot = BlindgraspGripper(rig.robot_config(tmp_path / "cal", **overrides))
    robot.connect()
    return robot


def time_until(condition, timeout_s: float = 10.0, poll_s: float = 0.001) -> float:
    """Seconds until `condition()` holds, polled; fails the test after `timeout_s`."""
    t0 = time.monotonic()
    while not condition():
        assert time.monotonic() - t0 < timeout_s, "condition never became true"
        time.sleep(poll_s)
    return time.monotonic() - t0


def robot_loop_process(rig, robot, tmp_path: Path) -> Operator:
    """`robot_loop.py` in a subprocess on the rig, with `robot`'s calibration, once its torque is on and its fingers
    move (`robot` is disconnected to free the ports)."""
    robot.disconnect()  # the calibration file stays; the subprocess connects without prompting
    args = {"port": rig.dxl.port, "force_port": rig.force.port, "calibration_dir": str(robot.calibration_dir),
            "scale": rig.force.scale.tolist(), "latency_timer_ms": LATENCY_TIMER_MS}  # fmt: skip
    proc = Operator([sys.executable, str(ROBOT_LOOP), json.dumps(args)], cli_env(tmp_path))
    proc.expect("READY")
    time.sleep(0.3)  # a few control periods with the torque on and the fingers moving
    assert all(rig.dxl.torque_enabled(i) for i in spec.SERVO_IDS)
    return proc
