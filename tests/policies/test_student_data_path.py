"""The student's data path (`window_cache`): lerobot-train's samples from the low-dim cache are LeRobot's own.

Each test compares against LeRobot's `DatasetReader.get_item` on the same dataset and indices: every key (the
`observation.state_is_pad` flags included), its order, dtype, shape and value, per sample and as a collated batch,
also through a spawned loader process as lerobot-train runs its workers.
"""

from __future__ import annotations

import pickle
import sys

import numpy as np
import pytest
import torch
from lerobot.datasets import LeRobotDataset
from lerobot.datasets.dataset_reader import DatasetReader
from lerobot.utils.constants import ACTION, OBS_STATE
from torch.utils.data import DataLoader, default_collate

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.policies.blindgrasp_transformer import BlindgraspTransformerConfig
from lerobot_blindgrasp.policies.blindgrasp_transformer.window_cache import LowDimWindowReader

EPISODE_LENGTHS = (12, 36, 40)  # one shorter than the 30-step window, so some windows are padded at both ends
TASKS = ("grasp the sphere", "grasp the box")


@pytest.fixture(scope="module")
def dataset_root(tmp_path_factory):
    root = tmp_path_factory.mktemp("data_path") / "ds"
    features = {**spec.dataset_features(), "episode.seed": {"dtype": "int64", "shape": (2,), "names": None}}
    ds = LeRobotDataset.create(
        "local/data_path", fps=spec.CONTROL_HZ, features=features, root=root, use_videos=False
    )
    rng = np.random.default_rng(0)
    for e, length in enumerate(EPISODE_LENGTHS):
        for _ in range(length):
            ds.add_frame(
                {
                    OBS_STATE: rng.normal(size=spec.STATE_DIM).astype(np.float32),
                    ACTION: rng.normal(size=spec.ACTION_DIM).astype(np.float32),
                    "episode.seed": np.array([e, 7], dtype=np.int64),
                    "task": TASKS[e % 2],
                }
            )
        ds.save_episode()
    ds.finalize()
    return root


def windowed(root, **kwargs) -> LeRobotDataset:
    """The dataset as lerobot-train builds it for the student: the policy's 30-step observation window."""
    deltas = BlindgraspTransformerConfig(size="quick").observation_delta_indices
    return LeRobotDataset(
        "local/data_path", root=root, delta_timestamps={OBS_STATE: [d / spec.CONTROL_HZ for d in deltas]}, **kwargs
    )


def assert_same_item(new: dict, ref: dict) -> None:
    assert list(new) == list(ref)
    for key, value in ref.items():
        if isinstance(value, torch.Tensor):
            assert new[key].dtype == value.dtype and new[key].shape == value.shape, key
            assert torch.equal(new[key], value), key
        else:
            assert new[key] == value, key


def test_every_sample_is_lerobots_own(dataset_root):
    ds = windowed(dataset_root)
    assert isinstance(ds.reader, LowDimWindowReader)
    pads = 0
    for i in range(len(ds)):
        new, ref = ds[i], DatasetReader.get_item(ds.reader, i)
        assert_same_item(new, ref)
        pads += int(ref[f"{OBS_STATE}_is_pad"].any())
    assert pads > 30  # the windows near each episode's start are padded: the flags were compared, not just zeros
    sample = ds[5]
    assert sample[OBS_STATE].shape == (30, spec.STATE_DIM) and sample["task"] == TASKS[0]


def test_an_episode_subset_maps_its_frames_as_lerobot_does(dataset_root):
    ds = windowed(dataset_root, episodes=[1, 2])
    assert isinstance(ds.reader, LowDimWindowReader) and len(ds) == sum(EPISODE_LENGTHS[1:])
    for i in range(len(ds)):
        assert_same_item(ds[i], DatasetReader.get_item(ds.reader, i))


def test_a_sample_is_a_copy_not_a_view_of_the_cache(dataset_root):
    ds = windowed(dataset_root)
    first = ds[40]
    first[OBS_STATE].zero_()
    first[ACTION].zero_()
    assert_same_item(ds[40], DatasetReader.get_item(ds.reader, 40))


def test_reads_without_a_window_keep_lerobots_reader(dataset_root):
    plain = LeRobotDataset("local/data_path", root=dataset_root)
    assert type(plain.reader) is DatasetReader


def test_a_batch_through_a_spawned_loader_process_equals_lerobots(dataset_root):
    """lerobot-train's loader: spawned worker processes, each building its own cache after unpickling."""
    ds = windowed(dataset_root)
    ds[0]  # builds the cache here; pickling must drop it
    assert "_low_dim_cache" in ds.reader.__dict__
    assert "_low_dim_cache" not in pickle.loads(pickle.dumps(ds.reader)).__dict__
    indices = [0, 3, 11, 12, 13, 41, 47, 87]
    loader = DataLoader(
        torch.utils.data.Subset(ds, indices),
        batch_size=len(indices),
        num_workers=1,
        multiprocessing_context="spawn",
    )
    batch = next(iter(loader))
    ref = default_collate([DatasetReader.get_item(ds.reader, i) for i in indices])
    assert_same_item(batch, ref)


