"""Loading a trained teacher for inference (evaluation, demo collection) without unpickling anything: a shipped
folder (`teacher.safetensors` + `teacher_config.json`, as `blindgrasp-export-teacher` writes them) or a training
run (rsl-rl's `model_<it>.pt`, read with `weights_only=True`). The actor is rsl-rl's `MLPModel` rebuilt from the
config, run on its mean or sampled from its Gaussian (demos need both; the JIT/ONNX exports carry only the mean).
"""

from __future__ import annotations

import hashlib
import json
import os
import re
from pathlib import Path

import numpy as np
import torch
from rsl_rl.models import MLPModel
from tensordict import TensorDict

from lerobot_blindgrasp import shipped, spec
from lerobot_blindgrasp.teacher import blind_approach

CONFIG_NAME = "teacher_config.json"
WEIGHTS_NAME = "teacher.safetensors"
FORMAT = "blindgrasp-teacher/1"
# The default teacher of every command: a folder under the shipped models/ (or $BLINDGRASP_TEACHER).
SHIPPED_TEACHER = "teacher_cpu_bc"
TEACHER_ENV_VAR = "BLINDGRASP_TEACHER"


class TeacherError(FileNotFoundError):
    """A teacher that cannot be found or loaded; the message is one line that says what to do."""


def default_teacher(folder: str | None = None) -> Path:
    """The teacher a command uses when none is given: $BLINDGRASP_TEACHER, else the shipped `folder` of models/."""
    if os.environ.get(TEACHER_ENV_VAR):
        return Path(os.environ[TEACHER_ENV_VAR])
    d = shipped.folder("models") / (folder or SHIPPED_TEACHER)
    if not (d / WEIGHTS_NAME).is_file():
        raise TeacherError(
            f"the shipped teacher is not at {d} (a wheel ships it as package data; reinstall "
            f"lerobot_policy_blindgrasp); pass a teacher folder explicitly or set {TEACHER_ENV_VAR}"
        )
    return d


def latest_checkpoint(run_dir: Path) -> Path | None:
    ckpts = sorted(Path(run_dir).glob("model_*.pt"), key=lambda p: int(re.findall(r"\d+", p.stem)[-1]))
    return ckpts[-1] if ckpts else None


def resolve_checkpoint(path: str | Path) -> Path:
    """The weights file of a teacher folder (teacher.safetensors, else the latest model_<it>.pt), or the file given."""
    p = Path(path)
    _refuse_student(p)
    if p.is_dir():
        ckpt = p / WEIGHTS_NAME if (p / WEIGHTS_NAME).is_file() else latest_checkpoint(p)
        if ckpt is None:
            raise TeacherError(
                f"no teacher in {p}: no {WEIGHTS_NAME} (a shipped teacher) and no model_<iteration>.pt (a training run)"
            )
    elif p.is_file():
        ckpt = p
    else:
        raise TeacherError(f"teacher not found: {p} does not exist")
    if ckpt.suffix not in (".pt", ".safetensors"):
        raise TeacherError(f"{ckpt} is not a teacher checkpoint (expected {WEIGHTS_NAME} or model_<it>.pt)")
    if not (ckpt.parent / CONFIG_NAME).is_file():
        raise TeacherError(f"{ckpt} has no {CONFIG_NAME} beside it; is it a blindgrasp teacher checkpoint?")
    return ckpt


def _refuse_student(p: Path) -> None:
    """A LeRobot policy folder (config.json with a `type`) where a teacher belongs: name the mix-up."""
    folder = p if p.is_dir() else p.parent
    cfg = folder / "config.json"
    if cfg.is_file() and not (folder / CONFIG_NAME).is_file():
        try:
            kind = json.loads(cfg.read_text()).get("type")
        except (json.JSONDecodeError, AttributeError):
            return
        if kind:
            raise TeacherError(
                f"{folder} is a LeRobot `{kind}` policy, not a blindgrasp teacher (teacher.safetensors + "
                f"{CONFIG_NAME}); evaluate it with lerobot-eval --policy.path={folder}"
            )


def file_sha256(path: Path) -> str:
    with open(path, "rb") as f:
        return hashlib.file_digest(f, "sha256").hexdigest()


def observation_layout() -> dict:
    return {"policy": [[spec.STATE_KEY, spec.STATE_DIM]], "privileged": [list(x) for x in spec.PRIVILEGED_LAYOUT]}


