"""Record in a blindgrasp_transformer checkpoint what it was trained for (`trained_for` in its config.json).

The record holds the robot type, the fps, the state and action names in order, the action meaning, and where they
were read.

lerobot-train writes it for every checkpoint it trains (the policy fills it from the training dataset's
metadata). This is the one-off for a checkpoint trained before that, whose fit the real gripper otherwise refuses
(`robots/blindgrasp_gripper/policy_check.py`), wherever its dataset is:

    python -m lerobot_blindgrasp.deploy.policy_contract --checkpoint=<checkpoint> --dataset_root=<dataset root>
    python -m lerobot_blindgrasp.deploy.policy_contract --checkpoint=models/student_cpu --sim_demos=true

`--dataset_root` reads the training dataset's `meta/info.json`. `--sim_demos=true` is for a checkpoint trained on
this project's simulated demonstrations (blindgrasp-collect-demos, blindgrasp-dagger, blindgrasp-pipeline) when the
dataset is not on this machine: those are all written with the one schema of `demos/dataset.py`, checked on every
write and read (robot type `blindgrasp_gripper`, 20 fps, `spec`'s names), and the record says so, with the
dataset's repo id from the checkpoint's train_config.json. The shipped models/student_cpu was stamped this way.
Running it again writes the same file.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace

from lerobot_blindgrasp import durable, spec
from lerobot_blindgrasp.cli import parse_config
from lerobot_blindgrasp.policies.blindgrasp_transformer.configuration_blindgrasp_transformer import TrainedFor

POLICY_TYPE = "blindgrasp_transformer"


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


def from_dataset_root(root: Path) -> TrainedFor:
    info_path = Path(root) / "meta" / "info.json"
    if not info_path.is_file():
        raise SystemExit(f"error: {info_path} not found")
    info = json.loads(info_path.read_text(encoding="utf-8"))
    meta = SimpleNamespace(robot_type=info.get("robot_type"), fps=info.get("fps"), features=info.get("features"))
    return TrainedFor.from_dataset(meta, source=str(info_path))


def from_sim_demos(checkpoint: Path) -> TrainedFor:
    from lerobot_blindgrasp.demos.dataset import FPS, ROBOT_TYPE

    train = checkpoint / "train_config.json"
    repo_id = json.loads(train.read_text())["dataset"]["repo_id"] if train.is_file() else "?"
    features = spec.dataset_features()
    meta = SimpleNamespace(robot_type=ROBOT_TYPE, fps=FPS, features=features)
    source = f"the sim demo schema of demos/dataset.py, which dataset {repo_id} was written with (not read itself)"
    return TrainedFor.from_dataset(meta, source=source)


def record(cfg: PolicyContractConfig) -> TrainedFor:
    where = Path(cfg.checkpoint)
    config = json.loads((where / "config.json").read_text(encoding="utf-8"))
    if config.get("type") != POLICY_TYPE:
        raise SystemExit(f"error: {where / 'config.json'} is a {config.get('type')!r} policy, not {POLICY_TYPE!r}")
    facts = from_dataset_root(cfg.dataset_root) if cfg.dataset_root is not None else from_sim_demos(where)
    config["trained_for"] = dataclasses.asdict(facts)
    durable.atomic_write_json(where / "config.json", config, indent=4)  # LeRobot's own layout of the file
    return facts


def main(argv: list[str] | None = None) -> None:
    facts = record(parse_config(PolicyContractConfig, argv))
    print(json.dumps(dataclasses.asdict(facts), indent=2))


if __name__ == "__main__":
    main()
