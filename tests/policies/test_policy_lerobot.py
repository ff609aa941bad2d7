"""blindgrasp_transformer inside LeRobot: real `lerobot-train` CLI, checkpoint reload, real dataset windows.

A tiny state-only LeRobotDataset (spec.dataset_features(), absolute-target actions) is written once per module.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
from lerobot.datasets import LeRobotDataset, resolve_delta_timestamps
from lerobot.policies.factory import make_policy, make_pre_post_processors
from lerobot.processor import PolicyProcessorPipeline
from lerobot.utils.constants import ACTION, OBS_STATE
from torch.utils.data import default_collate

from lerobot_blindgrasp import project, spec
from lerobot_blindgrasp.policies.blindgrasp_transformer import (
    BlindgraspTransformerConfig,
    BlindgraspTransformerPolicy,
)
from lerobot_blindgrasp.policies.blindgrasp_transformer.processor_blindgrasp_transformer import (
    Q_NOW,
    normalized_delta_to_target,
)

REPO_ID = "local/blindgrasp_policy_test"
EPISODE_LENGTHS = (36, 40)  # longer than the 30-step context, so windows go from fully padded to unpadded
TINY = ["--policy.size=quick", "--policy.n_layers=1", "--policy.embed_dim=32", "--policy.head_hidden_dims=[64]"]


pytestmark = pytest.mark.usefixtures("one_torch_thread")


@pytest.fixture(scope="module")
def dataset_root(tmp_path_factory) -> Path:
    """Synthetic episodes: q drifts towards commanded targets, target = q_now + delta with |delta| <= 0.3 rad."""
    root = tmp_path_factory.mktemp("policy_data") / "ds"
    ds = LeRobotDataset.create(
        REPO_ID, fps=spec.CONTROL_HZ, features=spec.dataset_features(), root=root, use_videos=False
    )
    rng = np.random.default_rng(0)
    for length in EPISODE_LENGTHS:
        q = spec.HOME_POSE + rng.uniform(-0.2, 0.2, spec.NUM_JOINTS)
        for _ in range(length):
            forces = np.clip(rng.normal(1.0, 1.0, spec.NUM_FORCES), 0.0, None)
            delta = rng.uniform(-spec.ACTION_BOUND_RAD, spec.ACTION_BOUND_RAD, spec.NUM_JOINTS)
            ds.add_frame(
                {
                    OBS_STATE: np.concatenate([q, forces]).astype(np.float32),
                    ACTION: (q + delta).astype(np.float32),
                    "task": "grasp",
                }
            )
            q = q + 0.5 * delta
        ds.save_episode()
    ds.finalize()
    return root


@pytest.mark.slow
def test_lerobot_train_cli_writes_a_self_contained_checkpoint(dataset_root, tmp_path):
    out = tmp_path / "train"
    env = dict(os.environ, HF_HUB_OFFLINE="1", OMP_NUM_THREADS="1", HF_LEROBOT_HOME=str(tmp_path / "hf_lerobot"))
    # No --*.discover_packages_path: the plugin must be found through its distribution name.
    cmd = [
        str(Path(sys.executable).with_name("lerobot-train")),
        "--policy.type=blindgrasp_transformer",
        f"--dataset.repo_id={REPO_ID}",
        f"--dataset.root={dataset_root}",
        "--policy.push_to_hub=false",
        "--policy.device=cpu",
        *TINY,
        "--policy.scheduler_constant_steps=2",
        "--steps=4",
        "--batch_size=4",
        "--save_freq=4",
        "--log_freq=1",
        "--num_workers=0",
        f"--output_dir={out}",
    ]
    proc = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    assert "step:4" in proc.stdout + proc.stderr

    ckpt = out / "checkpoints" / "000004" / "pretrained_model"
    for name in ("config.json", "model.safetensors", "policy_preprocessor.json", "policy_postprocessor.json"):
        assert (ckpt / name).is_file(), name
    train_cfg = json.loads((ckpt / "train_config.json").read_text())
    assert train_cfg["optimizer"]["type"] == "adamw"
    assert (train_cfg["optimizer"]["lr"], train_cfg["optimizer"]["weight_decay"]) == (1e-4, 0.01)
    assert train_cfg["scheduler"]["type"] == "blindgrasp_constant_then_linear"
    assert train_cfg["scheduler"]["num_constant_steps"] == 2
    steps = json.loads((out / "checkpoints" / "000004" / "training_state" / "training_step.json").read_text())
    assert steps["step"] == 4

    policy = BlindgraspTransformerPolicy.from_pretrained(ckpt)
    assert (policy.config.n_layers, policy.config.embed_dim, policy.config.head_hidden_dims) == (1, 32, [64])
    assert policy.config.n_obs_steps == 30
    pre_json = json.loads((ckpt / "policy_preprocessor.json").read_text())
    post_json = json.loads((ckpt / "policy_postprocessor.json").read_text())
    pre_steps = [s.get("registry_name") for s in pre_json["steps"]]
    assert pre_steps[3:] == ["blindgrasp_target_to_delta", "normalizer_processor"]
    assert pre_json["steps"][3]["config"] == {"action_bound": spec.ACTION_BOUND_RAD}
    assert [s.get("registry_name") for s in post_json["steps"]] == ["unnormalizer_processor", "device_processor"]

    # Both ways LeRobot loads processors give a working pre -> policy -> post loop that outputs joint targets.
    loaded = PolicyProcessorPipeline.from_pretrained(ckpt, "policy_preprocessor.json")
    assert [type(s).__name__ for s in loaded.steps][3] == "TargetToNormalizedDeltaStep"
    pre, post = make_pre_post_processors(policy.config, pretrained_path=str(ckpt))
    frames = LeRobotDataset(REPO_ID, root=dataset_root)
    policy.reset()
    with torch.inference_mode():
        for i in range(3):
            state = frames[i][OBS_STATE]
            target = post(policy.select_action(pre({OBS_STATE: state})))
            assert target.shape == (1, spec.ACTION_DIM)
            delta = target[0] - state[spec.STATE_JOINT_SLICE]
            assert delta.abs().max() <= spec.ACTION_BOUND_RAD + 1e-6
            assert delta.abs().max() > 0  # a real prediction, not q_now echoed back


def test_rolling_context_equals_lerobot_training_windows(dataset_root):
    """Feeding an episode step by step through select_action == a batched forward on LeRobot's delta-index windows
    of the same frames (padded start included), after the same processors lerobot-train and lerobot-eval use."""
    meta = LeRobotDataset(REPO_ID, root=dataset_root).meta
    config = BlindgraspTransformerConfig(size="quick", device="cpu")
    policy = make_policy(config, ds_meta=meta).eval()
    with torch.no_grad():  # unit-gain weights so that every input visibly moves the output
        for param in policy.model.parameters():
            if param.ndim >= 2:
                param.normal_(0.0, param.shape[-1] ** -0.5)
    pre, post = make_pre_post_processors(config, dataset_stats=meta.stats)

    dataset = LeRobotDataset(REPO_ID, root=dataset_root, delta_timestamps=resolve_delta_timestamps(config, meta))
    # The second episode: its padding must repeat its own first frame, not the end of the previous episode.
    start = EPISODE_LENGTHS[0]
    items = [dataset[start + i] for i in range(EPISODE_LENGTHS[1])]
    batch = default_collate(items)
    assert batch[f"{OBS_STATE}_is_pad"][0].sum() == config.n_obs_steps - 1
    assert not batch[f"{OBS_STATE}_is_pad"][-1].any()

    with torch.no_grad():
        train_batch = pre({k: batch[k] for k in (OBS_STATE, f"{OBS_STATE}_is_pad", ACTION)})
        batched = policy.model(train_batch[OBS_STATE], train_batch[f"{OBS_STATE}_is_pad"])
        # q_now = the last frame of each window, as the preprocessor passes it along
        batched_targets = post(normalized_delta_to_target(batched, train_batch[Q_NOW]))

    policy.reset()
    stepped, stepped_targets = [], []
    with torch.inference_mode():
        for item in items:
            obs = pre({OBS_STATE: item[OBS_STATE][-1]})  # lerobot-eval sends one (12,) observation per step
            target = post(policy.select_action(obs))
            stepped.append((target - obs[Q_NOW]) / spec.ACTION_BOUND_RAD)
            stepped_targets.append(target)
    torch.testing.assert_close(torch.cat(stepped), batched, atol=1e-5, rtol=1e-5)
    torch.testing.assert_close(torch.cat(stepped_targets), batched_targets, atol=1e-5, rtol=1e-5)
    # The training target the model is fit to is the dataset action seen as delta / 0.3.
    q_now = batch[OBS_STATE][:, -1, spec.STATE_JOINT_SLICE]
    torch.testing.assert_close(
        train_batch[ACTION], ((batch[ACTION] - q_now) / spec.ACTION_BOUND_RAD).clamp(-1, 1), atol=1e-5, rtol=0
    )


# Run the real lerobot-train entry point in a subprocess with only huggingface_hub's network entry points replaced:
# create_repo answers with the repo URL, the card check parses the card's YAML locally instead of asking the Hub,
# and upload_folder (the last call, which validates and commits on the Hub) copies the files it would send,
# filtered by the same allow/ignore patterns, to a folder. HF_HUB_OFFLINE=1 stays set, so any other network call
# fails the test.
HUB_CAPTURE = r"""
import os, shutil, sys
from pathlib import Path
import yaml
from huggingface_hub import HfApi
from huggingface_hub.hf_api import CommitInfo, RepoUrl
from huggingface_hub.repocard import RepoCard
from huggingface_hub.utils import filter_repo_objects