def load_actor_state(ckpt: Path) -> tuple[dict[str, torch.Tensor], int | None]:
    """(actor state dict, iteration or None) from either file kind, without unpickling objects."""
    if ckpt.suffix == ".safetensors":
        from safetensors.torch import load_file

        return load_file(str(ckpt)), None
    try:
        state = torch.load(ckpt, map_location="cpu", weights_only=True)
    except Exception as e:  # noqa: BLE001  (a truncated or foreign file: say which file, in one line)
        raise TeacherError(f"cannot read {ckpt} as an rsl-rl checkpoint ({type(e).__name__})") from None
    if not isinstance(state, dict) or "actor_state_dict" not in state:
        raise TeacherError(f"{ckpt} has no actor_state_dict; is it an rsl-rl checkpoint?")
    return state["actor_state_dict"], int(state["iter"]) if "iter" in state else None


class TeacherPolicy:
    """Numpy-in, numpy-out teacher: obs dict (N, ...) -> delta-theta actions (N, 9). A blind-approach teacher keeps
    per-env touch counts: one instance per env batch, called once per control step."""

    def __init__(self, checkpoint: str | Path, device: str = "cpu"):
        self.checkpoint = resolve_checkpoint(checkpoint)
        try:
            self.config = json.loads((self.checkpoint.parent / CONFIG_NAME).read_text())
            runner = self.config["runner"]
            actor_cfg = {k: v for k, v in runner["actor"].items() if k != "class_name"}
            self.obs_groups = runner["obs_groups"]
        except (json.JSONDecodeError, KeyError, TypeError) as e:
            raise TeacherError(f"{self.checkpoint.parent / CONFIG_NAME} is not a teacher config ({e!r})") from None
        layout = self.config.get("observation_layout")
        if layout is not None and layout != observation_layout():
            raise TeacherError(
                f"{self.checkpoint} was trained on another observation layout than spec.PRIVILEGED_LAYOUT; "
                "retrain or use a teacher from this version"
            )
        priv = spec.PRIVILEGED_DIM  # the width of "privileged" and of its blind-approach form
        dims = {"policy": spec.STATE_DIM, "privileged": priv, blind_approach.GROUP: priv}
        dummy = TensorDict({k: torch.zeros(1, d) for k, d in dims.items()}, batch_size=[1])
        self.actor = MLPModel(dummy, self.obs_groups, "actor", spec.NUM_JOINTS, **actor_cfg)
        state, iteration = load_actor_state(self.checkpoint)
        try:
            self.actor.load_state_dict(state)
        except RuntimeError as e:
            first = str(e).strip().splitlines()[-1].strip()
            raise TeacherError(
                f"{self.checkpoint} does not fit its config or this observation layout ({first})"
            ) from None
        self.actor.to(device).eval()
        # A blind-approach teacher computes its actor's group itself from the env's "privileged" vector.
        self.actor_input = blind_approach.ActorInput.from_record(self.config.get("actor_input"))
        reads_blind = blind_approach.reads_blind_group({"actor": self.obs_groups["actor"]})
        self._blind = blind_approach.BlindGroup(self.actor_input) if reads_blind else None
        self.device = device
        weights = self.config.get("weights", {})
        self.iteration = iteration if iteration is not None else int(weights.get("iteration", -1))
        self.sha256 = file_sha256(self.checkpoint)
        # folder/file, e.g. `teacher_cpu/teacher.safetensors`, for reports and provenance
        self.name = f"{self.checkpoint.parent.name}/{self.checkpoint.name}"

    @property
    def action_std(self) -> np.ndarray:
        """(9,) std of the stochastic teacher's Gaussian, rad: the noise in every demo's action label."""
        return self.actor.distribution.std_param.detach().cpu().numpy().astype(np.float64)

    @torch.inference_mode()
    def __call__(self, obs: dict[str, np.ndarray], stochastic: bool = False) -> np.ndarray:
        if self._blind is not None and blind_approach.GROUP not in obs:
            obs = self._blind(obs)  # a blind-approach teacher: the env gives "privileged"
        n = next(iter(obs.values())).shape[0]
        td = TensorDict(
            {k: torch.from_numpy(np.asarray(v)).to(self.device) for k, v in obs.items()}, batch_size=[n]
        )
        return self.actor(td, stochastic_output=stochastic).cpu().numpy().astype(np.float64)
