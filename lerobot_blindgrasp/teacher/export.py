"""`blindgrasp-export-teacher`: a training checkpoint as a shippable teacher (no pickle): `teacher.safetensors`
(the actor only), `teacher_config.json` (the run's config plus a `weights` block) and a `README.md` card, which a
card already there survives unless `--overwrite_card=true`.

    blindgrasp-export-teacher --source=runs/teacher_cpu --output_dir=models/teacher_cpu [--push_to_hub=you/name]
"""

from __future__ import annotations

import json
import sys
from dataclasses import dataclass
from pathlib import Path

from lerobot_blindgrasp import durable, project
from lerobot_blindgrasp.cards import model_cards
from lerobot_blindgrasp.cli import parse_config
from lerobot_blindgrasp.teacher import policy

CARD_NAME = "README.md"
PACKAGE = "lerobot_policy_blindgrasp"


@dataclass
class ExportTeacherConfig:
    """A training checkpoint as a shippable teacher folder: safetensors weights, config, card."""

    source: Path | None = None  # training run directory (its latest model_<it>.pt) or a checkpoint file
    output_dir: Path | None = None  # folder to write teacher.safetensors, teacher_config.json, README.md
    overwrite_card: bool = False  # replace a README.md already in output_dir
    push_to_hub: str | None = None  # also upload the folder to this Hub model repo (USER/NAME)
    private: bool = False  # create the Hub repo as private

    def __post_init__(self):
        if self.source is None:
            raise ValueError("--source is required (a training run directory or checkpoint file)")
        if self.output_dir is None:
            raise ValueError("--output_dir is required (the teacher folder to write)")


def export_teacher(source: str | Path, out_dir: str | Path, overwrite_card: bool = False) -> Path:
    """Write OUT_DIR from a run directory (its latest model_<it>.pt) or a checkpoint file. Returns OUT_DIR."""
    from safetensors.torch import save_file

    ckpt = policy.resolve_checkpoint(source)
    if ckpt.suffix != ".pt":
        raise policy.TeacherError(f"{ckpt} is already exported; copy its folder instead")
    state, iteration = policy.load_actor_state(ckpt)
    # Load it the way users will, before writing anything: a checkpoint that does not fit its config fails here.
    policy.TeacherPolicy(ckpt)
    config = json.loads((ckpt.parent / policy.CONFIG_NAME).read_text())
    config["observation_layout"] = policy.observation_layout()
    config["weights"] = {
        "format": policy.FORMAT,
        "file": policy.WEIGHTS_NAME,
        "iteration": iteration,
        "source_checkpoint": ckpt.name,
        "source_sha256": policy.file_sha256(ckpt),
    }
    if (summary := ckpt.parent / "train_summary.json").is_file():
        config["train_summary"] = json.loads(summary.read_text())
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    # safetensors wants contiguous tensors that share no memory.
    with durable.atomic_path(out / policy.WEIGHTS_NAME) as tmp:
        save_file({k: v.detach().contiguous().clone() for k, v in state.items()}, str(tmp),
                  metadata={"format": policy.FORMAT})  # fmt: skip
    durable.atomic_write_text(out / policy.CONFIG_NAME, json.dumps(config, indent=2) + "\n")
    if overwrite_card or not (out / CARD_NAME).exists():
        durable.atomic_write_text(out / CARD_NAME, card(config))
    return out


def card(config: dict) -> str:
    w = config["weights"]
    uses = "\n".join(model_cards.teacher_uses("THIS_FOLDER", config))
    return f"""---
library_name: {PACKAGE}
tags: [lerobot, robotics, blindgrasp, reinforcement-learning, ppo]
---
# blindgrasp PPO teacher (`{config.get("preset")}` preset, iteration {w["iteration"]})

Privileged-observation PPO teacher for three-finger blind grasping (rsl-rl MLP actor, {config["runner"]["actor"]["hidden_dims"]}),
used to collect the curated demonstrations the `blindgrasp_transformer` student learns from.

- `teacher.safetensors`: the actor's state dict (MLP, Gaussian std, observation normalizer); no pickle.
- `teacher_config.json`: preset, reward, PPO settings, observation layout, source checkpoint `{w["source_checkpoint"]}`
  (sha256 `{w["source_sha256"]}`).

Use it (`{project.install_line()}`):

```bash
{uses}
```

Made by: `{config.get("command", "?")}` (env seeds from {config.get("seed")}, {config.get("num_envs")} envs).
{project.code_line()}
"""


def push_teacher(folder: str | Path, repo_id: str, private: bool | None = None) -> str:
    """Upload a teacher folder to a Hub model repo (weights, config, card). Returns the repo URL."""
    from huggingface_hub import HfApi

    folder = Path(folder)
    policy.TeacherPolicy(folder)  # refuse to upload something that does not load
    if policy.resolve_checkpoint(folder).suffix != ".safetensors":
        raise policy.TeacherError(
            f"{folder} holds a training checkpoint; export it first (blindgrasp-export-teacher)"
        )
    api = HfApi()
    api.create_repo(repo_id, repo_type="model", private=private, exist_ok=True)
    api.upload_folder(
        repo_id=repo_id,
        folder_path=str(folder),
        repo_type="model",
        allow_patterns=[policy.WEIGHTS_NAME, policy.CONFIG_NAME, CARD_NAME],
        commit_message="Upload blindgrasp teacher",
    )
    return f"https://huggingface.co/{repo_id}"


def main(argv=None) -> None:
    cfg = parse_config(ExportTeacherConfig, argv)
    try:
        out = export_teacher(cfg.source, cfg.output_dir, cfg.overwrite_card)
        print(f"wrote {out / policy.WEIGHTS_NAME}, {out / policy.CONFIG_NAME}, {out / CARD_NAME}")
        if cfg.push_to_hub:
            print(f"pushed: {push_teacher(out, cfg.push_to_hub, cfg.private or None)}")
    except policy.TeacherError as e:
        print(f"error: {e}", file=sys.stderr)
        raise SystemExit(2) from None
    except OSError as e:  # network, auth, offline mode
        print(f"error: upload to the Hub failed ({type(e).__name__}: {e})", file=sys.stderr)
        raise SystemExit(1) from None


if __name__ == "__main__":
    main()
