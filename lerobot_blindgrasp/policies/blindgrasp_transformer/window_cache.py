"""The student's data path: LeRobotDataset windows sliced from one in-memory tensor per column (as robomimic's
`hdf5_cache_mode="low_dim"`), the same items as LeRobot's `DatasetReader`, which builds each window through Python
lists at a cost above the student's update. Only a reader of this plugin's schema (`ours`) that the cache reproduces
exactly (`servable`) is served; `BLINDGRASP_LOW_DIM_CACHE=0` at load time keeps LeRobot's path for all.
"""

from __future__ import annotations

import logging
import os

import numpy as np
import pyarrow as pa
import torch
from lerobot.datasets.dataset_reader import DatasetReader

from lerobot_blindgrasp import compat, spec

ENV_SWITCH = "BLINDGRASP_LOW_DIM_CACHE"
SERVED_LOG = "windows served from an in-memory low-dim cache"  # logged (INFO) when a reader is upgraded
logger = logging.getLogger(__name__)
_CACHE_ATTR = "_low_dim_cache"


def _column_dtype(arrow_type: pa.DataType) -> torch.dtype | None:
    """The dtype LeRobot's `torch.tensor(python value)` yields for a column of this type; None: not servable."""
    while pa.types.is_fixed_size_list(arrow_type) or pa.types.is_list(arrow_type):
        arrow_type = arrow_type.value_type
    if pa.types.is_boolean(arrow_type):
        return torch.bool
    if pa.types.is_integer(arrow_type):
        return torch.int64  # Python int -> int64
    if pa.types.is_floating(arrow_type):
        return torch.get_default_dtype()  # Python float -> the default dtype (float32)
    return None


def _to_numpy(name: str, column: pa.ChunkedArray) -> np.ndarray:
    """A column as one (rows,) or (rows, length) array; vectors must have one length."""
    array = column.combine_chunks() if column.num_chunks != 1 else column.chunk(0)
    if array.null_count:
        raise ValueError(f"column {name!r} has nulls: the low-dim cache cannot serve it")
    if not (pa.types.is_fixed_size_list(array.type) or pa.types.is_list(array.type)):
        return np.array(array.to_numpy(zero_copy_only=False))  # a copy: the cache owns its memory
    lengths = np.unique(array.value_lengths().to_numpy(zero_copy_only=False)) if len(array) else np.array([0])
    if len(lengths) != 1 or array.flatten().null_count:
        raise ValueError(
            f"column {name!r} is not one fixed-length vector per frame: the low-dim cache cannot serve it"
        )
    flat = _to_numpy(name, pa.chunked_array([array.flatten()]))
    return flat.reshape(len(array), int(lengths[0]), *flat.shape[1:])


def servable(reader: DatasetReader) -> bool:
    """Whether the cache reproduces this reader's items exactly (else LeRobot's path stays)."""
    meta, hf = reader._meta, reader.hf_dataset
    if reader.delta_indices is None or hf is None or len(hf) == 0 or hf._indices is not None:
        return False
    if meta.camera_keys or meta.video_keys or meta.depth_keys or reader._image_transforms is not None:
        return False
    if getattr(meta, "has_language_columns", False):
        return False
    schema = hf.data.schema
    if any(_column_dtype(f.type) is None for f in schema) or getattr(meta, "tasks", None) is None:
        return False
    if not {"index", "episode_index", "task_index"} <= set(schema.names):
        return False
    return all(key in schema.names for key in reader.delta_indices)


