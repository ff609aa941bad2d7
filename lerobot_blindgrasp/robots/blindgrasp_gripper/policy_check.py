"""The policy is an input too: a checkpoint is checked against the robot before any servo takes torque.

LeRobot's `make_policy` overwrites a checkpoint's output features with the env's, and a config validates shapes
only, so nothing else compares what a policy was trained for with the robot it is about to move. This reads the
checkpoint's own files, names the file each fact came from, and compares:
- `config.json`: policy type, `observation.state` and `action` shapes (as trained, before any overwrite);
- `policy_preprocessor.json` / `policy_postprocessor.json`: the shapes their normalizers were fitted on, and the
  action meaning: absolute joint targets in and out (`blindgrasp_target_to_delta` turns them into the network's
  deltas and the policy back; LeRobot's `relative_actions_processor` without `absolute_actions_processor` in the
  postprocessor would send deltas to a robot that takes targets);
- `train_config.json`: the training dataset (repo id, root) and, when it trained with an env, that env's fps;
- the dataset's `meta/info.json` (at the recorded root, or in `HF_LEROBOT_HOME`): robot type, fps and the feature
  names and their order.
A fact no file holds is reported as unverified (a warning); a fact that differs refuses the run
(`PolicyMismatchError`), before the ports are opened.
"""

from __future__ import annotations

import json
import logging
from dataclasses import dataclass
from pathlib import Path

from lerobot_blindgrasp import spec

from .errors import PolicyMismatchError

logger = logging.getLogger(__name__)

STATE, ACTION = "observation.state", "action"
_checked: set[tuple] = set()


@dataclass(frozen=True)
class RobotContract:
    robot_type: str
    state_names: tuple[str, ...]
    action_names: tuple[str, ...]
    fps: float
    fps_source: str


def gripper_contract(robot_type: str, fps: float, fps_source: str) -> RobotContract:
    return RobotContract(robot_type, spec.STATE_NAMES, spec.ACTION_NAMES, float(fps), fps_source)


def _load(path: Path) -> dict | None:
    if not path.is_file():
        return None
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise PolicyMismatchError(f"{path} is unreadable ({type(e).__name__}: {e}); nothing was moved.") from e


def _dataset_info(train: dict | None, where: Path) -> tuple[dict | None, str]:
    ds = (train or {}).get("dataset") or {}
    candidates = []
    if ds.get("root"):
        candidates.append(Path(ds["root"]))
    if ds.get("repo_id"):
        from lerobot.utils.constants import HF_LEROBOT_HOME  # where LeRobot itself looks, env vars included

        candidates.append(Path(HF_LEROBOT_HOME) / ds["repo_id"])
    for root in candidates:
        info = _load(root / "meta" / "info.json")
        if info is not None:
            return info, str(root / "meta" / "info.json")
    return None, f"the training dataset's meta/info.json (looked in {[str(c) for c in candidates]}, from {where})"


def _shape(features: dict | None, key: str) -> tuple | None:
    ft = (features or {}).get(key)
    return tuple(ft["shape"]) if isinstance(ft, dict) and "shape" in ft else None


def _step_names(pipeline: dict | None) -> list[str]:
    return [s.get("registry_name", "") for s in (pipeline or {}).get("steps", [])]


def _normalizer_shapes(pipeline: dict | None) -> dict[str, tuple]:
    out = {}
    for step in (pipeline or {}).get("steps", []):
        for key, ft in ((step.get("config") or {}).get("features") or {}).items():
            if isinstance(ft, dict) and "shape" in ft:
                out[key] = tuple(ft["shape"])
    return out


def _shape_problems(cfg: dict, where: Path, robot: RobotContract) -> list[str]:
    want = {STATE: (len(robot.state_names),), ACTION: (len(robot.action_names),)}
    bad = []
    for key, group in ((STATE, "input_features"), (ACTION, "output_features")):
        have = _shape(cfg.get(group), key)
        if have != want[key]:
            bad.append(f"'{key}' shape {have} in {where / 'config.json'} ({group}), the robot has {want[key]}")
    for name in ("policy_preprocessor.json", "policy_postprocessor.json"):
        for key, have in _normalizer_shapes(_load(where / name)).items():
            if key in want and have != want[key]:
                bad.append(f"'{key}' shape {have} in {where / name} (normalizer), the robot has {want[key]}")
    return bad


