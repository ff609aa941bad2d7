"""The scripted side grasp and its cloning into the PPO actor (`cpu_bc`, issue #9: the small capsule)."""

from __future__ import annotations

import json
import math
import signal
from dataclasses import replace

import numpy as np
import pytest
import torch
from rsl_rl.utils import resolve_callable

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.presets import teacher as teacher_presets
from lerobot_blindgrasp.sim import objects, scripted
from lerobot_blindgrasp.sim.batched_config import GraspEnvConfig
from lerobot_blindgrasp.sim.batched_env import BatchedGraspEnv
from lerobot_blindgrasp.teacher import aux_bc, scripted_demos


def test_support_distance_is_the_surface_seen_from_each_side():
    along_x, along_y = np.array([[1.0, 0.0]]), np.array([[0.0, 1.0]])
    capsule = objects.get_object("capsule_small")  # radius 2 cm, half-length 1 cm, lying along x
    assert scripted.support_distance(capsule, along_x)[0] == pytest.approx(0.03)
    assert scripted.support_distance(capsule, along_y)[0] == pytest.approx(0.02)
    box = objects.get_object("cuboid_a_medium")
    diag = np.array([[math.sqrt(0.5), math.sqrt(0.5)]])
    assert scripted.support_distance(box, diag)[0] == pytest.approx((box.size[0] + box.size[1]) * math.sqrt(0.5))
    sphere = objects.get_object("sphere_small")
    assert scripted.support_distance(sphere, diag)[0] == pytest.approx(sphere.size[0])


def test_side_grasp_script_lifts_the_small_capsule_from_the_paper_start_pose_under_randomization():
    """The premise of `cpu_bc`: from the paper's start pose, with the object anywhere in its Table II offset, joint
    offsets, friction, mass and gain draws, the script lifts the object the teacher only ever pressed down."""
    env = BatchedGraspEnv(
        GraspEnvConfig(
            num_envs=8, objects=("capsule_small", "sphere_small"), seed=1 << 32, nthread=1, autoreset=False
        )
    )
    env.reset()
    assert np.abs(env.object_position()[:, :2]).max() > 0.005  # the objects really are off-centre
    script = scripted.SideGraspScript(
        env.joint_positions(), env.object_position(), [objects.get_object(n) for n in env.object_names]
    )
    success = np.zeros(env.num_envs, dtype=bool)
    for _ in range(120):
        q = env.joint_positions()
        assert (q >= spec.JOINT_LOWER - 0.05).all() and (q <= spec.JOINT_UPPER + 0.05).all()
        *_, info = env.step(script(q))
        success |= info["success"]
    assert success.sum() >= 6, success  # measured: 87 % (capsule) and 93 % (sphere) over 30 draws each


def test_scripted_demos_keep_only_successful_episodes_and_refuse_bad_settings():
    cfg = scripted_demos.ScriptedDemos(
        objects=("capsule_small", "cuboid_a_large"), episodes_per_object=2, steps_per_episode=10
    )
    data = scripted_demos.collect_scripted_demos(cfg)
    # The script cannot lift the large cuboid (measured 0/4): only capsule episodes become demonstrations.
    assert data["success"]["cuboid_a_large"] == 0.0 and data["success"]["capsule_small"] > 0
    kept = round(data["success"]["capsule_small"] * 2)
    assert data["obs"]["privileged"].shape == (kept * 10, spec.PRIVILEGED_DIM)
    assert data["obs"]["policy"].shape == (kept * 10, spec.STATE_DIM) and data["actions"].shape == (kept * 10, 9)
    assert np.abs(data["actions"]).max() <= spec.ACTION_BOUND_RAD + 1e-6
    with pytest.raises(ValueError, match="catalogue"):
        scripted_demos.ScriptedDemos(objects=("teapot",))
    with pytest.raises(ValueError, match="positive"):
        scripted_demos.ScriptedDemos(decay_iterations=0)
    with pytest.raises(ValueError, match="teacher_train"):
        scripted_demos.ScriptedDemos(seed=spec.DEMO_SEED)  # demo-collection start states are not training data
    assert cfg.weight_at(0) == cfg.coef and cfg.weight_at(cfg.decay_iterations) == 0.0 == cfg.weight_at(10**6)
    late = scripted_demos.ScriptedDemos(coef=0.2, start_iteration=10, decay_iterations=4)
    assert [late.weight_at(i) for i in (9, 10, 12, 14)] == pytest.approx([0.0, 0.2, 0.1, 0.0])


