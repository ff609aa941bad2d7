"""The student part of the preset registry: each stage's size (a `SIZES` entry) and length. Table IV's epochs are
passes over the collected dataset's frames (LeRobot's reading; robomimic's template counts 100 steps, and the paper
does not say which), so the steps exist only after the demo stage (`schedule`):

    --steps = epochs * ceil(total_frames / batch_size)      --policy.scheduler_constant_steps likewise
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

from lerobot_blindgrasp.policies.blindgrasp_transformer.configuration_blindgrasp_transformer import SIZES


@dataclass(frozen=True, kw_only=True)
class StudentStage:
    """lerobot-train of the student: its size and either a fixed step count or epochs of the collected data."""

    size: str  # a key of SIZES
    batch_size: int
    steps: int | None = None  # fixed optimizer steps (small presets: a measured wall-clock budget)
    epochs: int | None = None  # passes over the collected dataset (paper); steps then follow from its frames
    constant_lr_epochs: int | None = None  # LR constant this many epochs, then linear decay (Table IV)
    constant_lr_steps: int | None = None  # the same for a fixed-step stage, in steps
    lr: float | None = None  # AdamW learning rate; None: the policy's (Table IV's 1e-4)
    threads: int = 1  # OMP threads of lerobot-train (nothing else runs during that stage)
    # lerobot-train's data-loader processes: one next to one torch thread overlaps loading with the update.
    num_workers: int = 0
    device: str = "cpu"  # student training and eval; the pipeline's --device overrides
    # Training-time sensor errors (beyond the paper; 0: off): the policy's --policy.augment_* settings.
    augment_force_gain: float = 0.0
    augment_force_bias_n: float = 0.0
    augment_joint_offset_rad: float = 0.0

    @property
    def policy_flags(self) -> list[str]:
        """lerobot-train --policy.* flags beyond size: the augmentation that is on."""
        names = ("augment_force_gain", "augment_force_bias_n", "augment_joint_offset_rad")
        return [f"--policy.{n}={getattr(self, n)}" for n in names if getattr(self, n) > 0]

    def __post_init__(self):
        if self.size not in SIZES:
            raise ValueError(f"student size {self.size!r} is not one of {sorted(SIZES)}")
        if (self.steps is None) == (self.epochs is None):
            raise ValueError("a student stage gives exactly one of steps and epochs")
        if self.constant_lr_epochs is not None and self.epochs is None:
            raise ValueError("constant_lr_epochs needs epochs: it is counted in passes over the data")
        if self.constant_lr_steps is not None and self.steps is None:
            raise ValueError("constant_lr_steps needs steps (an epoch-sized stage gives constant_lr_epochs)")
        if self.lr is not None and not self.lr > 0:
            raise ValueError(f"the student's learning rate must be > 0, not {self.lr}")


@dataclass(frozen=True, kw_only=True)
class DaggerStage:
    """DAgger-style relabelling, beyond the paper (`blindgrasp-dagger`): `rounds` times, the latest student drives
    `episodes_per_object` episodes per object of `objects`, the teacher's mean action labels every state it visits,
    and the student is fine-tuned for `steps` on everything aggregated so far."""

    episodes_per_object: int
    steps: int
    rounds: int = 1
    num_envs: int = 360
    objects: str = "all"  # whose episodes the student drives: "all", "medium" or a comma list of catalogue names

    def __post_init__(self):
        if min(self.episodes_per_object, self.steps, self.rounds, self.num_envs) < 1:
            raise ValueError("a DAgger stage needs at least one episode, step, round and env")


@dataclass(frozen=True)
class Schedule:
    """What lerobot-train is given for one dataset."""

    steps: int
    constant_lr_steps: int | None  # None: the policy's default (LR constant over the whole run)
    total_frames: int | None = None
    steps_per_epoch: int | None = None


def schedule(stage: StudentStage, total_frames: int | None) -> Schedule:
    """Steps (and the LR schedule) for `stage` on a dataset of `total_frames` frames."""
    if stage.steps is not None:
        return Schedule(steps=stage.steps, constant_lr_steps=stage.constant_lr_steps, total_frames=total_frames)
    if not total_frames or total_frames < 1:
        raise ValueError("an epoch-sized student stage needs the dataset's total_frames (collect the demos first)")
    per_epoch = math.ceil(total_frames / stage.batch_size)
    constant = None if stage.constant_lr_epochs is None else stage.constant_lr_epochs * per_epoch
    return Schedule(
        steps=stage.epochs * per_epoch,
        constant_lr_steps=constant,
        total_frames=total_frames,
        steps_per_epoch=per_epoch,
    )


def dataset_frames(root: Path) -> int:
    return int(json.loads((Path(root) / "meta" / "info.json").read_text())["total_frames"])
