"""Loading a trained teacher for inference (evaluation, demo collection), from a training checkpoint.

A checkpoint directory holds rsl-rl's `model_<it>.pt` files and our `teacher_config.json` (preset, variant, env
settings). The actor is rebuilt with rsl-rl's own `MLPModel` and run deterministically (mean) or stochastically
(sampled from its Gaussian), which demo collection needs; the JIT/ONNX exports only carry the mean.
"""

from __future__ import annotations

import hashlib
import json
import re
from pathlib import Path

import numpy as np
import torch
from rsl_rl.models import MLPModel
from tensordict import TensorDict

from lerobot_blindgrasp import spec

CONFIG_NAME = "teacher_config.json"


def latest_checkpoint(run_dir: Path) -> Path | None:
    ckpts = sorted(run_dir.glob("model_*.pt"), key=lambda p: int(re.findall(r"\d+", p.stem)[-1]))
    return ckpts[-1] if ckpts else None


def resolve_checkpoint(path: str | Path) -> Path:
    """A checkpoint file, or a run directory (its latest checkpoint). Clear errors for anything else."""
    p = Path(path)
    if p.is_dir():
        ckpt = latest_checkpoint(p)
        if ckpt is None:
            raise FileNotFoundError(f"no model_<iteration>.pt checkpoint in {p}")
        return ckpt
    if not p.is_file():
        raise FileNotFoundError(f"teacher checkpoint not found: {p}")
    if not (p.parent / CONFIG_NAME).is_file():
        raise FileNotFoundError(f"{p} has no {CONFIG_NAME} beside it; is it a blindgrasp teacher checkpoint?")
    return p


def file_sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


class TeacherPolicy:
    """Numpy-in, numpy-out teacher: obs dict (N, ...) -> delta-theta actions (N, 9)."""

    def __init__(self, checkpoint: str | Path, device: str = "cpu"):
        self.checkpoint = resolve_checkpoint(checkpoint)
        self.config = json.loads((self.checkpoint.parent / CONFIG_NAME).read_text())
        runner = self.config["runner"]
        actor_cfg = {k: v for k, v in runner["actor"].items() if k != "class_name"}
        dims = {"policy": spec.STATE_DIM, "privileged": spec.PRIVILEGED_DIM}
        dummy = TensorDict({k: torch.zeros(1, d) for k, d in dims.items()}, batch_size=[1])
        self.obs_groups = runner["obs_groups"]
        self.actor = MLPModel(dummy, self.obs_groups, "actor", spec.NUM_JOINTS, **actor_cfg)
        state = torch.load(self.checkpoint, map_location=device, weights_only=False)
        self.actor.load_state_dict(state["actor_state_dict"])
        self.actor.to(device).eval()
        self.device = device
        self.iteration = int(state.get("iter", -1))
        self.sha256 = file_sha256(self.checkpoint)

    @torch.inference_mode()
    def __call__(self, obs: dict[str, np.ndarray], stochastic: bool = False) -> np.ndarray:
        n = next(iter(obs.values())).shape[0]
        td = TensorDict({k: torch.from_numpy(np.asarray(v)).to(self.device) for k, v in obs.items()}, batch_size=[n])
        return self.actor(td, stochastic_output=stochastic).cpu().numpy().astype(np.float64)