def _meaning_problems(where: Path) -> list[str]:
    pre = _step_names(_load(where / "policy_preprocessor.json"))
    post = _step_names(_load(where / "policy_postprocessor.json"))
    if "relative_actions_processor" in pre and "absolute_actions_processor" not in post:
        return [
            (
                f"'action' meaning: {where / 'policy_preprocessor.json'} makes actions relative and "
                f"{where / 'policy_postprocessor.json'} never makes them absolute again; the robot takes absolute "
                "joint targets (rad)"
            )
        ]
    return []


def _dataset_problems(info: dict, source: str, robot: RobotContract) -> list[str]:
    bad = []
    if info.get("robot_type") != robot.robot_type:
        bad.append(f"robot type {info.get('robot_type')!r} in {source}, the robot is {robot.robot_type!r}")
    if info.get("fps") is not None and float(info["fps"]) != robot.fps:
        bad.append(f"fps {info['fps']} in {source}, the loop runs at {robot.fps:g} ({robot.fps_source})")
    features = info.get("features") or {}
    for key, want in ((STATE, robot.state_names), (ACTION, robot.action_names)):
        names = (features.get(key) or {}).get("names")
        if isinstance(names, dict):  # LeRobot also writes {"axes": [...]} for some features
            names = next(iter(names.values()), None)
        if names is not None and tuple(names) != tuple(want):
            bad.append(f"'{key}' names {list(names)} in {source}, the robot's are {list(want)} (names and order)")
    return bad


def problems(path: str | Path, robot: RobotContract) -> tuple[list[str], list[str]]:
    """(mismatches, unverified facts) of the checkpoint at `path` against the robot."""
    where = Path(path)
    cfg = _load(where / "config.json")
    if cfg is None:
        return [f"{where / 'config.json'} not found: not a LeRobot policy checkpoint directory"], []
    bad = _shape_problems(cfg, where, robot) + _meaning_problems(where)
    train = _load(where / "train_config.json")
    unverified = []
    info, source = _dataset_info(train, where)
    if info is not None:
        bad += _dataset_problems(info, source, robot)
    else:
        unverified.append(f"robot type, fps and feature names: {source} not found")
    env_fps = ((train or {}).get("env") or {}).get("fps")
    if env_fps is not None and float(env_fps) != robot.fps:
        bad.append(f"fps {env_fps} in {where / 'train_config.json'} (env), the loop runs at {robot.fps:g} "
                   f"({robot.fps_source})")  # fmt: skip
    return bad, unverified


def check(path: str | Path, robot: RobotContract) -> None:
    """Refuse (`PolicyMismatchError`) a checkpoint that does not fit the robot; warn about what no file says."""
    key = (str(path), robot)
    if key in _checked:
        return
    bad, unverified = problems(path, robot)
    if bad:
        raise PolicyMismatchError(
            f"The policy at {path} does not fit the {robot.robot_type} robot: {'; '.join(bad)}. Nothing was moved "
            "(no servo took torque)."
        )
    for note in unverified:
        logger.warning(
            "Policy at %s: could not verify %s; checked the shapes and action meaning only.", path, note
        )
    _checked.add(key)


def local_checkpoint(path: str) -> Path | None:
    """A local checkpoint directory; a Hub id is resolved from the cache only (nothing is downloaded here)."""
    if Path(path).is_dir():
        return Path(path)
    try:
        from huggingface_hub import snapshot_download

        return Path(snapshot_download(path, local_files_only=True))
    except Exception:  # not cached (LeRobot downloads it later): the robot-side check runs at connect
        return None


def check_cli_policy(robot) -> None:
    """The policy named on this process's command line (`--policy.path`, as LeRobot's parser reads it), checked
    against `robot` at its rate (`loop_hz`, and `--fps` / `--env.fps` / `--dataset.fps` when given)."""
    from lerobot.configs import parser

    path = parser.get_path_arg("policy")
    if not path or (where := local_checkpoint(path)) is None:
        return
    fps, source = float(robot.config.loop_hz), "the robot's loop_hz"
    for flag in ("fps", "env.fps", "dataset.fps"):
        if (value := parser.parse_arg(flag)) is not None:
            fps, source = float(value), f"--{flag}"
    check(where, gripper_contract(robot.name, fps, source))
    if fps != float(robot.config.loop_hz):
        raise PolicyMismatchError(
            f"{source}={fps:g} but the robot's loop_hz is {robot.config.loop_hz:g}: set "
            "--robot.loop_hz to the loop's rate (it measures the loop against it)."
        )
