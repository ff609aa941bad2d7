"""The student's diagnosis and DAgger relabelling, on the shipped teacher and student with data the
tests collect themselves (two objects, a few short episodes)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from lerobot.datasets.lerobot_dataset import LeRobotDataset

from lab.diagnosis import student_diagnosis as diag
from lab.diagnosis import student_fit
from lerobot_blindgrasp import spec
from lerobot_blindgrasp.demos import collection_loop, curation, dagger
from lerobot_blindgrasp.demos.config import CollectConfig
from lerobot_blindgrasp.sim import objects

ROOT = Path(__file__).resolve().parents[2]
STUDENT = ROOT / "models" / "student_cpu"
OBJECTS = "cylinder_b_large,capsule_small"
pytestmark = pytest.mark.usefixtures("one_torch_thread")


@pytest.fixture(scope="module")
def demos(tmp_path_factory) -> Path:
    """Two whole uncurated episodes per object from the shipped teacher."""
    out = tmp_path_factory.mktemp("demos") / "demos"
    collection_loop.collect_demos(
        CollectConfig(
            output_dir=out,
            repo_id="test/demos",
            objects=OBJECTS,
            episodes_per_object=2,
            num_envs=4,
            seed=spec.DEMO_SEED + 11,
            curation=curation.NO_CURATION,
            progress=False,
        )
    )
    return out


def test_windows_are_the_windows_lerobot_train_loads(demos):
    ds = LeRobotDataset(
        "test/demos", root=demos, delta_timestamps={spec.STATE_KEY: [i / spec.CONTROL_HZ for i in range(-29, 1)]}
    )
    episodes = student_fit.episodes_by_object(demos)
    state, action = episodes["capsule_small"][0]
    win, pad = student_fit.windows(state, 30)
    capsule = list(ds.meta.tasks.index).index(objects.get_object("capsule_small").task)
    first = int(
        np.flatnonzero(np.asarray(ds.hf_dataset.with_format("numpy")["task_index"]).reshape(-1) == capsule)[0]
    )
    for t in (0, 5, 29, 40, len(state) - 1):
        item = ds[first + t]
        np.testing.assert_array_equal(item[spec.STATE_KEY].numpy(), win[t])
        np.testing.assert_array_equal(item[f"{spec.STATE_KEY}_is_pad"].numpy(), pad[t])
        np.testing.assert_array_equal(item[spec.ACTION_KEY].numpy(), action[t])


def _trace(lift, force, down=0.0, success=False, left=False, n=40):
    from lerobot_blindgrasp.rollout.loop import Episode

    traces = {"lift": lift, "tip_object_force": force, "tip_object_downward": np.full((n, 3), down)}
    return Episode("capsule_small", success, left, False, n, float(lift.max()), 0, 0, np.zeros(7), traces)


def test_each_failure_kind_follows_from_ground_truth():
    n = 40
    flat, ramp = np.zeros(n), np.linspace(0, 0.02, n)
    touch = np.zeros((n, 3))
    touch[10:, 0] = 2.0
    cases = {
        "success": _trace(ramp, touch, success=True),
        "never touches": _trace(flat, np.zeros((n, 3))),
        "presses from above": _trace(flat, touch, down=0.9),
        "touches, never lifts": _trace(flat, touch, down=0.1),
        "knocked out of reach": _trace(flat, touch, down=0.1, left=True),
        "slips while lifting": _trace(np.linspace(0, 0.01, n), touch),
        "drops during the hold": _trace(ramp, touch, left=True),
    }
    assert set(cases) == set(diag.KINDS)
    for kind, trace in cases.items():
        assert diag.failure_kind(trace) == kind


def test_drift_is_the_first_run_of_outside_steps():
    dist = np.array([[0, 5, 0, 5, 5, 5, 0], [5, 5, 5, 0, 0, 0, 0], [0, 0, 0, 0, 0, 5, 5]], float)
    steps = student_fit.first_run_above(dist, 1.0, 3, np.array([7, 7, 6]))
    assert steps.tolist() == [3, 0, -1]  # the third episode ended before its run of 2 grew to 3


@pytest.mark.parametrize("calibration_rad", [0.0, 0.05])
def test_dagger_labels_are_the_targets_the_env_commands_for_the_teachers_action(calibration_rad):
    """The label of a teacher action is the target the env commands for it, in the joints' measured frame: under a
    calibration offset too, where target - true q is not the step."""
    from dataclasses import replace

    from lerobot_blindgrasp.rollout.actors import TeacherActor
    from lerobot_blindgrasp.rollout.envs import make_batched_env
    from lerobot_blindgrasp.sim.randomization import EVAL_DR
    from lerobot_blindgrasp.teacher.policy import TeacherPolicy, default_teacher

    teacher = TeacherActor(TeacherPolicy(default_teacher()))
    dr = replace(EVAL_DR, joint_calibration_rad=calibration_rad)
    env = make_batched_env("dagger", ("sphere_small",), num_envs=2, seed=spec.DEMO_SEED + 5, dr=dr)
    obs = env.reset()
    for _ in range(15):
        a = teacher(obs) * 3.0  # beyond the 0.3 rad bound somewhere, so both clips matter
        true_frame = np.clip(env.joint_positions() + np.clip(a, -0.3, 0.3), spec.JOINT_LOWER, spec.JOINT_UPPER)
        label = env.target_for_delta(a)
        obs, _, _, _, info = env.step(a)
        np.testing.assert_array_equal(label, info["joint_target"])
        # the label is the true-frame target read through the encoders' offset (0 without one)
        np.testing.assert_allclose(label - true_frame, env.sensor_draw.joint_offset, atol=1e-12)
        assert np.abs(env.sensor_draw.joint_offset).max() == calibration_rad
    env.close()


@pytest.mark.slow
def test_dagger_and_diagnosis_end_to_end(demos, tmp_path):
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    out = tmp_path / "dagger"
    cmd = [
        sys.executable,
        "-m",
        "lerobot_blindgrasp.demos.dagger",
        f"--student={STUDENT}",
        f"--demos={demos}",
        f"--output_dir={out}",
        "--episodes_per_object=1",
        f"--objects={OBJECTS}",
        "--num_envs=2",
        "--progress=false",
    ]
    subprocess.run(cmd, check=True, capture_output=True, env=env, timeout=600)
    record = json.loads((out / dagger.DONE).read_text())
    relabelled = LeRobotDataset("x/relabelled", root=out / "relabelled")
    aggregate = LeRobotDataset("x/aggregate", root=out / "aggregate")
    demo = LeRobotDataset("x/demos", root=demos)
    assert record["episodes"] == relabelled.meta.total_episodes == 2
    assert aggregate.meta.total_episodes == demo.meta.total_episodes + 2
    assert aggregate.meta.total_frames == demo.meta.total_frames + relabelled.meta.total_frames
    # A student episode runs until the object leaves the workspace or the 10 s are up (not the demos' 5 s).
    assert all(1 <= n <= spec.EPISODE_STEPS for n in relabelled.meta.episodes["length"])
    # A second run with the same arguments finds the work done and redoes nothing (the command's own entry point,
    # in this process: the check comes before anything is loaded).
    stamp = (out / dagger.DONE).stat().st_mtime_ns
    assert cmd[1:3] == ["-m", "lerobot_blindgrasp.demos.dagger"]
    dagger.main(cmd[3:])
    assert (out / dagger.DONE).stat().st_mtime_ns == stamp

    # The diagnosis: its closed loop is lerobot-eval's (same successes on the same start states and batch).
    ev = tmp_path / "eval"
    subprocess.run(
        [
            sys.executable,
            "-m",
            "lerobot.scripts.lerobot_eval",
            f"--policy.path={STUDENT}",
            "--env.type=blindgrasp",
            "--env.task=capsule_small",
            "--eval.n_episodes=2",
            "--eval.batch_size=2",
            "--policy.device=cpu",
            "--eval.use_async_envs=false",
            "--env.render_episodes=0",
            f"--output_dir={ev}",
            "--seed=1000",
        ],
        check=True,
        capture_output=True,
        env=env,
        timeout=600,
    )
    diag_out = tmp_path / "diag"
    subprocess.run(
        [
            sys.executable,
            "-m",
            "lab.diagnosis.student_diagnosis",
            f"--student={STUDENT}",
            f"--demos={demos}",
            f"--held_out={out / 'relabelled'}",
            "--objects=capsule_small",
            "--episodes=2",
            f"--student_eval={ev}",
            f"--output_dir={diag_out}",
            "--progress=false",
        ],
        check=True,
        cwd=ROOT,  # the lab runs from the repository root
        capture_output=True,
        env=env,
        timeout=600,
    )
    result = json.loads((diag_out / "diagnosis.json").read_text())
    assert result["matches_lerobot_eval"]["all"]
    row = result["objects"]["capsule_small"]
    assert sum(row["kind_counts"].values()) == 2 and set(row["kind_counts"]) <= set(diag.KINDS)
    assert 0 < row["fit"]["train"]["mse"] < 1 and row["fit"]["held_out"]["frames"] > 0
    assert len(row["drift"]["joints"]["first_step"]) == 2
    assert (diag_out / "diagnosis.png").stat().st_size > 1000
