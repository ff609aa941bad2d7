"""The guides' hardware commands, run whole as they are printed, where an emulator or simavr can serve them.

`test_docs_commands.py` parses every command of the README and docs/*.md; here the ones a lab runs on the gripper
run to their end: `lerobot-calibrate` of the gripper and of the glove, `blindgrasp-calibrate-force` (each
documented variant, the operator's weight moved pad to pad at its prompts), `blindgrasp-rollout`, `lerobot-eval
--env.type=blindgrasp_real` and `real_report` on what that eval wrote, and the force board's `build` and `sim`
lines where the AVR toolchain is installed. Each is the guide's own argv (`commands_of`) with only what points it
at the emulators appended (ports, the calibration folder, test-sized durations; later flags win in draccus), run
through its console script's entry point in this process (`run_in_process`), from a folder that sees the
repository as the guides' working folder and has the guides' checkpoint path pointing at the shipped student.
One emulated gripper serves the whole file, in order: the calibrations the first tests make are the ones the
rollout and the eval find by `--robot.id`.
"""

from __future__ import annotations

import re
import signal
import subprocess
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from doc_commands import ALL, ROOT, SHIPPED_STUDENT
from emulators.glove_sender import GloveEmulator, free_udp_port
from emulators.rig import LATENCY_TIMER_MS, GripperRig
from test_docs_commands import offline_in, run_in_process

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.hardware.force_board import build
from lerobot_blindgrasp.hardware.force_board import force_calibration as fc

pytestmark = pytest.mark.slow

BRINGUP = "docs/bringup.md"
GRIPPER_ID = "lab_gripper"  # the id every guide calibrates, deploys and evaluates with
WEIGHT_N = 0.5 * fc.STANDARD_GRAVITY  # the guides' --mass_kg=0.5
SYNC_WRITE = 0x83


def documented(program: str, doc: str | None = None) -> list[list[str]]:
    """The distinct argv of `program` in the guides (or in `doc`)."""
    out: list[list[str]] = []
    for c in ALL:
        if c.program == program and doc in (None, c.doc) and list(c.argv) not in out:
            out.append(list(c.argv))
    assert out, f"no guide runs {program}"
    return out


@dataclass
class Lab:
    box: Path  # the guides' working folder
    home: Path
    rig: GripperRig

    @property
    def calibration_dir(self) -> Path:
        return self.home / "calibration" / "robots" / "blindgrasp_gripper"

    def robot_args(self, prefix: str = "--robot") -> list[str]:
        """The emulators' ports, this lab's calibration folder, and a loaded CI host's slack: the loop's timing and
        the force stream's staleness are tested in test_hazards_host_timing.py and test_hazards_force_frame.py, not here."""
        return [
            f"{prefix}.port={self.rig.dxl.port}",
            f"{prefix}.force_sensor.port={self.rig.force.port}",
            f"{prefix}.calibration_dir={self.calibration_dir}",
            f"{prefix}.latency_timer_ms={LATENCY_TIMER_MS}",
            f"{prefix}.max_overrun_s=0",
            f"{prefix}.force_sensor.tare_s=0.2",
            f"{prefix}.force_sensor.stale_timeout_s=2.0",
        ]

    def run(self, argv: list[str], operator=None) -> str:
        """`argv` run whole in the guides' folder; returns its output, failing with it on a non-zero exit."""
        with offline_in(self.box, self.home) as mp:
            if operator is not None:
                mp.setattr("builtins.input", operator)
            _, code, out = run_in_process(argv, mp, stop_at_parse=False)
        assert code == 0, f"{' '.join(argv)}\nexit {code}:\n{out[-4000:]}"
        return out


@pytest.fixture(scope="module")
def lab(tmp_path_factory):
    box = tmp_path_factory.mktemp("guides_cwd")
    for entry in ROOT.iterdir():
        if not entry.name.startswith(".") and entry.name not in ("outputs", "runs", "build", "data"):
            (box / entry.name).symlink_to(entry)
    checkpoint = box / "outputs" / "glove_student" / "student" / "checkpoints" / "last" / "pretrained_model"
    checkpoint.parent.mkdir(parents=True)
    checkpoint.symlink_to(SHIPPED_STUDENT)  # the guide deploys the student it trained; the shipped one stands in
    with GripperRig() as rig:
        rig.hand_move(spec.HOME_POSE)
        yield Lab(box, tmp_path_factory.mktemp("lab_home"), rig)
        assert not rig.dxl.any_torque()


@pytest.fixture(autouse=True)
def _signal_handlers():
    """The CLIs install their own SIGINT/SIGTERM/SIGHUP handlers (LeRobot's ProcessSignalHandler, the robot's)."""
    saved = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)}
    yield
    for s, handler in saved.items():
        signal.signal(s, handler)


