"""The shipped teacher: safetensors + JSON config, loaded without unpickling; export from rsl-rl run dirs; the
default every command falls back to; its Hub push up to the network; one-line errors for what users get wrong."""

from __future__ import annotations

import json
import pickle
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch
from safetensors.torch import load_file

from lerobot_blindgrasp import shipped as shipped_files
from lerobot_blindgrasp import spec
from lerobot_blindgrasp.sim import objects
from lerobot_blindgrasp.teacher import evaluate, export, policy
from lerobot_blindgrasp.teacher.policy import TeacherError, TeacherPolicy


def _obs(n: int = 6, seed: int = 0) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    return {
        "policy": rng.normal(size=(n, spec.STATE_DIM)).astype(np.float32),
        "privileged": rng.normal(size=(n, spec.PRIVILEGED_DIM)).astype(np.float32),
    }


@pytest.fixture(scope="module")
def shipped() -> TeacherPolicy:
    return TeacherPolicy(policy.default_teacher())


@pytest.fixture
def run_dir(shipped, tmp_path) -> Path:
    """A training run dir as blindgrasp-train-teacher leaves it: rsl-rl's checkpoint dict and teacher_config.json
    (without the export's extra blocks), holding the shipped actor's real weights."""
    run = tmp_path / "run"
    run.mkdir()
    actor = load_file(str(shipped.checkpoint))
    critic = {k: torch.zeros_like(v) for k, v in actor.items()}  # present in real checkpoints, unused here
    torch.save({"actor_state_dict": actor, "critic_state_dict": critic, "optimizer_state_dict": {},
                "iter": 7, "infos": None}, run / "model_7.pt")  # fmt: skip
    cfg = {k: v for k, v in shipped.config.items() if k not in ("weights", "observation_layout", "train_summary")}
    (run / policy.CONFIG_NAME).write_text(json.dumps(cfg))
    return run


def test_the_shipped_teacher_is_safetensors_and_json_only(shipped):
    folder = policy.default_teacher()
    assert folder == shipped_files.path(policy.SHIPPED_TEACHER)
    assert shipped.checkpoint == folder / policy.WEIGHTS_NAME
    assert not list(folder.glob("*.pt")) and not list(folder.glob("*.pkl"))
    cfg = json.loads((folder / policy.CONFIG_NAME).read_text())
    assert cfg["weights"]["format"] == policy.FORMAT and cfg["weights"]["iteration"] == shipped.iteration
    assert cfg["observation_layout"]["privileged"] == [list(x) for x in spec.PRIVILEGED_LAYOUT]
    # The card says how it was made and how well it does, with its seeds.
    card = (folder / export.CARD_NAME).read_text()
    for needle in ("blindgrasp-train-teacher", "blindgrasp-eval-teacher", "seed", "%"):
        assert needle in card
    a = shipped(_obs())
    assert a.shape == (6, spec.NUM_JOINTS) and np.isfinite(a).all()


def test_export_of_a_run_dir_acts_exactly_like_its_checkpoint(run_dir, tmp_path, shipped):
    out = export.export_teacher(run_dir, tmp_path / "shipped")
    assert sorted(p.name for p in out.iterdir()) == sorted(["README.md", policy.CONFIG_NAME, policy.WEIGHTS_NAME])
    from_pt, from_st = TeacherPolicy(run_dir), TeacherPolicy(out)
    assert from_pt.checkpoint.name == "model_7.pt" and from_st.checkpoint.name == policy.WEIGHTS_NAME
    assert from_pt.iteration == from_st.iteration == 7
    obs = _obs()
    np.testing.assert_array_equal(from_pt(obs), from_st(obs))
    np.testing.assert_array_equal(from_st(obs), shipped(obs))
    torch.manual_seed(3)
    a = from_pt(obs, stochastic=True)
    torch.manual_seed(3)
    np.testing.assert_array_equal(a, from_st(obs, stochastic=True))  # the Gaussian std came along too
    cfg = json.loads((out / policy.CONFIG_NAME).read_text())
    assert cfg["weights"]["source_checkpoint"] == "model_7.pt"
    assert cfg["weights"]["source_sha256"] == policy.file_sha256(run_dir / "model_7.pt")
    # Its card gives the commands the shipped cards give (model_cards), run on this folder.
    assert (
        "```bash\nblindgrasp-eval-teacher --teacher=THIS_FOLDER --episodes=20\n" in (out / "README.md").read_text()
    )
    calibrated = export.card({**cfg, "joint_calibration_rad": 0.05})  # trained against a joint offset
    assert (
        "blindgrasp-collect-demos --teacher=THIS_FOLDER --joint_calibration_rad=0.05 \\\n  --output_dir"
        in calibrated
    )
    # The CLI does the same and keeps a hand-written card.
    (out / "README.md").write_text("my card")
    export.main([f"--source={run_dir}", f"--output_dir={out}"])
    assert (out / "README.md").read_text() == "my card"


class Payload:
    """Anything that is not plain tensors and containers would need unpickling code to load."""


