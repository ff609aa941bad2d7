"""The policy is an input too: a checkpoint is checked against the robot before any servo takes torque.

LeRobot's `make_policy` overwrites a checkpoint's output features with the env's, and a config validates shapes
only, so nothing else compares what a policy was trained for with the robot it is about to move. This reads the
checkpoint's own files (`policy_files.py`), names the file each fact came from, and compares:
- `config.json`: every input and output feature key (the robot gives `observation.state` and takes `action`, no
  camera), their shapes as trained (before any overwrite), and `trained_for`: the robot type, fps, state and action
  names (in order) and action meaning the policy recorded from its training dataset when lerobot-train built it;
- `policy_preprocessor.json` / `policy_postprocessor.json`: the shapes their normalizers were fitted on, their
  statistics (finite, a standard deviation above 0), and the action meaning: absolute joint targets in and out
  (LeRobot's `relative_actions_processor` without `absolute_actions_processor` would send deltas to a robot that
  takes targets);
- `model.safetensors`: finite weights;
- `train_config.json`: the env it trained with (its type and fps) and, for a checkpoint without `trained_for`, its
  dataset, whose `meta/info.json` is read when it is on this machine.
A fact that differs refuses the run (`PolicyMismatchError`). A fact no file holds (no `trained_for` and no dataset
metadata here, or metadata without feature names) refuses it too, unless the robot's `allow_unverified_policy` is
set: then it is a warning. `python -m lerobot_blindgrasp.deploy.policy_contract` records `trained_for` in an older
checkpoint.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

from lerobot_blindgrasp import compat, spec

from . import policy_files as files
from .errors import PolicyMismatchError

logger = logging.getLogger(__name__)

STATE, ACTION = files.STATE, files.ACTION
ACTION_MEANING = "absolute joint targets (rad)"  # what `send_action` takes
ENV_TYPES = ("blindgrasp", "blindgrasp_real")  # the envs whose observation and action are this robot's
OVERRIDE = "--robot.allow_unverified_policy=true (lerobot-eval: --env.robot.allow_unverified_policy=true)"
_checked: set[tuple] = set()


@dataclass(frozen=True)
class RobotContract:
    robot_type: str
    state_names: tuple[str, ...]
    action_names: tuple[str, ...]
    fps: float
    fps_source: str
    action_meaning: str = ACTION_MEANING
    env_types: tuple[str, ...] = ENV_TYPES


def gripper_contract(robot_type: str, fps: float, fps_source: str) -> RobotContract:
    return RobotContract(robot_type, spec.STATE_NAMES, spec.ACTION_NAMES, float(fps), fps_source)


def _feature_problems(cfg: dict, where: Path, robot: RobotContract) -> list[str]:
    want = {STATE: (len(robot.state_names),), ACTION: (len(robot.action_names),)}
    bad = []
    for key, group in ((STATE, "input_features"), (ACTION, "output_features")):
        extra = sorted(set(cfg.get(group) or {}) - {key})
        if extra:
            bad.append(f"{group} {extra} in {where / 'config.json'}: the robot has only '{key}' there (no camera)")
        have = files.shape(cfg.get(group), key)
        if have != want[key]:
            bad.append(f"'{key}' shape {have} in {where / 'config.json'} ({group}), the robot has {want[key]}")
    for name in files.PROCESSORS:
        for key, have in files.normalizer_shapes(files.load(where / name)).items():
            if key in want and have != want[key]:
                bad.append(f"'{key}' shape {have} in {where / name} (normalizer), the robot has {want[key]}")
    return bad


def _meaning_problems(where: Path) -> list[str]:
    pre = files.step_names(files.load(where / "policy_preprocessor.json"))
    post = files.step_names(files.load(where / "policy_postprocessor.json"))
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
    if env.get("type") is not None and env["type"] not in robot.env_types:
        bad.append(f"env type {env['type']!r} in {source}, this robot's envs are {list(robot.env_types)}")
    if env.get("fps") is not None and float(env["fps"]) != robot.fps:
        bad.append(f"fps {env['fps']} in {source} (env), the loop runs at {robot.fps:g} ({robot.fps_source})")
    return bad


def _trained_for(cfg: dict, train: dict | None, where: Path) -> tuple[dict | None, str]:
    """The facts the checkpoint records (`trained_for` in config.json), else its dataset's meta/info.json."""
    if isinstance(cfg.get("trained_for"), dict):
        facts = cfg["trained_for"]
        via = f" ({facts['source']})" if facts.get("source") else ""
        return facts, f"{where / 'config.json'} (trained_for{via})"
    info, source = files.dataset_info(train, where)
    if info is None:
        return None, f"{where / 'config.json'} has no trained_for, and {source} was not found"
    features = info.get("features") or {}

    def names(key: str):
        value = (features.get(key) or {}).get("names")
        return next(iter(value.values()), None) if isinstance(value, dict) else value

    return {"robot_type": info.get("robot_type"), "fps": info.get("fps"), "state_names": names(STATE),
            "action_names": names(ACTION)}, source  # fmt: skip


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
    if meaning is not None and meaning != robot.action_meaning:
        bad.append(f"'action' meaning {meaning!r} in {source}, the robot takes {robot.action_meaning}")
    return bad, unverified


