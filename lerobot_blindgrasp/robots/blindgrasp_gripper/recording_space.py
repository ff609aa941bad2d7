"""Room on disk for the next recording episode, checked at every episode start: refused with the numbers if not (a
disk that fills at LeRobot's `save_episode` also loses the episodes before). The dataset comes from the script's
command line, its features from its `meta/info.json`. The need is an upper bound: raw bytes per frame (images raw),
the episode's stats row, times `MARGIN` for parquet's dictionary pages, plus `FIXED_BYTES` for the files rewritten at
every save and the footers `finalize()` writes.
"""

from __future__ import annotations

import logging
import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lerobot_blindgrasp import compat

from .errors import GripperSafetyStop

logger = logging.getLogger(__name__)

MARGIN = 2.0
STATS_PER_VALUE = 10  # min, max, mean, std, count and five quantiles (LeRobot's compute_episode_stats)
FIXED_BYTES = 64 * 1024
STRING_BYTES = 256  # a string feature (a task text) per frame, generously


class RecordingSpaceError(GripperSafetyStop):
    """Not enough free space for the next recording episode: refused before it starts."""


def frame_bytes(features: dict) -> int:
    """Raw bytes of one frame of a LeRobot feature dict (`{key: {"dtype", "shape"}}`)."""
    total = 0
    for ft in features.values():
        n = int(np.prod(ft["shape"])) if len(ft["shape"]) else 1
        if ft["dtype"] in ("image", "video"):
            total += n
        elif ft["dtype"] in ("string", "language"):
            total += STRING_BYTES
        else:
            total += n * np.dtype(ft["dtype"]).itemsize
    return total


def episode_bytes(features: dict, fps: float, episode_time_s: float) -> int:
    """The upper bound above for one episode of `episode_time_s` at `fps`."""
    frames = int(np.ceil(fps * episode_time_s))
    values = sum(int(np.prod(ft["shape"])) for ft in features.values() if ft["dtype"] not in ("image", "video"))
    row = values * STATS_PER_VALUE * 8
    return int(MARGIN * (frames * frame_bytes(features) + row)) + FIXED_BYTES


def _existing(path: Path) -> Path:
    """`path` or its nearest existing parent: the filesystem the dataset is (or will be) written to."""
    path = Path(path).absolute()
    while not path.exists() and path.parent != path:
        path = path.parent
    return path


@dataclass
class RecordingSpace:
    root: Path
    fps: float
    episode_time_s: float
    fallback_features: dict  # the robot's own, for a dataset whose info.json is not (yet) where expected

    @classmethod
    def of(cls, command_line: compat.CommandLine, action_features: dict, observation_features: dict):
        """The recording a script makes (its `--dataset.repo_id` given) with a robot of these features, or None (no
        dataset is written)."""
        from lerobot.configs.dataset import DatasetRecordConfig
        from lerobot.utils.constants import HF_LEROBOT_HOME

        repo_id = command_line.dataset_repo_id
        if not repo_id:
            return None
        defaults = DatasetRecordConfig.__dataclass_fields__
        root = command_line.dataset_root or HF_LEROBOT_HOME / repo_id
        fps = float(command_line.dataset_fps or defaults["fps"].default)
        episode_s = float(command_line.episode_time_s or defaults["episode_time_s"].default)
        return cls(Path(root), fps, episode_s, robot_dataset_features(action_features, observation_features))

    def features(self) -> dict:
        from lerobot.datasets.io_utils import load_info

        try:
            return load_info(self.root).features
        except (OSError, ValueError, KeyError, TypeError):  # not there (a stamped repo_id) or unreadable
            return self.fallback_features

    def check(self) -> None:
        """Refuse the episode about to start when the dataset's filesystem has less free space than it needs."""
        where = _existing(self.root)
        free = shutil.disk_usage(where).free
        need = episode_bytes(self.features(), self.fps, self.episode_time_s)
        if free < need:
            raise RecordingSpaceError(
                f"Refused to start the next recording episode: {free} bytes free on the filesystem of {where} "
                f"(dataset {self.root}), the episode needs up to {need} bytes ({self.fps:g} fps x "
                f"{self.episode_time_s:g} s). The episodes recorded so far are kept; free some space or shorten "
                "--dataset.episode_time_s, then record on with --resume=true."
            )
        logger.debug("Recording space: %d bytes free on %s, an episode needs up to %d.", free, where, need)


def robot_dataset_features(action_features: dict, observation_features: dict) -> dict:
    """The dataset features lerobot-record derives from a robot with its default (identity) processors."""
    from lerobot.utils.constants import DEFAULT_FEATURES
    from lerobot.utils.feature_utils import hw_to_dataset_features

    return {
        **hw_to_dataset_features(action_features, "action"),
        **hw_to_dataset_features(observation_features, "observation"),
        **DEFAULT_FEATURES,
    }