def test_lerobot_train_itself_trains_on_the_caches_samples(dataset_root, tmp_path, monkeypatch):
    """The real lerobot-train (its `main`, in this process, no loader workers): every sample it draws is served by
    the cache's reader, and the reader says so in the log."""
    from lerobot.scripts import lerobot_train

    from lerobot_blindgrasp.policies.blindgrasp_transformer import window_cache

    served, get_item = [], LowDimWindowReader.get_item
    monkeypatch.setattr(LowDimWindowReader, "get_item", lambda self, i: served.append(i) or get_item(self, i))
    logged = []
    monkeypatch.setattr(window_cache.logger, "info", lambda msg, *args: logged.append(msg % args))
    steps, batch = 2, 4
    argv = [
        "lerobot-train",
        "--policy.type=blindgrasp_transformer",
        "--policy.size=quick",
        "--policy.device=cpu",
        "--policy.push_to_hub=false",
        "--dataset.repo_id=local/data_path",
        f"--dataset.root={dataset_root}",
        f"--output_dir={tmp_path / 'out'}",
        f"--steps={steps}",
        f"--batch_size={batch}",
        "--num_workers=0",
        "--save_checkpoint=false",
        "--wandb.enable=false",
    ]
    monkeypatch.setattr(sys, "argv", argv)
    lerobot_train.main()
    assert len(served) >= steps * batch
    assert any(window_cache.SERVED_LOG in line and str(dataset_root) in line for line in logged)


def test_bench_student_times_each_data_path_and_the_updates_parts(dataset_root):
    from lab.bench import student_bench as student
    from lab.bench.student_parts import PARTS

    torch.manual_seed(0)
    r = student.run(
        student.BenchStudentConfig(
            dataset_root=dataset_root,
            size="quick",
            batch_size=8,
            load_samples=20,
            update_steps=2,
            loader_workers=[0],
            loader_batches=12,  # with the warm-up batch, more than one epoch of this dataset's 88 frames
            profile=True,
            json=True,
        )
    )
    load, update = r["load_ms_per_sample"], r["update_ms_per_sample"]
    assert set(load) == {"lerobot", "lerobot_row", "lerobot_window", "streaming", "cache"}
    assert min(load.values()) > 0
    assert (
        load["cache"] < load["lerobot"] / 3
    )  # tens of microseconds against milliseconds, even on a loaded machine
    for name in ("lerobot_adamw", "foreach_adamw", "fused_adamw"):
        assert update[name]["total"] == pytest.approx(sum(update[name][p] for p in PARTS))
    per_sample = update["lerobot_adamw"]["total"]
    assert r["load_over_update"]["cache"] == pytest.approx(load["cache"] / per_sample)
    assert r["bound_samples_per_s"]["cache"] == pytest.approx(min(1 / load["cache"], 1 / per_sample) * 1e3)
    assert r["update_over_floor"] == pytest.approx(per_sample / r["floor_ms_per_sample"])
    assert update["profile"]["matmul_ms"] > 0 and update["profile"]["aten_ops_per_step"] > 100
    assert [(row["path"], row["num_workers"]) for row in r["loader"]] == [("lerobot", 0), ("cache", 0)]
    assert all(row["samples_per_s"] > 0 for row in r["loader"])
    memory = r["cache_memory"]  # state 12 + action 9 float32, seed 2 int64, timestamp float32, 4 int64 indices
    assert memory["frames"] == sum(EPISODE_LENGTHS) and memory["bytes_per_frame"] == 48 + 36 + 16 + 4 + 32
    assert memory["rss_anon_growth_bytes"] is not None
    with pytest.raises(ValueError, match="dataset_root"):
        student.BenchStudentConfig(dataset_root=None)


def test_lerobot_trains_log_is_read_per_window():
    from lab.bench.student_bench import train_log_windows

    log = (
        "INFO 2026-12-04 17:42:11 ot_train.py:640 step:50 smpl:13K ep:130 epch:2.18 loss:0.923 grdn:1.234 "
        "lr:1.0e-04 updt_s:0.016 data_s:0.226 smp/s:1058 mem_gb:1.23\n"
        "INFO 2026-12-04 17:42:12 ot_train.py:700 Checkpoint policy after step 50\n"
        "INFO 2026-12-04 17:42:23 ot_train.py:640 step:100 smpl:26K ep:260 epch:4.35 loss:0.811 grdn:1.1 "
        "lr:1.0e-04 updt_s:0.015 data_s:0.005 smp/s:12800 mem_gb:1.23\n"
    )
    assert train_log_windows(log) == [
        {"step": "50", "updt_s": 0.016, "data_s": 0.226},
        {"step": "100", "updt_s": 0.015, "data_s": 0.005},
    ]


def test_blindgrasp_bench_imports_only_the_bench_it_runs():
    from lab.bench import BENCHMARKS, _modules

    assert _modules(["--bench.type=student", "--bench.size=cpu"]) == ("student",)
    assert _modules(["--bench.type", "teacher"]) == ("teacher",)
    assert _modules(["--help"]) == BENCHMARKS  # all, so that --help and a wrong type list every choice