def test_cpu_bc_joint_is_cpu_plus_the_cloning_algorithm_only():
    cpu, bc = teacher_presets.CPU, teacher_presets.TEACHER_PRESETS["cpu_bc_joint"]
    alg = bc.runner_cfg()["algorithm"]
    assert resolve_callable(alg["class_name"]) is aux_bc.PPOWithScriptedDemos
    rest = {k: v for k, v in alg.items() if k not in ("class_name", "scripted_demos")}
    assert rest == {k: v for k, v in cpu.runner_cfg()["algorithm"].items() if k != "class_name"}
    assert {k: v for k, v in bc.runner_cfg().items() if k != "algorithm"} == {
        k: v for k, v in cpu.runner_cfg().items() if k != "algorithm"
    }
    assert bc.reward == cpu.reward and bc.external_force == cpu.external_force
    assert scripted_demos.ScriptedDemos(
        **{**alg["scripted_demos"], "objects": tuple(alg["scripted_demos"]["objects"])}
    ) == scripted_demos.ScriptedDemos(
        pushes=cpu.external_force, start_iteration=1398, decay_iterations=300, coef=0.1
    )
    assert bc.deviations[: len(cpu.deviations)] == cpu.deviations and len(bc.deviations) == len(cpu.deviations) + 1


@pytest.mark.parametrize("student_obs", [False, True])
def test_cloning_pulls_the_actor_to_the_script_and_its_decay_resumes(tmp_path, monkeypatch, student_obs):
    """Two iterations, then a resumed third: the cloning loss is logged and falls, its weight follows the decay
    across the resume (it is not restarted), and the checkpoint loads as a plain rsl-rl PPO one. The "RL w/ o_t"
    actor (student observation only) clones the same demonstrations through their o_t group."""
    from lab.diagnosis.progress import _scalars
    from lerobot_blindgrasp.teacher import train

    full = 3.0
    demos = scripted_demos.ScriptedDemos(
        objects=("capsule_small",), episodes_per_object=3, decay_iterations=3, batch_size=256, coef=full
    )
    short = replace(
        teacher_presets.TEACHER_PRESETS["cpu_bc_joint"],
        max_iterations=3,
        runner=demos.runner_cfg(teacher_presets.CPU.runner),
    )
    monkeypatch.setitem(teacher_presets.TEACHER_PRESETS, "cpu_bc_joint", short)
    out = tmp_path / "bc"
    previous = signal.getsignal(signal.SIGTERM)  # the trainer installs its own SIGTERM handler
    try:
        for its in (2, 3):
            train.train(
                train.TrainTeacherConfig(
                    output_dir=out,
                    preset="cpu_bc_joint",
                    iterations=its,
                    num_envs=18,
                    threads=1,
                    export=False,
                    student_obs=student_obs,
                )
            )
    finally:
        signal.signal(signal.SIGTERM, previous)
    s = _scalars(out)
    weights = [s["Loss/bc_weight"][i] for i in range(3)]  # iterations 0, 1 and (resumed) 2
    assert weights == pytest.approx([full, full * 2 / 3, full / 3])
    if (
        student_obs
    ):  # o_t does not show where the object is, which the script's actions depend on: no fit to expect
        assert all(0 < s["Loss/bc"][i] < 10 for i in range(3))
    else:
        assert s["Loss/bc"][1] < s["Loss/bc"][0]
    assert all(s["Loss/bc_grad_ratio"][i] > 0 for i in range(3))  # the cloning gradient's size next to PPO's
    assert "actor_state_dict" in torch.load(out / "model_2.pt", weights_only=False)


def test_script_success_table_per_object(capsys):
    from lab.diagnosis import script_success

    script_success.main(["--objects=capsule_small,cuboid_a_large", "--episodes_per_object=2", "--pushes=false"])
    out = capsys.readouterr().out
    assert "| cuboid_a_large | 0% (0/2) |" in out and "| capsule_small |" in out and "| **all** |" in out


def test_a_staged_preset_trains_the_stage_it_continues_first(tmp_path, monkeypatch):
    """One command from scratch: the preset it continues runs first in stages/<name>, this one resumes its last
    checkpoint, and running the same command again resumes rather than restarting either stage."""
    from lerobot_blindgrasp.teacher import train

    second = replace(teacher_presets.QUICK, name="quick_second", stages=(("quick", 2),))
    monkeypatch.setitem(teacher_presets.TEACHER_PRESETS, "quick_second", second)
    out = tmp_path / "staged"
    cfg = train.TrainTeacherConfig(
        output_dir=out, preset="quick_second", iterations=4, num_envs=18, threads=1, export=False
    )
    previous = signal.getsignal(signal.SIGTERM)
    try:
        assert train.train(cfg) == out / "model_3.pt"
        first = json.loads((out / "stages" / "quick" / "train_summary.json").read_text())
        assert first["iterations"] == 2 and not first["interrupted"]
        assert torch.equal(
            torch.load(out / "model_1.pt", weights_only=False)["actor_state_dict"]["mlp.0.weight"],
            torch.load(out / "stages" / "quick" / "model_1.pt", weights_only=False)["actor_state_dict"][
                "mlp.0.weight"
            ],
        )
        assert json.loads((out / "teacher_config.json").read_text())["preset"] == "quick_second"
        stamp = (out / "stages" / "quick" / "model_1.pt").stat().st_mtime_ns
        train.train(cfg)  # done: resumes at its last checkpoint, does not retrain the first stage
        assert (out / "stages" / "quick" / "model_1.pt").stat().st_mtime_ns == stamp
    finally:
        signal.signal(signal.SIGTERM, previous)