def problems(path: str | Path, robot: RobotContract) -> tuple[list[str], list[str]]:
    """(mismatches, unverified facts) of the checkpoint at `path` against the robot."""
    where = Path(path)
    cfg = files.load(where / "config.json")
    if cfg is None:
        return [f"{where / 'config.json'} not found: not a LeRobot policy checkpoint directory"], []
    names = {STATE: robot.state_names, ACTION: robot.action_names}
    bad = _feature_problems(cfg, where, robot) + _meaning_problems(where)
    bad += files.stats_problems(where, names) + files.weight_problems(where)
    train = files.load(where / "train_config.json")
    bad += _env_problems(train, where, robot)
    facts, source = _trained_for(cfg, train, where)
    if facts is None:
        return bad, [f"robot type, fps and feature names: {source}"]
    mismatched, unverified = _contract_problems(facts, source, robot)
    return bad + mismatched, unverified


def check(path: str | Path, robot: RobotContract, *, allow_unverified: bool = False) -> None:
    """Refuse (`PolicyMismatchError`) a checkpoint that does not fit the robot, or whose fit no file states
    (unless `allow_unverified`: then warn)."""
    key = (str(path), robot, allow_unverified)
    if key in _checked:
        return
    bad, unverified = problems(path, robot)
    if bad:
        raise PolicyMismatchError(
            f"The policy at {path} does not fit the {robot.robot_type} robot: {'; '.join(bad)}. Nothing was moved "
            "(no servo took torque)."
        )
    if unverified and not allow_unverified:
        raise PolicyMismatchError(
            f"The policy at {path} cannot be verified for the {robot.robot_type} robot: {'; '.join(unverified)}. "
            "Nothing was moved (no servo took torque). Record what it was trained for with `python -m "
            f"lerobot_blindgrasp.deploy.policy_contract --checkpoint={path} --dataset_root=<its training dataset>`, "
            f"or run it anyway with {OVERRIDE}."
        )
    for note in unverified:
        logger.warning("Policy at %s: could not verify %s; run anyway (allow_unverified_policy).", path, note)
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
    path = compat.cli_policy_path()
    if not path or (where := local_checkpoint(path)) is None:
        return
    fps, source = float(robot.config.loop_hz), "the robot's loop_hz"
    for flag in ("fps", "env.fps", "dataset.fps"):
        if (value := compat.cli_arg(flag)) is not None:
            fps, source = float(value), f"--{flag}"
    check(where, gripper_contract(robot.name, fps, source), allow_unverified=robot.config.allow_unverified_policy)
    if fps != float(robot.config.loop_hz):
        raise PolicyMismatchError(
            f"{source}={fps:g} but the robot's loop_hz is {robot.config.loop_hz:g}: set "
            "--robot.loop_hz to the loop's rate (it measures the loop against it)."
        )
