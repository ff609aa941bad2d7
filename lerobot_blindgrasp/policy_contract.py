"""The policy-vs-robot contract: what a checkpoint records it was trained for, and the check that refuses one that
does not fit the robot before any servo takes torque. The caller that knows the checkpoint runs it (the real eval
env, blindgrasp-rollout, the robot at connect); it reads the checkpoint's own files (LeRobot's `make_policy`
overwrites a loaded policy's output features with the env's) and names the file each fact came from. `python -m
lerobot_blindgrasp.policy_contract` records `trained_for` in a checkpoint trained before lerobot-train wrote it.
"""

from __future__ import annotations

import json
import logging
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from lerobot_blindgrasp import durable, spec
from lerobot_blindgrasp.cli import parse_config

logger = logging.getLogger(__name__)

STATE, ACTION = spec.STATE_KEY, spec.ACTION_KEY
ACTION_MEANING = "absolute joint targets (rad)"  # what the gripper's `send_action` takes
POLICY_TYPE = "blindgrasp_transformer"  # the policy whose checkpoints `record` stamps
ROBOT_TYPE = "blindgrasp_gripper"  # the gripper's LeRobot name, which the sim demos' datasets carry too
NORMALIZERS = ("normalizer_processor", "unnormalizer_processor")  # LeRobot's steps that hold fitted statistics
PROCESSORS = ("policy_preprocessor.json", "policy_postprocessor.json")
ENV_TYPES = ("blindgrasp", "blindgrasp_real")  # the envs whose observation and action are this robot's
OVERRIDE = "--robot.allow_unverified_policy=true (lerobot-eval: --env.robot.allow_unverified_policy=true)"
_checked: set[tuple] = set()


class PolicyMismatchError(ValueError):
    """The checkpoint was trained for another robot (features, robot type, fps, action meaning): refused before torque."""


@dataclass(frozen=True)
class RobotContract:
    robot_type: str
    state_names: tuple[str, ...]
    action_names: tuple[str, ...]
    fps: float
    fps_source: str


def gripper_contract(robot_type: str, fps: float, fps_source: str) -> RobotContract:
    return RobotContract(robot_type, spec.STATE_NAMES, spec.ACTION_NAMES, float(fps), fps_source)


# --- the checkpoint's files, each fact with the file it was read from -----------------------------------------
def read_checkpoint_json(path: Path) -> dict | None:
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
        info = read_checkpoint_json(root / "meta" / "info.json")
        if info is not None:
            return info, str(root / "meta" / "info.json")
    return None, f"the training dataset's meta/info.json (looked in {[str(c) for c in candidates]}, from {where})"


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
        for step in (read_checkpoint_json(where / name) or {}).get("steps", []):
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


# --- the check ---------------------------------------------------------------------------------------------------
def _feature_problems(cfg: dict, where: Path, robot: RobotContract) -> list[str]:
    want = {STATE: (len(robot.state_names),), ACTION: (len(robot.action_names),)}
    bad = []
    for key, group in ((STATE, "input_features"), (ACTION, "output_features")):
        extra = sorted(set(cfg.get(group) or {}) - {key})
        if extra:
            bad.append(f"{group} {extra} in {where / 'config.json'}: the robot has only '{key}' there (no camera)")
        ft = (cfg.get(group) or {}).get(key)
        have = tuple(ft["shape"]) if isinstance(ft, dict) and "shape" in ft else None
        if have != want[key]:
            bad.append(f"'{key}' shape {have} in {where / 'config.json'} ({group}), the robot has {want[key]}")
    for name in PROCESSORS:
        for key, have in normalizer_shapes(read_checkpoint_json(where / name)).items():
            if key in want and have != want[key]:
                bad.append(f"'{key}' shape {have} in {where / name} (normalizer), the robot has {want[key]}")
    return bad


def _meaning_problems(where: Path) -> list[str]:
    pre = step_names(read_checkpoint_json(where / "policy_preprocessor.json"))
    post = step_names(read_checkpoint_json(where / "policy_postprocessor.json"))
    if "relative_actions_processor" in pre and "absolute_actions_processor" not in post:
        return [
            f"'action' meaning: {where / 'policy_preprocessor.json'} makes actions relative and "
            f"{where / 'policy_postprocessor.json'} never makes them absolute again; the robot takes {ACTION_MEANING}"
        ]
    return []