def test_the_documented_gripper_calibration(lab):
    [argv] = [a for a in documented("lerobot-calibrate", BRINGUP) if f"--robot.id={GRIPPER_ID}" in a]
    lab.run(argv + lab.robot_args(), operator=lab.rig.calibration_inputs())
    assert (lab.calibration_dir / f"{GRIPPER_ID}.json").is_file()
    assert not lab.rig.dxl.any_torque()


def test_the_documented_force_calibrations(lab):
    """Every documented variant (with the yaml's include, with --robot.type); the weight moves at each prompt."""
    loads = {1: [0, 0, 0], 2: [WEIGHT_N, 0, 0], 3: [0, WEIGHT_N, 0], 4: [0, 0, WEIGHT_N], 5: [0, 0, 0]}

    def operator(prompt: str = "") -> str:
        lab.rig.force.forces_n = np.array(loads[int(re.search(r"Step (\d)/5", prompt).group(1))], dtype=float)
        return ""

    variants = documented("blindgrasp-calibrate-force")
    assert len(variants) >= 2
    for argv in variants:
        saved = lab.calibration_dir / f"{GRIPPER_ID}.force.json"
        saved.unlink(missing_ok=True)
        out = lab.run(argv + lab.robot_args() + ["--settle_s=0.1", "--window_s=0.3"], operator=operator)
        assert f"Saved {saved}" in out, out[-2000:]
        np.testing.assert_allclose(fc.load_force_calibration(saved).scales(), lab.rig.force.scale, rtol=5e-3)
    lab.rig.force.forces_n = np.zeros(3)


def test_the_documented_glove_calibration(lab):
    port = free_udp_port()
    with GloveEmulator(port) as glove:

        def operator(prompt: str = "") -> str:
            glove.closure = 0.0 if "OPEN HAND" in prompt else 1.0
            time.sleep(0.1)  # a few datagrams of the new pose
            return ""

        [argv] = [a for a in documented("lerobot-calibrate", BRINGUP) if any(x.startswith("--teleop") for x in a)]
        teleop_dir = lab.home / "calibration" / "teleoperators" / "manus_glove"
        lab.run(argv + [f"--teleop.port={port}", f"--teleop.calibration_dir={teleop_dir}",
                        "--teleop.calibration_s=0.3"], operator=operator)  # fmt: skip
    assert (teleop_dir / "alice.json").is_file()


def test_the_documented_rollout(lab):
    [argv] = documented("blindgrasp-rollout", BRINGUP)
    before = lab.rig.dxl.instruction_counts.get(SYNC_WRITE, 0)
    lab.run(argv + lab.robot_args() + ["--duration=1.5"])
    assert lab.rig.dxl.instruction_counts.get(SYNC_WRITE, 0) - before >= 20  # ~30 steps, 9 goals each
    assert not lab.rig.dxl.any_torque()


def test_the_documented_real_eval_and_its_report(lab):
    """The guide's lerobot-eval for one trial of one object, judged by force (no operator), then the guide's
    report line on the eval_info.json it wrote where the guide says."""
    [argv] = documented("lerobot-eval", BRINGUP)
    lab.run(argv + lab.robot_args("--env.robot") + [
        "--env.task=cylinder_a_medium", "--eval.n_episodes=1", "--env.success_mode=force",
        "--env.unattended_reset_s=0.1", "--env.episode_s=1.0"])  # fmt: skip
    assert not lab.rig.dxl.any_torque()
    [report] = documented("python -m lerobot_blindgrasp.envs.real_report", BRINGUP)
    out = lab.run(report)
    assert "| cylinder_a_medium | 1 |" in out and "| **overall** | 1 |" in out, out


def test_the_documented_force_board_build_and_sim(lab):
    if missing := build.missing_packages():
        pytest.skip(f"the force board's toolchain is missing: apt-get install {' '.join(missing)}")
    [build_argv] = documented("python -m lerobot_blindgrasp.hardware.force_board.build")
    out = lab.run(build_argv)
    avrdude = re.search(r"^flash it: (avrdude .*)$", out, flags=re.M).group(1)
    make = re.search(r"^      or: (make .*)$", out, flags=re.M).group(1)
    # The two printed flash commands are one: make's recipe, printed without running it, is the avrdude line.
    dry = subprocess.run([*make.split(), "-n"], capture_output=True, text=True, check=True).stdout.strip()
    assert dry == avrdude, (dry, avrdude)
    [sim_argv] = documented("python -m lerobot_blindgrasp.emulators.force_board_simavr")
    out = lab.run(sim_argv)
    rate = float(re.search(r"([\d.]+) frames/s", out).group(1))
    assert 50 < rate < 100 and "0 reads not of 25 pulses" in out, out  # simavr paced to a loaded wall clock
    given, read = re.search(r"forces given \[(.*)\] N, read \[(.*)\] N", out).groups()
    np.testing.assert_allclose(np.array(read.split(","), float), np.array(given.split(","), float), atol=0.02)