class LowDimCache:
    """Every column of one reader's table as a torch tensor, plus what LeRobot's `get_item` looks up per frame."""

    def __init__(self, reader: DatasetReader):
        table = reader.hf_dataset.data.table
        self.columns: dict[str, torch.Tensor] = {}
        for name, field in zip(table.schema.names, table.schema, strict=True):
            column = table.column(name)
            self.columns[name] = torch.from_numpy(_to_numpy(name, column)).to(_column_dtype(field.type))
        episodes = reader._meta.episodes
        self.ep_from = torch.as_tensor(np.asarray(episodes["dataset_from_index"]), dtype=torch.int64)
        self.ep_to = torch.as_tensor(np.asarray(episodes["dataset_to_index"]), dtype=torch.int64)
        self.deltas = {key: torch.as_tensor(d, dtype=torch.int64) for key, d in reader.delta_indices.items()}
        self.abs_to_rel = None  # None: LeRobot uses the absolute index as the row (no episode filter)
        if reader._absolute_to_relative_idx is not None:
            index = self.columns["index"]
            self.abs_to_rel = torch.full((int(index.max()) + 1,), -1, dtype=torch.int64)
            self.abs_to_rel[index] = torch.arange(len(index))
        self.tasks = list(reader._meta.tasks.index)

    def rows(self, absolute: torch.Tensor) -> torch.Tensor:
        if self.abs_to_rel is None:
            return absolute
        rel = self.abs_to_rel[absolute]
        if bool((rel < 0).any()):
            raise KeyError(f"frames {absolute[rel < 0].tolist()} are not in the selected episodes")
        return rel

    def item(self, idx: int) -> dict:
        """What LeRobot's `DatasetReader.get_item(idx)` returns for a low-dim dataset, in the same key order."""
        item = {name: col[idx].clone() for name, col in self.columns.items()}
        ep_idx, abs_idx = int(item["episode_index"]), int(item["index"])
        start, end = int(self.ep_from[ep_idx]), int(self.ep_to[ep_idx])
        padding, windows = {}, {}
        for key, delta in self.deltas.items():
            wanted = abs_idx + delta
            padding[f"{key}_is_pad"] = (wanted < start) | (wanted >= end)
            windows[key] = self.columns[key][self.rows(wanted.clamp(start, end - 1))]
        item = {**item, **padding, **windows}  # a window replaces its frame's value in place
        item["task"] = self.tasks[int(item["task_index"])]
        return item


class LowDimWindowReader(DatasetReader):
    """LeRobot's reader, with `get_item` served from a per-process `LowDimCache` (see the module docstring)."""

    def get_item(self, idx) -> dict:
        cache = self.__dict__.get(_CACHE_ATTR)
        if cache is None:
            cache = self.__dict__[_CACHE_ATTR] = LowDimCache(self)
        return cache.item(int(idx))

    def __getstate__(self) -> dict:
        # Each loader process builds its own cache from the (memory-mapped) table instead of receiving a copy.
        state = dict(self.__dict__)
        state.pop(_CACHE_ATTR, None)
        return state


def enabled() -> bool:
    """The switch, read at each dataset load (so a process can time both paths, and its spawned workers follow)."""
    return os.environ.get(ENV_SWITCH, "1") != "0"


def ours(meta) -> bool:
    """Whether a dataset carries this plugin's schema: its state and action names are `spec`'s, in `spec`'s order."""
    features = getattr(meta, "features", None) or {}
    return all(
        isinstance(features.get(key), dict) and list(features[key].get("names") or ()) == list(feature["names"])
        for key, feature in spec.dataset_features().items()
    )


def _choose(reader: DatasetReader) -> type[DatasetReader] | None:
    """The reader class for a reader that has just loaded its table (None: it stays as it is)."""
    if type(reader) is LowDimWindowReader:
        reader.__dict__.pop(_CACHE_ATTR, None)  # reloaded: rebuild from the new table
    elif type(reader) is DatasetReader and enabled() and ours(reader._meta) and servable(reader):
        logger.info("blindgrasp: %s %s", reader.root, SERVED_LOG)
        return LowDimWindowReader
    return None


def install_window_cache() -> None:
    """From now on in this process, serve the servable readers of this plugin's datasets from the cache."""
    compat.serve_dataset_readers_with(_choose)
