"""Teacher: the rsl-rl VecEnv adapter contract, a short PPO run that saves/reloads/resumes, presets, eval table."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
import torch
from tensordict import TensorDict

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.presets import teacher as presets
from lerobot_blindgrasp.presets import teacher_configs
from lerobot_blindgrasp.sim import objects, randomization, rewards
from lerobot_blindgrasp.sim.batched_config import GraspEnvConfig
from lerobot_blindgrasp.sim.batched_env import BatchedGraspEnv
from lerobot_blindgrasp.teacher import evaluate
from lerobot_blindgrasp.teacher.policy import TeacherPolicy
from lerobot_blindgrasp.teacher.vecenv import RslRlGraspEnv


def test_vecenv_contract_shapes_dtypes_dones_timeouts_and_logs():
    env = BatchedGraspEnv(GraspEnvConfig(num_envs=18, seed=0, episode_s=0.25, dr=randomization.NO_DR))
    vec = RslRlGraspEnv(env)
    obs = vec.get_observations()
    assert isinstance(obs, TensorDict) and obs.batch_size == torch.Size([18])
    assert obs["policy"].shape == (18, spec.STATE_DIM) and obs["policy"].dtype == torch.float32
    assert obs["privileged"].shape == (18, spec.PRIVILEGED_DIM)
    assert vec.num_actions == 9 and vec.max_episode_length == 5
    for t in range(5):
        obs, rew, dones, extras = vec.step(torch.zeros(18, 9))
        assert rew.shape == (18,) and rew.dtype == torch.float32
        assert dones.dtype == torch.bool and extras["time_outs"].dtype == torch.bool
        if t < 4:
            assert not dones.any()
    # Fifth step: every episode times out, is auto-reset, and its terms are logged.
    assert dones.all() and extras["time_outs"].all()
    log = extras["log"]
    for term in ("task", "incentive", "joint_limit", "action", "action_rate", "reach"):
        assert f"Episode_Reward/{term}" in log
    assert log["Episode_Termination/time_out"] == 1.0
    assert {f"Success/{n}" for n in objects.PAPER_OBJECTS} <= set(log)
    assert (env.episode_length == 0).all()
    # rsl-rl's init_at_random_ep_len writes episode_length_buf; the env must see it.
    vec.episode_length_buf = torch.full((18,), 3)
    assert (env.episode_length == 3).all()


def test_presets_paper_is_table_iii_exactly():
    p = presets.PAPER
    alg = p.runner["algorithm"]
    assert p.num_envs == 9000 and p.max_iterations == 4500 and p.runner["num_steps_per_env"] == 24
    assert p.runner["actor"]["hidden_dims"] == [512, 256, 128] == p.runner["critic"]["hidden_dims"]
    assert p.runner["actor"]["activation"] == "elu"
    assert (alg["num_learning_epochs"], alg["num_mini_batches"], alg["learning_rate"]) == (5, 6, 1e-3)
    assert (alg["schedule"], alg["desired_kl"], alg["entropy_coef"]) == ("adaptive", 0.01, 0.003)
    assert (alg["value_loss_coef"], alg["clip_param"], alg["gamma"], alg["lam"], alg["max_grad_norm"]) == (
        1.0,
        0.2,
        0.99,
        0.95,
        1.0,
    )
    assert (
        p.reward.weight("reach") == 0.0
        and p.reward.weights == {**rewards.PAPER_WEIGHTS, "reach": 0.0, "touch": 0.0}
        and p.deviations == ()
        and p.external_force
    )
    assert presets.CPU.deviations and presets.CPU.reward.weight("reach") > 0


def test_variants():
    v = teacher_configs.Variant(no_incentive=True, student_obs=True).apply(presets.CPU)
    assert v.reward.weight("incentive") == 0.0 == v.reward.weight("touch")
    assert v.runner["obs_groups"] == {"actor": ["policy"], "critic": ["policy"]}
    assert presets.CPU.reward.weight("incentive") == 0.2  # the preset itself is untouched


@pytest.fixture(scope="module")
def quick_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("teacher") / "run"
    cmd = [
        sys.executable,
        "-m",
        "lerobot_blindgrasp.teacher.train",
        "--preset",
        "quick",
        "--output_dir",
        str(out),
        "--iterations",
        "3",
        "--num_envs",
        "36",
        "--threads",
        "1",
    ]
    subprocess.run(cmd, check=True, capture_output=True, timeout=300)
    return out, cmd


@pytest.mark.slow
def test_short_ppo_run_saves_exports_and_reloads_deterministically(quick_run):
    out, _ = quick_run
    assert (out / "model_2.pt").exists() and (out / "exported" / "teacher.pt").exists()
    summary = json.loads((out / "train_summary.json").read_text())
    assert summary["env_steps_this_session"] == 3 * 24 * 36 and summary["physics_resets"] == 0
    assert summary["iterations"] == 3 and not summary["interrupted"]
    assert (out / "learning_curve.png").stat().st_size > 1000
    env = BatchedGraspEnv(GraspEnvConfig(num_envs=4, seed=5))
    obs = env.reset()
    a1 = TeacherPolicy(out)(obs)
    a2 = TeacherPolicy(out / "model_2.pt")(obs)
    np.testing.assert_array_equal(a1, a2)
    assert a1.shape == (4, 9) and np.isfinite(a1).all()
    # The exported TorchScript actor gives the same deterministic actions as the checkpoint.
    jit = torch.jit.load(str(out / "exported" / "teacher.pt"))
    np.testing.assert_allclose(jit(torch.from_numpy(obs["privileged"])).detach().numpy(), a1, atol=1e-5)
    # Stochastic actions differ from the mean.
    torch.manual_seed(0)
    assert not np.allclose(TeacherPolicy(out)(obs, stochastic=True), a1)


@pytest.mark.slow
def test_rerunning_the_command_resumes(quick_run, one_torch_thread):
    out, cmd = quick_run
    more = [*cmd[:-4], "--iterations", "4", "--num_envs", "36", "--threads", "1"]
    subprocess.run(more, check=True, capture_output=True, timeout=300)
    assert (out / "model_3.pt").exists()
    assert torch.load(out / "model_3.pt", weights_only=False)["iter"] == 3
    # A different preset in the same folder is refused instead of silently mixing runs. The refusal comes before
    # anything is built, so this process runs the command's own parse and training call (a SystemExit with the
    # message is what the command prints to stderr, exiting 1) without a second interpreter's imports.
    from lerobot_blindgrasp.cli import parse_config
    from lerobot_blindgrasp.teacher import train

    assert cmd[3:5] == ["--preset", "quick"]
    with pytest.raises(SystemExit, match=r"holds a run with a different 'preset'; use another --output_dir"):
        train.train(parse_config(train.TrainTeacherConfig, ["--preset", "cpu", *cmd[5:]]))
    assert torch.load(out / "model_3.pt", weights_only=False)["iter"] == 3  # the run is untouched


@pytest.mark.slow
def test_sigterm_saves_a_checkpoint_and_a_summary(tmp_path):
    import signal
    import time

    out = tmp_path / "run"
    cmd = [
        sys.executable,
        "-m",
        "lerobot_blindgrasp.teacher.train",
        "--preset",
        "quick",
        "--output_dir",
        str(out),
        "--iterations",
        "500",
        "--num_envs",
        "18",
        "--threads",
        "1",
        "--export=false",
    ]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.time() + 240
    while not (out / "model_0.pt").exists() and time.time() < deadline:
        time.sleep(0.5)
    assert (out / "model_0.pt").exists()
    time.sleep(2.0)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err[-2000:]
    assert "interrupted: saved" in err
    summary = json.loads((out / "train_summary.json").read_text())
    assert summary["interrupted"] and summary["iterations"] >= 1
    assert TeacherPolicy(out).iteration == summary["iterations"] - 1


def test_bad_teacher_path_is_a_clear_error(tmp_path):
    with pytest.raises(FileNotFoundError, match="not found"):
        TeacherPolicy(tmp_path / "nope.pt")
    with pytest.raises(FileNotFoundError, match="no model_"):
        TeacherPolicy(tmp_path)


@pytest.mark.slow
def test_eval_outputs_table_json_and_chart(quick_run, tmp_path):
    out, _ = quick_run
    res = evaluate.evaluate_teacher(TeacherPolicy(out), ("sphere_small", "cuboid_a_medium"), 2, progress=False)
    evaluate.write_outputs(res, tmp_path)
    data = json.loads((tmp_path / "eval.json").read_text())
    assert set(data["modes"]) == {"deterministic", "stochastic"}
    for mode in data["modes"].values():
        assert set(mode["per_object"]) == {"sphere_small", "cuboid_a_medium"}
        assert all(0.0 <= r["success_rate"] <= 1.0 for r in mode["per_object"].values())
    md = (tmp_path / "eval.md").read_text().splitlines()
    assert md[0].startswith("| object | deterministic success [95 % CI] | stochastic success [95 % CI]")
    assert any(line.startswith("| sphere_small |") for line in md)
    assert any(line.startswith("| **1 medium objects**") for line in md)
    assert any(line.startswith("| **all 2**") for line in md)
    assert (tmp_path / "eval.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_the_shipped_teachers_eval_agrees_across_backends():
    """The same paired start states on MuJoCo Warp (its CPU device here) as on mujoco.batch: medium objects, which
    the shipped teacher grasps on every one of seed 1000's states on both backends, so any flip is a defect."""
    from lerobot_blindgrasp.teacher.policy import default_teacher

    with pytest.raises(ValueError, match="backend"):
        evaluate.EvalTeacherConfig(backend="physx")
    teacher, names = TeacherPolicy(default_teacher()), ("cylinder_a_medium",)
    runs = {
        b: evaluate.evaluate_teacher(teacher, names, 3, modes=("deterministic",), progress=False, backend=b)
        for b in ("batch", "warp")
    }
    assert [r["backend"] for r in runs.values()] == ["batch", "warp"]
    flags = [r["modes"]["deterministic"]["per_object"]["cylinder_a_medium"]["successes"] for r in runs.values()]
    assert flags[0] == flags[1] == [True] * 3