def _env_problems(train: dict | None, where: Path, robot: RobotContract) -> list[str]:
    env = (train or {}).get("env") or {}
    source = where / "train_config.json"
    bad = []
    if env.get("type") is not None and env["type"] not in ENV_TYPES:
        bad.append(f"env type {env['type']!r} in {source}, this robot's envs are {list(ENV_TYPES)}")
    if env.get("fps") is not None and float(env["fps"]) != robot.fps:
        bad.append(f"fps {env['fps']} in {source} (env), the loop runs at {robot.fps:g} ({robot.fps_source})")
    return bad


def _trained_for(cfg: dict, train: dict | None, where: Path) -> tuple[dict | None, str]:
    """The facts the checkpoint records (`trained_for` in config.json), else its dataset's meta/info.json."""
    if isinstance(cfg.get("trained_for"), dict):
        facts = cfg["trained_for"]
        via = f" ({facts['source']})" if facts.get("source") else ""
        return facts, f"{where / 'config.json'} (trained_for{via})"
    info, source = dataset_info(train, where)
    if info is None:
        return None, f"{where / 'config.json'} has no trained_for, and {source} was not found"
    return facts_from_dataset(SimpleNamespace(**info), source), source


def _contract_problems(facts: dict, source: str, robot: RobotContract) -> tuple[list[str], list[str]]:
    bad, unverified = [], []
    if facts.get("robot_type") is None:
        unverified.append(f"robot type: not in {source}")
    elif facts["robot_type"] != robot.robot_type:
        bad.append(f"robot type {facts['robot_type']!r} in {source}, the robot is {robot.robot_type!r}")
    if facts.get("fps") is None:
        unverified.append(f"fps: not in {source}")
    elif float(facts["fps"]) != robot.fps:
        bad.append(f"fps {facts['fps']:g} in {source}, the loop runs at {robot.fps:g} ({robot.fps_source})")
    for key, field, want in (
        (STATE, "state_names", robot.state_names),
        (ACTION, "action_names", robot.action_names),
    ):
        names = facts.get(field)
        if names is None:
            unverified.append(f"'{key}' names: not in {source}")
        elif tuple(names) != tuple(want):
            bad.append(f"'{key}' names {list(names)} in {source}, the robot's are {list(want)} (names and order)")
    meaning = facts.get("action_meaning")
    if meaning is not None and meaning != ACTION_MEANING:
        bad.append(f"'action' meaning {meaning!r} in {source}, the robot takes {ACTION_MEANING}")
    return bad, unverified


def checkpoint_problems(path: str | Path, robot: RobotContract) -> tuple[list[str], list[str]]:
    """(mismatches, unverified facts) of the checkpoint at `path` against the robot."""
    where = Path(path)
    cfg = read_checkpoint_json(where / "config.json")
    if cfg is None:
        return [f"{where / 'config.json'} not found: not a LeRobot policy checkpoint directory"], []
    names = {STATE: robot.state_names, ACTION: robot.action_names}
    bad = _feature_problems(cfg, where, robot) + _meaning_problems(where)
    bad += stats_problems(where, names) + weight_problems(where)
    train = read_checkpoint_json(where / "train_config.json")
    bad += _env_problems(train, where, robot)
    facts, source = _trained_for(cfg, train, where)
    if facts is None:
        return bad, [f"robot type, fps and feature names: {source}"]
    mismatched, unverified = _contract_problems(facts, source, robot)
    return bad + mismatched, unverified


def check_checkpoint(path: str | Path, robot: RobotContract, *, allow_unverified: bool = False) -> None:
    """Refuse (`PolicyMismatchError`) a checkpoint that does not fit the robot, or whose fit no file states
    (unless `allow_unverified`: then warn)."""
    key = (str(path), robot, allow_unverified)
    if key in _checked:
        return
    bad, unverified = checkpoint_problems(path, robot)
    if bad:
        raise PolicyMismatchError(
            f"The policy at {path} does not fit the {robot.robot_type} robot: {'; '.join(bad)}. Nothing was moved "
            "(no servo took torque)."
        )
    if unverified and not allow_unverified:
        raise PolicyMismatchError(
            f"The policy at {path} cannot be verified for the {robot.robot_type} robot: {'; '.join(unverified)}. "
            "Nothing was moved (no servo took torque). Record what it was trained for with `python -m "
            f"lerobot_blindgrasp.policy_contract --checkpoint={path} --dataset_root=<its training dataset>`, "
            f"or run it anyway with {OVERRIDE}."
        )
    for note in unverified:
        logger.warning("Policy at %s: could not verify %s; run anyway (allow_unverified_policy).", path, note)
    _checked.add(key)


