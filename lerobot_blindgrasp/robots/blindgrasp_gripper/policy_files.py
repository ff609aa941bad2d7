"""A policy checkpoint's files, read for `policy_check.py` without loading the policy: its config, processors,
normalizer statistics, weights, training config and (when it is on this machine) its dataset's metadata. Every
fact comes with the file it was read from."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from .errors import PolicyMismatchError

STATE, ACTION = "observation.state", "action"
NORMALIZERS = ("normalizer_processor", "unnormalizer_processor")  # LeRobot's steps that hold fitted statistics
PROCESSORS = ("policy_preprocessor.json", "policy_postprocessor.json")


def load(path: Path) -> dict | None:
    if not path.is_file():
        return None
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise PolicyMismatchError(f"{path} is unreadable ({type(e).__name__}: {e}); nothing was moved.") from e


def load_tensors(path: Path) -> dict[str, np.ndarray]:
    """A safetensors file as float64 arrays (torch reads every dtype a checkpoint may hold, bfloat16 included)."""
    from safetensors import SafetensorError
    from safetensors.torch import load_file

    try:
        return {k: v.double().numpy() for k, v in load_file(str(path)).items()}
    except (OSError, SafetensorError) as e:
        raise PolicyMismatchError(f"{path} is unreadable ({type(e).__name__}: {e}); nothing was moved.") from e


def dataset_info(train: dict | None, where: Path) -> tuple[dict | None, str]:
    """The training dataset's meta/info.json (at the recorded root, or in `HF_LEROBOT_HOME`), and where it was."""
    ds = (train or {}).get("dataset") or {}
    candidates = []
    if ds.get("root"):
        candidates.append(Path(ds["root"]))
    if ds.get("repo_id"):
        from lerobot.utils.constants import HF_LEROBOT_HOME  # where LeRobot itself looks, env vars included

        candidates.append(Path(HF_LEROBOT_HOME) / ds["repo_id"])
    for root in candidates:
        info = load(root / "meta" / "info.json")
        if info is not None:
            return info, str(root / "meta" / "info.json")
    return None, f"the training dataset's meta/info.json (looked in {[str(c) for c in candidates]}, from {where})"


def shape(features: dict | None, key: str) -> tuple | None:
    ft = (features or {}).get(key)
    return tuple(ft["shape"]) if isinstance(ft, dict) and "shape" in ft else None


def step_names(pipeline: dict | None) -> list[str]:
    return [s.get("registry_name", "") for s in (pipeline or {}).get("steps", [])]


def normalizer_shapes(pipeline: dict | None) -> dict[str, tuple]:
    out = {}
    for step in (pipeline or {}).get("steps", []):
        for key, ft in ((step.get("config") or {}).get("features") or {}).items():
            if isinstance(ft, dict) and "shape" in ft:
                out[key] = tuple(ft["shape"])
    return out


def _stat_problems(stats: dict, key: str, mode: str, source: str, names: dict) -> list[str]:
    label = lambda i: f"{key}[{i}] ({names[key][i]})" if key in names and i < len(names[key]) else f"{key}[{i}]"  # noqa: E731
    wanted = {"MEAN_STD": ("mean", "std"), "MIN_MAX": ("min", "max")}.get(mode, ())
    bad = []
    for stat in wanted:
        value = stats.get(f"{key}.{stat}")
        if value is None:
            bad.append(f"{key}.{stat} missing from {source} ({mode} normalization needs it)")
        elif not np.all(np.isfinite(value)):
            bad.append(f"{key}.{stat} not finite at {[label(i) for i in np.flatnonzero(~np.isfinite(value))]} in "
                       f"{source}")  # fmt: skip
    std = stats.get(f"{key}.std")
    if mode == "MEAN_STD" and std is not None and np.all(np.isfinite(std)) and np.any(std <= 0):
        bad.append(f"{key}.std is 0 at {[label(i) for i in np.flatnonzero(std <= 0)]} in {source}: any change of "
                   "that input would reach the network multiplied by 1/eps")  # fmt: skip
    return bad


def stats_problems(where: Path, names: dict[str, tuple[str, ...]]) -> list[str]:
    """The normalizers' fitted statistics: finite, and a standard deviation above 0, for every feature they
    normalize (`norm_map` by feature type; IDENTITY features use none)."""
    bad = []
    for name in PROCESSORS:
        for step in (load(where / name) or {}).get("steps", []):
            if step.get("registry_name") not in NORMALIZERS or not step.get("state_file"):
                continue
            source = str(where / step["state_file"])
            stats = load_tensors(where / step["state_file"])
            config = step.get("config") or {}
            for key, ft in (config.get("features") or {}).items():
                mode = (config.get("norm_map") or {}).get(ft.get("type"), "IDENTITY")
                bad += _stat_problems(stats, key, mode, source, names)
    return bad


def weight_problems(where: Path) -> list[str]:
    """NaN or infinite weights (a diverged training run) make every action NaN; the robot would refuse each one,
    mid-run. Refused here instead, before anything moves."""
    path = where / "model.safetensors"
    if not path.is_file():
        return [f"{path} not found: the checkpoint has no weights"]
    bad = {k: int(np.size(v) - np.isfinite(v).sum()) for k, v in load_tensors(path).items()}
    bad = {k: n for k, n in bad.items() if n}
    return [f"{sum(bad.values())} non-finite weights in {path} (in {sorted(bad)[:3]})"] if bad else []