OUT = Path(os.environ["HUB_CAPTURE"])

def create_repo(self, repo_id, **kwargs):
    return RepoUrl(f"https://huggingface.co/{repo_id}")

def upload_folder(self, *, repo_id, folder_path, path_in_repo=None, commit_message="", allow_patterns=None,
                  ignore_patterns=None, **kwargs):
    folder = Path(folder_path)
    files = [str(p.relative_to(folder)) for p in folder.rglob("*") if p.is_file()]
    for rel in filter_repo_objects(files, allow_patterns=allow_patterns, ignore_patterns=ignore_patterns):
        dest = OUT / repo_id / (path_in_repo or "") / rel
        dest.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(folder / rel, dest)
    return CommitInfo(f"https://huggingface.co/{repo_id}/commit/{'0' * 40}", commit_message, "", "0" * 40)

def validate(self, repo_type=None):
    assert isinstance(yaml.safe_load(str(self).split("---")[1]), dict)

HfApi.create_repo, HfApi.upload_folder, RepoCard.validate = create_repo, upload_folder, validate
if __name__ == "__main__":
    from lerobot.scripts.lerobot_train import main
    sys.argv[0] = "lerobot-train"
    main()
"""


@pytest.mark.slow
def test_lerobot_train_pushes_the_policy_to_the_hub_with_an_install_card(dataset_root, tmp_path):
    captured = tmp_path / "hub"
    env = dict(os.environ, HF_HUB_OFFLINE="1", OMP_NUM_THREADS="1", HUB_CAPTURE=str(captured),
               HF_LEROBOT_HOME=str(tmp_path / "hf_lerobot"))  # fmt: skip
    cmd = [sys.executable, "-c", HUB_CAPTURE, "--policy.type=blindgrasp_transformer", f"--dataset.repo_id={REPO_ID}",
           f"--dataset.root={dataset_root}", "--policy.push_to_hub=true", "--policy.repo_id=you/blindgrasp_student",
           "--policy.device=cpu", *TINY, "--steps=1", "--batch_size=2", "--save_freq=1", "--num_workers=0",
           f"--output_dir={tmp_path / 'train'}", "--wandb.enable=false"]  # fmt: skip
    proc = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    repo = captured / "you" / "blindgrasp_student"
    for name in ("config.json", "model.safetensors", "train_config.json", "README.md",
                 "policy_preprocessor.json", "policy_postprocessor.json"):  # fmt: skip
        assert (repo / name).is_file(), name
    card = (repo / "README.md").read_text()
    assert project.install_line() in card and "--policy.path=you/blindgrasp_student" in card
    assert "lerobot_policy_blindgrasp" in card.split("---")[1]  # a tag in the card's metadata
    # What was uploaded is a complete policy: it loads as LeRobot loads a --policy.path download.
    policy = BlindgraspTransformerPolicy.from_pretrained(repo)
    assert policy.config.repo_id == "you/blindgrasp_student" and policy.config.n_layers == 1