def check_named(path, robot_type: str, fps: float, fps_source: str, *, allow_unverified: bool = False) -> bool:
    """`check_checkpoint` the checkpoint a caller names (a folder, or a Hub id already in the cache: nothing is
    downloaded here) against the gripper at `fps`; False when there is none here to check (LeRobot downloads it
    later, and the robot-side check runs at connect)."""
    if not path:
        return False
    where = Path(path)
    if not where.is_dir():
        try:
            from huggingface_hub import snapshot_download

            where = Path(snapshot_download(str(path), local_files_only=True))
        except Exception:  # not in the cache
            return False
    check_checkpoint(where, gripper_contract(robot_type, fps, fps_source), allow_unverified=allow_unverified)
    return True


# --- what a checkpoint records it was trained for ----------------------------------------------------------------
def facts_from_dataset(meta, source: str | None = None) -> dict:
    """`trained_for` from a dataset's metadata (anything with `robot_type`, `fps`, `features`, `repo_id`): the
    names of `observation.state` and `action` in order, and the policy's action meaning."""
    features = getattr(meta, "features", None) or {}

    def names(key: str) -> list[str] | None:
        value = (features.get(key) or {}).get("names")
        if isinstance(value, dict):  # LeRobot also writes {"axes": [...]} for some features
            value = next(iter(value.values()), None)
        return [str(n) for n in value] if isinstance(value, (list, tuple)) else value

    fps = getattr(meta, "fps", None)
    return {"robot_type": getattr(meta, "robot_type", None), "fps": float(fps) if fps is not None else None,
            "state_names": names(STATE), "action_names": names(ACTION), "action_meaning": ACTION_MEANING,
            "source": source or f"the metadata of dataset {getattr(meta, 'repo_id', '?')}"}  # fmt: skip


@dataclass
class PolicyContractConfig:
    checkpoint: Path  # a pretrained_model folder (config.json, model.safetensors, ...)
    dataset_root: Path | None = None  # the training dataset (its meta/info.json is read)
    sim_demos: bool = False  # the training dataset was this project's sim demos (not on this machine)

    def __post_init__(self):
        if (self.dataset_root is None) == (not self.sim_demos):
            raise ValueError("give exactly one of --dataset_root=<dataset root> and --sim_demos=true")
        if not (Path(self.checkpoint) / "config.json").is_file():
            raise ValueError(f"{self.checkpoint} has no config.json: not a LeRobot pretrained_model folder")


def record(cfg: PolicyContractConfig) -> dict:
    """Write `trained_for` into the checkpoint's config.json (atomically, LeRobot's layout of the file)."""
    where = Path(cfg.checkpoint)
    config = json.loads((where / "config.json").read_text(encoding="utf-8"))
    if config.get("type") != POLICY_TYPE:
        raise SystemExit(f"error: {where / 'config.json'} is a {config.get('type')!r} policy, not {POLICY_TYPE!r}")
    if cfg.dataset_root is not None:
        info_path = Path(cfg.dataset_root) / "meta" / "info.json"
        info = read_checkpoint_json(info_path)
        if info is None:
            raise SystemExit(f"error: {info_path} not found")
        facts = facts_from_dataset(SimpleNamespace(**info), source=str(info_path))
    else:
        train = where / "train_config.json"
        repo_id = json.loads(train.read_text())["dataset"]["repo_id"] if train.is_file() else "?"
        meta = SimpleNamespace(robot_type=ROBOT_TYPE, fps=spec.CONTROL_HZ, features=spec.dataset_features())
        facts = facts_from_dataset(meta, source=f"the sim demo schema of demos/dataset.py, which dataset {repo_id} "
                                   "was written with (not read itself)")  # fmt: skip
    config["trained_for"] = facts
    durable.atomic_write_json(where / "config.json", config, indent=4)
    return facts


def main(argv: list[str] | None = None) -> None:
    print(json.dumps(record(parse_config(PolicyContractConfig, argv)), indent=2))


if __name__ == "__main__":
    main()
