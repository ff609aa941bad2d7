"""The demo dataset writer, its per-episode metadata through LeRobot's edit tools, and the dataset cards.

No teacher needed: episodes are synthetic but go through the real curation, writer and LeRobot code.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import threading

import numpy as np
import pytest
from huggingface_hub import DatasetCard
from lerobot.datasets.dataset_tools import delete_episodes, merge_datasets, remove_feature
from lerobot.datasets.lerobot_dataset import LeRobotDataset

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.cards import dataset_cards as cards
from lerobot_blindgrasp.demos import curation
from lerobot_blindgrasp.demos import dataset as demo_dataset
from lerobot_blindgrasp.demos.episode_writer import EpisodeWriter
from lerobot_blindgrasp.hub import push
from lerobot_blindgrasp.rollout.loop import Episode
from lerobot_blindgrasp.sim import objects

OBJECTS = ("sphere_small", "capsule_large", "cuboid_a_medium", "cylinder_b_small")
TRIMMED = dataclasses.replace(curation.PAPER_CURATION, trim_to_success=True)


def synthetic_episode(i: int, hold_start: int) -> Episode:
    rng = np.random.default_rng(i)
    t = 100
    r = np.zeros(t)
    r[hold_start:] = 0.8
    return Episode(
        object_name=OBJECTS[i % len(OBJECTS)],
        success=i % 2 == 0,
        left_workspace=False,
        physics_failed=False,
        length=t,
        max_lift=0.0,
        env_seed=100 + i,
        env_episode=i,
        randomization=np.array([0.8, 0.9, 1.1 + 0.1 * i, 2.0, 1.0, 0.01, -0.02]),
        traces={
            "state": rng.normal(size=(t, spec.STATE_DIM)).astype(np.float32),
            "action": rng.normal(size=(t, spec.ACTION_DIM)).astype(np.float32),
            "task_reward": r,
            "uniaxial_force": np.full((t, 3), 3.0),  # 9 N per step: the sum passes 200 N at step 22
        },
    )


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    """Six curated episodes written through the real path, trimmed (the opt-in) so that their lengths differ."""
    root = tmp_path_factory.mktemp("ds") / "sim"
    ds = demo_dataset.create(root, "test/sim")
    episodes, cuts = [], []
    for i in range(6):
        ep = synthetic_episode(i, hold_start=20 + 5 * i)
        cut = curation.judge_episode(ep.task_reward, ep.uniaxial_force, TRIMMED)
        assert cut.keep
        demo_dataset.write_episode(ds, ep, cut)
        episodes.append(ep)
        cuts.append(cut)
    ds.finalize()
    return root, episodes, cuts


def test_written_episodes_load_back_with_schema_and_metadata(written):
    root, episodes, cuts = written
    ds = LeRobotDataset("test/sim", root=root, video_backend="pyav")
    assert ds.num_episodes == 6 and ds.fps == spec.CONTROL_HZ
    assert ds.meta.robot_type == demo_dataset.ROBOT_TYPE and ds.meta.video_keys == []
    assert ds.meta.names[spec.STATE_KEY] == list(spec.STATE_NAMES)
    assert ds.meta.names[spec.ACTION_KEY] == list(spec.ACTION_NAMES)
    # Trimmed at the later criterion: hold of 10 steps from 20 + 5i, force sum > 200 N at step 22.
    lengths = [c.keep_steps for c in cuts]
    assert lengths == [max(20 + 5 * i + 9, 22) + 1 for i in range(6)]
    assert ds.num_frames == sum(lengths)
    start = 0
    for ep, n in zip(episodes, lengths, strict=True):
        first, last = ds[start], ds[start + n - 1]
        np.testing.assert_array_equal(first[spec.STATE_KEY].numpy(), ep.state[0])
        np.testing.assert_array_equal(last[spec.ACTION_KEY].numpy(), ep.action[n - 1])
        assert first["task"] == objects.get_object(ep.object_name).task
        assert last["timestamp"].item() == pytest.approx((n - 1) / spec.CONTROL_HZ)
        assert last["episode.seed"].tolist() == [ep.env_seed, ep.env_episode]
        start += n


def test_fast_writer_path_writes_the_same_files_as_lerobots_default(tmp_path):
    import pyarrow.parquet as pq
    from lerobot.datasets import dataset_writer

    original = dataset_writer.embed_images
    roots = {}
    for fast in (True, False):
        root = roots[fast] = tmp_path / f"fast_{fast}"
        ds = demo_dataset.create(root, "test/fast")
        for i in range(3):
            ep = synthetic_episode(i, hold_start=20)
            demo_dataset.write_episode(
                ds, ep, curation.judge_episode(ep.task_reward, ep.uniaxial_force), fast=fast
            )
        ds.finalize()
    assert dataset_writer.embed_images is original  # the skip is scoped to the write
    files = sorted(p.relative_to(roots[True]) for p in roots[True].rglob("*.parquet"))
    assert files == sorted(p.relative_to(roots[False]) for p in roots[False].rglob("*.parquet")) and files
    for f in files:
        a, b = pq.read_table(roots[True] / f), pq.read_table(roots[False] / f)
        assert a.equals(b) and a.schema.equals(b.schema), f
        # Schema metadata too, but for the random cache fingerprint `datasets` stamps on a mapped table.
        meta_a, meta_b = (json.loads((t.schema.metadata or {}).get(b"huggingface", b"{}")) for t in (a, b))
        meta_b.pop("fingerprint", None)
        assert meta_a == meta_b, f
    for name in ("info.json", "stats.json"):
        assert (roots[True] / "meta" / name).read_text() == (roots[False] / "meta" / name).read_text()


def test_the_episode_writer_waits_when_its_queue_is_full_and_keeps_the_order(tmp_path):
    """Backpressure: with 2 jobs waiting (the thread held by the first), a third submit waits for a free place
    instead of growing the queue. Then every episode is saved in the order submitted."""
    ds = demo_dataset.create(tmp_path / "w", "test/w")
    episodes = [synthetic_episode(i, hold_start=20) for i in range(5)]
    cut = curation.judge_episode(episodes[0].task_reward, episodes[0].uniaxial_force, curation.NO_CURATION)
    save = [functools.partial(demo_dataset.write_episode, ds, ep, cut) for ep in episodes]
    gate, writer = threading.Event(), EpisodeWriter(queue=2)
    writer.submit(gate.wait)  # holds the writer thread
    writer.submit(save[0])
    third = threading.Thread(target=writer.submit, args=(save[1],))
    third.start()
    third.join(0.5)
    assert third.is_alive() and writer.pending == 2  # waiting for a free place, not queued
    gate.set()
    third.join(60)
    assert not third.is_alive()
    for job in save[2:]:
        writer.submit(job)
        assert writer.pending <= 2
    writer.close()
    ds.finalize()
    seeds = demo_dataset.episode_table(tmp_path / "w")["env_seed"].tolist()
    assert seeds == [ep.env_seed for ep in episodes]
    assert LeRobotDataset("test/w", root=tmp_path / "w").num_episodes == 5


def test_episode_table_reads_metadata_without_frames(written):
    root, episodes, cuts = written
    table = demo_dataset.episode_table(root)
    assert table["object"].tolist() == [e.object_name for e in episodes]
    assert table["success"].tolist() == [e.success for e in episodes]
    assert table["curation_passed"].all() and not table["left_workspace"].any()
    assert table["rollout_steps"].tolist() == [100] * 6
    np.testing.assert_allclose(table["object_mass_scale"], [e.randomization[2] for e in episodes], rtol=1e-6)
    np.testing.assert_allclose(table["force_sum_n"], [c.force_sum_n for c in cuts], rtol=1e-6)
    assert table["env_seed"].tolist() == [e.env_seed for e in episodes]
    heavy = table[table.object_mass_scale > 1.35].episode_index.tolist()
    assert heavy == [3, 4, 5]
    ds = LeRobotDataset("test/sim", root=root, episodes=heavy, video_backend="pyav")
    assert ds.num_episodes == 3


def test_metadata_survives_lerobot_edit_tools(written, tmp_path):
    """What `lerobot-edit-dataset --operation.type delete_episodes` does: the metadata follows the episodes."""
    root, episodes, _ = written
    src = LeRobotDataset("test/sim", root=root, video_backend="pyav")
    kept = delete_episodes(src, episode_indices=[0, 2], output_dir=tmp_path / "edited", repo_id="test/edited")
    assert kept.num_episodes == 4
    table = demo_dataset.episode_table(tmp_path / "edited")
    survivors = [episodes[i] for i in (1, 3, 4, 5)]
    assert table["episode_index"].tolist() == [0, 1, 2, 3]
    assert table["object"].tolist() == [e.object_name for e in survivors]
    assert table["env_seed"].tolist() == [e.env_seed for e in survivors]
    assert kept[0]["episode.outcome"].shape == (len(demo_dataset.OUTCOME_NAMES),)


def test_sim_demos_merge_with_glove_schema_after_dropping_metadata(written, tmp_path):
    root, _, _ = written
    glove = LeRobotDataset.create(
        "test/glove",
        fps=spec.CONTROL_HZ,
        features=spec.dataset_features(),
        root=tmp_path / "glove",
        robot_type=demo_dataset.ROBOT_TYPE,
        use_videos=False,
        video_backend="pyav",
    )
    for _ in range(2):
        for _ in range(12):
            glove.add_frame(
                {
                    spec.STATE_KEY: np.zeros(12, np.float32),
                    spec.ACTION_KEY: np.zeros(9, np.float32),
                    "task": objects.get_object("sphere_large").task,
                }
            )
        glove.save_episode()
    glove.finalize()
    sim = LeRobotDataset("test/sim", root=root, video_backend="pyav")
    with pytest.raises(ValueError, match="Same features"):
        merge_datasets([sim, glove], output_repo_id="test/bad", output_dir=tmp_path / "bad")
    core = remove_feature(sim, list(demo_dataset.METADATA_FEATURE_NAMES), tmp_path / "core", "test/core")
    merged = merge_datasets([core, glove], output_repo_id="test/merged", output_dir=tmp_path / "merged")
    assert merged.num_episodes == sim.num_episodes + 2
    assert set(merged.meta.features) == set(glove.meta.features)
    # ...and the glove card renders from a lerobot-record style dataset.
    text = str(
        cards.build_card(
            push.push_card_kwargs(tmp_path / "glove", "test/glove", operators=["alice"]), "test/glove"
        )
    )
    meta = cards.validate(text)
    assert "teleoperation" in meta["tags"] and "LeRobot" in meta["tags"]
    assert "grasp and lift the large sphere | 2 | 24" in text and "alice" in text
    assert push.detect_kind(tmp_path / "glove") == "glove"


def test_resume_refuses_foreign_schema(tmp_path):
    other = LeRobotDataset.create(
        "test/other",
        fps=30,
        features=spec.dataset_features(),
        root=tmp_path / "o",
        use_videos=False,
        video_backend="pyav",
    )
    other.add_frame(
        {spec.STATE_KEY: np.zeros(12, np.float32), spec.ACTION_KEY: np.zeros(9, np.float32), "task": "x"}
    )
    other.save_episode()
    other.finalize()
    with pytest.raises(ValueError, match="missing feature 'episode.outcome'.*fps 30"):
        demo_dataset.resume(tmp_path / "o", "test/other")


def test_card_validation_catches_bad_metadata():
    good = (
        "---\nlicense: apache-2.0\ntask_categories: [robotics]\ntags: [LeRobot]\n"
        "configs:\n- config_name: default\n  data_files: data/*/*.parquet\n---\nbody\n"
    )
    assert cards.validate(good)["license"] == "apache-2.0"
    with pytest.raises(ValueError, match="robotics"):
        cards.validate(good.replace("[robotics]", "[text-generation]"))
    with pytest.raises(ValueError, match="license"):
        cards.validate(good.replace("apache-2.0", "apache 2"))
    with pytest.raises(ValueError, match="tags"):
        cards.validate(good.replace("[LeRobot]", "['two words']"))
    assert isinstance(DatasetCard(good).data.to_dict(), dict)


def test_demo_diversity_is_computed_per_object_from_the_written_episodes(written):
    from lab.diagnosis.diversity import diversity

    root, episodes, cuts = written
    d = diversity(root, at_s=0.5)  # frame 10, inside every (trimmed) episode
    assert d["episodes"] == 6 and set(d["objects"]) == set(OBJECTS)
    # By hand from the synthetic episodes: spread across episodes of one object at frame 10 (objects with two
    # episodes only), and the mean step-to-step command change over each episode's written frames.
    by_object: dict[str, list[int]] = {}
    for i, ep in enumerate(episodes):
        by_object.setdefault(ep.object_name, []).append(i)
    spreads, jitters = [], []
    for name, idx in by_object.items():
        if len(idx) > 1:
            spreads.append(np.std([episodes[i].state[10, : spec.NUM_JOINTS] for i in idx], axis=0).mean())
        diffs = [np.abs(np.diff(episodes[i].action[: cuts[i].keep_steps], axis=0)) for i in idx]
        jitter = np.concatenate(diffs).mean()
        jitters.append(jitter)
        assert d["objects"][name]["command_jitter_rad"] == pytest.approx(jitter, rel=1e-5)
    assert d["grasp_pose_spread_rad"] == pytest.approx(np.mean(spreads), rel=1e-5)
    assert d["command_jitter_rad"] == pytest.approx(np.mean(jitters), rel=1e-5)


def test_demo_diversity_command_line(written, capsys):
    from lab.diagnosis.diversity import diversity, main

    root = written[0]
    main([f"--datasets=[demos={root}]", "--at_s=0.5"])
    d = diversity(root, at_s=0.5)
    lines = capsys.readouterr().out.splitlines()
    assert "grasp-pose spread at 0.5 s" in lines[0]
    assert lines[2] == f"| demos | 6 | {d['grasp_pose_spread_rad']:.3f} | {d['command_jitter_rad']:.3f} |"
    main([f"--datasets=[{root}]"])  # no label: the root names the row; default time 3 s
    out = capsys.readouterr().out
    assert "spread at 3 s" in out and f"| {root} | 6 |" in out


def test_merged_demos_stay_mergeable_when_a_source_has_two_episode_files(written, tmp_path):
    """demo_dataset.aggregate: a resumed collection keeps its episode rows in two meta/episodes files. LeRobot's
    aggregate_datasets alone then leaves rows naming a file that does not exist, and merging the result again (a
    DAgger round on targeted demos) fails; after `aggregate` every row names its own file and the re-merge loads."""
    import shutil

    import pyarrow.parquet as pq

    root, episodes, cuts = written
    two = tmp_path / "two"
    shutil.copytree(root, two)
    ds = demo_dataset.resume(two, "test/sim")  # what a resumed collection does: a second episodes file
    demo_dataset.write_episode(ds, episodes[0], cuts[0])
    ds.finalize()
    assert len(list((two / "meta" / "episodes").glob("chunk-*/file-*.parquet"))) == 2
    demo_dataset.aggregate(["test/sim", "test/two"], [root, two], "test/merged", tmp_path / "merged")
    for f in (tmp_path / "merged" / "meta" / "episodes").glob("chunk-*/file-*.parquet"):
        assert set(pq.read_table(f)["meta/episodes/file_index"].to_pylist()) == {int(f.stem[5:])}
    demo_dataset.aggregate(
        ["test/merged", "test/sim"], [tmp_path / "merged", root], "test/again", tmp_path / "again"
    )
    again = LeRobotDataset("test/again", root=tmp_path / "again", video_backend="pyav")
    assert again.num_episodes == 6 + 7 + 6
    table = demo_dataset.episode_table(tmp_path / "again")
    assert table["env_seed"].tolist() == [e.env_seed for e in (*episodes, *episodes, episodes[0], *episodes)]