def test_a_checkpoint_with_pickled_objects_is_refused_not_executed(run_dir):
    state = torch.load(run_dir / "model_7.pt", weights_only=True)
    state["infos"] = Payload()
    torch.save(state, run_dir / "model_8.pt", pickle_protocol=pickle.HIGHEST_PROTOCOL)
    with pytest.raises(TeacherError, match="cannot read .*model_8.pt"):
        TeacherPolicy(run_dir)


def test_clear_one_line_errors(run_dir, tmp_path, monkeypatch):
    cases = []
    with pytest.raises(TeacherError, match="does not exist") as e:
        TeacherPolicy(tmp_path / "missing")
    cases.append(e)
    student = tmp_path / "pretrained_model"
    student.mkdir()
    (student / "config.json").write_text(json.dumps({"type": "blindgrasp_transformer"}))
    with pytest.raises(
        TeacherError, match="LeRobot `blindgrasp_transformer` policy, not a blindgrasp teacher"
    ) as e:
        TeacherPolicy(student)
    cases.append(e)
    cfg = json.loads((run_dir / policy.CONFIG_NAME).read_text())
    cfg["observation_layout"] = {"privileged": [["joint_pos", 9]]}
    (run_dir / policy.CONFIG_NAME).write_text(json.dumps(cfg))
    with pytest.raises(TeacherError, match="another observation layout") as e:
        TeacherPolicy(run_dir)
    cases.append(e)
    del cfg["observation_layout"]
    cfg["runner"]["actor"]["hidden_dims"] = [64]  # weights of another network size
    (run_dir / policy.CONFIG_NAME).write_text(json.dumps(cfg))
    with pytest.raises(TeacherError, match="does not fit its config") as e:
        TeacherPolicy(run_dir)
    cases.append(e)
    monkeypatch.setattr(shipped_files, "folder", lambda kind: tmp_path / "site-packages")  # a non-editable install
    with pytest.raises(TeacherError, match="BLINDGRASP_TEACHER") as e:
        policy.default_teacher()
    cases.append(e)
    assert all("\n" not in str(c.value) for c in cases)
    monkeypatch.setenv(policy.TEACHER_ENV_VAR, str(run_dir))
    assert policy.default_teacher() == run_dir


def test_eval_teacher_defaults_to_the_shipped_teacher_and_its_seeds(tmp_path, capsys):
    evaluate.main(
        ["--episodes=2", "--objects=cuboid_b_large", "--modes=deterministic", f"--output_dir={tmp_path}"]
    )
    res = json.loads((tmp_path / "eval.json").read_text())
    assert res["checkpoint"] == str(policy.default_teacher() / policy.WEIGHTS_NAME)
    assert res["seed"] == spec.EVAL_SEED
    row = res["modes"]["deterministic"]["per_object"]["cuboid_b_large"]
    assert row["first_env_seed"] == spec.eval_env_seed(
        spec.EVAL_SEED, list(objects.CATALOGUE).index("cuboid_b_large")
    )
    assert "[95 % CI]" in capsys.readouterr().out


def test_teacher_eval_runs_the_start_states_lerobot_eval_runs():
    """Pairing: episode k of the teacher eval starts exactly where the lerobot-eval env starts for seed S + k."""
    from lerobot_blindgrasp.sim import gym_env, rewards

    seen = []

    def record(obs, stochastic=False):
        seen.append(obs["policy"].copy())
        return np.zeros((obs["policy"].shape[0], spec.NUM_JOINTS))

    evaluate._run_object(
        record, "sphere_medium", 3, spec.EVAL_SEED, "deterministic", rewards.RewardConfig(), "batch"
    )
    for k in range(3):
        env = gym_env.BlindGraspGymEnv("sphere_medium", render_mode=None)
        obs, _ = env.reset(seed=spec.EVAL_SEED + k)
        np.testing.assert_array_equal(obs["agent_pos"], seen[0][k])


def test_teacher_push_sends_weights_config_and_card(monkeypatch, tmp_path):
    from huggingface_hub import HfApi
    from huggingface_hub.hf_api import RepoUrl

    sent = {}
    monkeypatch.setattr(
        HfApi, "create_repo", lambda self, repo_id, **kw: RepoUrl(f"https://huggingface.co/{repo_id}")
    )

    def upload_folder(self, *, repo_id, folder_path, allow_patterns=None, **kw):  # the network call
        from huggingface_hub.utils import filter_repo_objects

        files = [p.name for p in Path(folder_path).iterdir()]
        sent[repo_id] = sorted(filter_repo_objects(files, allow_patterns=allow_patterns))

    monkeypatch.setattr(HfApi, "upload_folder", upload_folder)
    folder = tmp_path / "teacher"
    shutil.copytree(policy.default_teacher(), folder)
    (folder / "scratch.log").write_text("not for the Hub")
    assert export.push_teacher(folder, "you/blindgrasp_teacher") == "https://huggingface.co/you/blindgrasp_teacher"
    assert sent["you/blindgrasp_teacher"] == sorted(["README.md", policy.CONFIG_NAME, policy.WEIGHTS_NAME])
