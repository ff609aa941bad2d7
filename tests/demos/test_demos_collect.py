"""blindgrasp-collect-demos end to end with a real (barely trained) quick teacher; the push up to the network."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from lerobot.datasets.lerobot_dataset import LeRobotDataset

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.cards import dataset_cards as cards
from lerobot_blindgrasp.cli import GracefulStop, parse_config
from lerobot_blindgrasp.demos import collect_cli, collection_loop, curation, provenance, yield_report
from lerobot_blindgrasp.demos import dataset as demo_dataset
from lerobot_blindgrasp.demos.config import CollectConfig
from lerobot_blindgrasp.hub import push
from lerobot_blindgrasp.sim import objects

N_ENVS = 18  # one env per object
SEED = spec.DEMO_SEED + 3  # demos draw env seeds from their own range only


@pytest.fixture(scope="module")
def teacher(tmp_path_factory) -> Path:
    from lerobot_blindgrasp.teacher import train

    out = tmp_path_factory.mktemp("teacher") / "quick"
    previous = signal.getsignal(signal.SIGTERM)  # the trainer installs its own SIGTERM handler
    try:
        train.train(
            train.TrainTeacherConfig(output_dir=out, preset="quick", iterations=1, num_envs=N_ENVS, export=False)
        )
    finally:
        signal.signal(signal.SIGTERM, previous)
    return out


def config(teacher: Path, out: Path, **kw) -> CollectConfig:
    base = {
        "teacher": teacher,
        "output_dir": out,
        "repo_id": "test/demos",
        "episodes_per_object": 1,
        "num_envs": N_ENVS,
        "seed": SEED,
        "curation": curation.NO_CURATION,
        "progress": False,
    }
    return CollectConfig(**{**base, **kw})


@pytest.fixture(scope="module")
def tiny(teacher, tmp_path_factory):
    """One whole episode per object from the deterministic teacher (so a reference rollout can replay it)."""
    out = tmp_path_factory.mktemp("tiny") / "demos"
    stats = collection_loop.collect_demos(config(teacher, out, stochastic=False))
    return out, stats


def snapshot(root: Path) -> dict:
    return {
        str(p.relative_to(root)): (p.stat().st_size, p.stat().st_mtime_ns) for p in root.rglob("*") if p.is_file()
    }


def test_tiny_collection_loads_back(tiny):
    out, stats = tiny
    ds = LeRobotDataset("test/demos", root=out, video_backend="pyav")
    n_obj = len(objects.PAPER_OBJECTS)
    assert stats.stop_reason == "done" and stats.kept == n_obj
    assert ds.num_episodes == n_obj and ds.fps == 20 and ds.meta.video_keys == []
    for key, names, dim in ((spec.STATE_KEY, spec.STATE_NAMES, 12), (spec.ACTION_KEY, spec.ACTION_NAMES, 9)):
        assert ds.meta.names[key] == list(names) and ds.meta.shapes[key] == (dim,)
        assert ds[0][key].shape == (dim,)
    tasks = sorted(ds.meta.tasks.index)
    assert tasks == sorted(objects.get_object(n).task for n in objects.PAPER_OBJECTS)

    table = demo_dataset.episode_table(out)
    assert sorted(table["object"]) == sorted(objects.PAPER_OBJECTS)
    # --no-curation: whole episodes (100 steps unless the object left the workspace).
    assert (table["length"] == table["rollout_steps"]).all()
    assert ((table["length"] == 100) | table["left_workspace"]).all()
    assert ds.num_frames == table["length"].sum() == stats.frames
    assert len(set(zip(table.env_seed, table.env_episode, strict=True))) == n_obj

    # The action is the absolute target the env commanded: within 0.3 rad of the (noisy) joint reading o_t and
    # inside the joint limits.
    frames = ds.hf_dataset.with_format("numpy")
    state, action = np.stack(frames[spec.STATE_KEY]), np.stack(frames[spec.ACTION_KEY])
    q = state[:, spec.STATE_JOINT_SLICE]
    assert np.abs(action - q).max() <= spec.ACTION_BOUND_RAD + 5 * spec.JOINT_NOISE_STD_RAD
    assert (action >= spec.JOINT_LOWER - 1e-6).all() and (action <= spec.JOINT_UPPER + 1e-6).all()
    assert np.abs(action - q).max() > 0.05  # the teacher moved the fingers

    rep = json.loads((out / yield_report.REPORT_NAME).read_text())
    assert set(rep["objects"]) == set(objects.PAPER_OBJECTS)
    assert all(row["kept"] == 1 for row in rep["objects"].values())
    assert rep["total"]["kept"] == n_obj and rep["demos_per_minute"] > 0
    prov = provenance.load_provenance(out)
    assert prov["runs"][0]["stop_reason"] == "done" and prov["teacher_sha256"] == prov["teacher"]["sha256"]
    card = (out / cards.CARD_NAME).read_text()
    cards.validate(card)
    assert prov["teacher_sha256"] in card and "without curation" in card


def test_frames_are_the_observation_before_each_step_and_the_commanded_target(teacher, tiny):
    """Replay: env i of the collection holds object i with env seed SEED + i; its first episode must match a rollout
    of a fresh env built from the same settings, frame by frame."""
    from lerobot_blindgrasp.sim import randomization

    _assert_replays(teacher, tiny[0], randomization.EVAL_DR)


def test_demos_under_a_calibration_offset_record_it_and_act_in_the_measured_frame(teacher, tmp_path):
    """--joint_calibration_rad (beyond the paper): the rollouts run with the offset, the provenance and the card
    say so, and every frame is what an env with that offset observes and is sent (targets in the measured frame)."""
    from dataclasses import replace

    from lerobot_blindgrasp.sim import randomization

    out = tmp_path / "demos"
    collection_loop.collect_demos(config(teacher, out, stochastic=False, joint_calibration_rad=0.05))
    assert json.loads((out / "collection.json").read_text())["randomization"]["joint_calibration_rad"] == 0.05
    assert "joint_calibration_rad" in (out / "README.md").read_text()
    _assert_replays(teacher, out, replace(randomization.EVAL_DR, joint_calibration_rad=0.05))
    with pytest.raises(ValueError, match="joint_calibration_rad"):
        config(teacher, tmp_path / "x", joint_calibration_rad=-0.1)


def _assert_replays(teacher: Path, out: Path, dr) -> None:
    from lerobot_blindgrasp.sim import rewards
    from lerobot_blindgrasp.sim.batched_config import GraspEnvConfig
    from lerobot_blindgrasp.sim.batched_env import BatchedGraspEnv
    from lerobot_blindgrasp.teacher.policy import TeacherPolicy

    policy = TeacherPolicy(teacher)
    env = BatchedGraspEnv(
        GraspEnvConfig(
            num_envs=N_ENVS,
            seed=SEED,
            episode_s=spec.DEMO_EPISODE_S,
            dr=dr,
            reward=rewards.RewardConfig.from_record(policy.config["reward"]),
        )
    )
    obs = env.reset()
    states, targets = [], []
    for _ in range(env.max_episode_steps):
        states.append(obs["policy"].copy())
        obs, _, _, _, info = env.step(policy(obs, stochastic=False))
        targets.append(info["joint_target"].astype(np.float32))
    states, targets = np.stack(states, 1), np.stack(targets, 1)  # (envs, steps, dim)

    ds = LeRobotDataset("test/demos", root=out, video_backend="pyav")
    frames = ds.hf_dataset.with_format("numpy")
    table = demo_dataset.episode_table(out)
    for row in table.itertuples():
        i = row.env_seed - SEED
        assert row.env_episode == 0 and row.object == objects.PAPER_OBJECTS[i]
        ep = ds.meta.episodes[row.episode_index]
        rows = frames[ep["dataset_from_index"] : ep["dataset_to_index"]]
        np.testing.assert_array_equal(rows[spec.STATE_KEY], states[i, : row.length])
        np.testing.assert_array_equal(rows[spec.ACTION_KEY], targets[i, : row.length])


def test_bad_inputs_are_refused_and_touch_nothing(teacher, tiny, tmp_path, capsys):
    out, _ = tiny
    before = snapshot(out)
    fresh = tmp_path / "fresh"
    student_like = tmp_path / "pretrained_model"  # what lerobot-train writes: a policy, not a teacher
    student_like.mkdir()
    (student_like / "config.json").write_text(json.dumps({"type": "blindgrasp_transformer"}))
    cases = [
        ([f"--teacher={tmp_path / 'missing'}", f"--output_dir={fresh}"], "cannot load the teacher"),
        ([f"--teacher={tmp_path}", f"--output_dir={fresh}"], "no model_<iteration>.pt"),
        ([f"--teacher={teacher}", f"--output_dir={out}"], "already exists"),
        ([f"--teacher={teacher}", f"--output_dir={fresh}", "--resume=true"], "does not exist"),
        (
            [f"--teacher={teacher}", f"--output_dir={out}", "--resume=true", "--stochastic=false"],
            "different curation",
        ),
        (
            [f"--teacher={teacher}", f"--output_dir={out}", "--resume=true", "--curation.enabled=false"],
            "different stochastic",
        ),
        # Seed 0 is a teacher-training env seed: demos from it would overlap training start states.
        ([f"--teacher={teacher}", f"--output_dir={fresh}", "--seed=0"], "outside the demos range"),
        ([f"--teacher={student_like}", f"--output_dir={fresh}"], "not a blindgrasp teacher"),
    ]
    for argv, message in cases:
        with pytest.raises(SystemExit) as exc:
            collect_cli.main([*argv, "--repo_id=test/demos", "--progress=false"])
        assert exc.value.code == 2
        assert message in capsys.readouterr().err
        assert not fresh.exists()
    with pytest.raises(SystemExit):
        collect_cli.main([f"--teacher={teacher}", f"--output_dir={fresh}", "--repo_id=no-slash"])
    assert "USER/NAME" in capsys.readouterr().err and not fresh.exists()
    assert snapshot(out) == before


def test_exception_mid_collection_leaves_finished_episodes_readable(teacher, tmp_path):
    """An error raised from inside the collection loop (here the per-episode callback) still finalizes."""
    out = tmp_path / "crash"

    def explode(ep, cut, written, stats):
        if stats.kept == 3:
            raise RuntimeError("injected failure")

    with pytest.raises(RuntimeError, match="injected failure"):
        collection_loop.collect_demos(config(teacher, out, episodes_per_object=5), on_episode=explode)
    ds = LeRobotDataset("test/demos", root=out, video_backend="pyav")
    assert ds.num_episodes == 3 and len(ds) == ds.meta.total_frames
    ds[len(ds) - 1]  # the last frame of the last episode reads back
    run = provenance.load_provenance(out)["runs"][-1]
    assert run["stop_reason"].startswith("error: RuntimeError") and run["kept"] == 3
    assert json.loads((out / yield_report.REPORT_NAME).read_text())["total"]["kept"] == 3


def test_second_ctrl_c_aborts_at_once_but_never_inside_a_save(teacher, tmp_path):
    out = tmp_path / "abort"

    def double_ctrl_c(ep, cut, written, stats):
        if written and stats.kept == 2:
            signal.raise_signal(signal.SIGINT)  # first: stop after this step
            signal.raise_signal(signal.SIGINT)  # second: abort now

    before = signal.getsignal(signal.SIGINT)  # default_int_handler; SIG_IGN under a shell's background `&`
    with pytest.raises(KeyboardInterrupt):
        collection_loop.collect_demos(config(teacher, out, episodes_per_object=5), on_episode=double_ctrl_c)
    assert signal.getsignal(signal.SIGINT) is before  # handlers restored
    ds = LeRobotDataset("test/demos", root=out, video_backend="pyav")
    assert ds.num_episodes == 2 and provenance.load_provenance(out)["runs"][-1]["stop_reason"] == "interrupted"

    # A second Ctrl-C that lands while an episode is being saved waits for the save to complete.
    with GracefulStop() as stop, pytest.raises(KeyboardInterrupt):
        with stop.saving():
            signal.raise_signal(signal.SIGINT)
            signal.raise_signal(signal.SIGINT)
            saved = True  # reached: no KeyboardInterrupt inside the save
        pytest.fail("the deferred abort must be raised when the save completes")
    assert saved and stop.requested == signal.SIGINT


def _frames(root: Path, repo_id: str = "test/demos") -> tuple[dict, LeRobotDataset]:
    ds = LeRobotDataset(repo_id, root=root, video_backend="pyav")
    return ds.hf_dataset.with_format("numpy")[:], ds


def test_the_writer_thread_writes_the_dataset_the_loop_writes(tmp_path):
    """The shipped teacher, sampled (stochastic), curated as in the paper, with crash checkpoints every few
    episodes: saved by the writer thread behind a queue of 2 (so the loop also waits on it) or in the loop, the
    same seed gives the same dataset, read back with LeRobot's loader, the same files and the same counts."""
    runs = {}
    for queue in (0, 2):
        out = tmp_path / f"queue{queue}"
        cfg = config(None, out, curation=curation.PAPER_CURATION, objects="cylinder_a_medium,cuboid_a_medium",
                     num_envs=2, episodes_per_object=3, max_rollouts_per_object=6, writer_queue=queue)  # fmt: skip
        runs[queue] = (out, collection_loop.collect_demos(cfg))
    (in_loop, s0), (threaded, s2) = runs[0], runs[2]
    assert s0.kept == s2.kept >= 4 and s0.rollouts == s2.rollouts and s0.stop_reason == s2.stop_reason == "done"
    assert s2.checkpoints == s0.checkpoints >= 1 and s2.env_builds == s0.env_builds
    (a, ds_a), (b, ds_b) = _frames(in_loop), _frames(threaded)
    assert ds_a.meta.total_episodes == ds_b.meta.total_episodes == s0.kept
    assert a.keys() == b.keys()
    for key in a:
        np.testing.assert_array_equal(np.stack(a[key]), np.stack(b[key]), err_msg=key)
    assert ds_a.meta.episodes["length"] == ds_b.meta.episodes["length"]
    assert ds_a.meta.episodes["tasks"] == ds_b.meta.episodes["tasks"]
    files = [sorted(str(p.relative_to(r)) for p in r.glob("data/**/*.parquet")) for r in (in_loop, threaded)]
    assert files[0] == files[1] and len(files[0]) >= 2  # LeRobot starts a new data file after a checkpoint
    assert yield_report.load_tally(in_loop).to_json() == yield_report.load_tally(threaded).to_json()


def test_a_write_error_on_the_writer_thread_ends_the_run_in_the_loop(teacher, tmp_path, monkeypatch):
    """The third save fails on the writer thread while the episodes after it wait in the queue: the loop raises
    that error, nothing is written after it, and the two episodes before it stay readable."""
    write, queued, where = demo_dataset.write_episode, threading.Event(), []

    def third_fails(ds, ep, cut, **kw):
        where.append(threading.current_thread())
        if len(where) < 3:
            return write(ds, ep, cut, **kw)
        assert queued.wait(60)  # the episodes after it are in the queue now
        raise OSError(28, "No space left on device", "episode data")

    def count(ep, cut, kept, stats):
        if stats.kept == 5:
            queued.set()

    monkeypatch.setattr(demo_dataset, "write_episode", third_fails)
    with pytest.raises(OSError) as e:
        collection_loop.collect_demos(config(teacher, tmp_path / "err", episodes_per_object=5), on_episode=count)
    assert e.value.filename == "episode data"
    assert len(where) == 3 and threading.main_thread() not in where  # written off the loop; none after the error
    _, ds = _frames(tmp_path / "err")
    assert ds.num_episodes == 2 and len(ds) == ds.meta.total_frames
    run = provenance.load_provenance(tmp_path / "err")["runs"][-1]
    assert run["stop_reason"].startswith("error: OSError") and run["interrupted"]


def test_an_abort_writes_the_queued_episodes_before_finalizing(teacher, tmp_path, monkeypatch):
    """Ctrl-C twice while six kept episodes are still queued (the writer is held before its first save): all six are
    written, then the dataset is finalized."""
    write, gate, on_disk = demo_dataset.write_episode, threading.Event(), []

    def held(ds, ep, cut, **kw):
        assert gate.wait(60)
        return write(ds, ep, cut, **kw)

    def abort(ep, cut, kept, stats):
        if kept and stats.kept == 6:
            on_disk.append(json.loads((tmp_path / "abort" / "meta" / "info.json").read_text())["total_episodes"])
            gate.set()
            signal.raise_signal(signal.SIGINT)
            signal.raise_signal(signal.SIGINT)

    monkeypatch.setattr(demo_dataset, "write_episode", held)
    with pytest.raises(KeyboardInterrupt):
        collection_loop.collect_demos(config(teacher, tmp_path / "abort", episodes_per_object=5), on_episode=abort)
    _, ds = _frames(tmp_path / "abort")
    assert on_disk == [0] and ds.num_episodes == 6 and len(ds) == ds.meta.total_frames
    run = provenance.load_provenance(tmp_path / "abort")["runs"][-1]
    assert run["stop_reason"] == "interrupted" and run["kept"] == 6


@pytest.mark.slow
def test_sigint_finalizes_and_resume_appends(teacher, tmp_path):
    out = tmp_path / "sig"
    # The release-0.1 argparse spellings, as pipeline.py still passes them: translated, with a deprecation note.
    cmd = [
        sys.executable,
        "-m",
        "lerobot_blindgrasp.demos.collect_cli",
        "--teacher",
        str(teacher),
        "--output_dir",
        str(out),
        "--repo_id",
        "test/sig",
        "--episodes_per_object",
        "50",
        "--num_envs",
        str(N_ENVS),
        "--curation.enabled=false",
        "--progress=false",
        "--seed",
        str(spec.DEMO_SEED + 11),
    ]
    env = {**os.environ, "HF_HUB_OFFLINE": "1"}
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    info = out / "meta" / "info.json"
    deadline = time.time() + 120
    while time.time() < deadline and proc.poll() is None:
        if info.is_file() and json.loads(info.read_text() or "{}").get("total_episodes", 0) >= 1:
            break
        time.sleep(0.2)
    assert proc.poll() is None, proc.communicate()[1][-3000:]
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err[-3000:]
    assert "finalizing" in err and "--resume" in err

    ds = LeRobotDataset("test/sig", root=out, video_backend="pyav")
    prov = provenance.load_provenance(out)
    assert prov["runs"][0]["interrupted"] and ds.num_episodes == prov["runs"][0]["kept"] >= 1
    ds[len(ds) - 1]
    first_episode = ds.hf_dataset.with_format("numpy")[: ds.meta.episodes[0]["length"]][spec.ACTION_KEY]
    old_seeds = set(demo_dataset.episode_table(out).env_seed)

    # --resume appends until every object has 2 episodes, with env seeds no earlier run used.
    stats = collection_loop.collect_demos(
        config(teacher, out, repo_id="test/sig", episodes_per_object=2, seed=spec.DEMO_SEED + 11, resume=True)
    )
    assert stats.stop_reason == "done" and stats.kept >= 1
    ds2 = LeRobotDataset("test/sig", root=out, video_backend="pyav")
    assert ds2.num_episodes == ds.num_episodes + stats.kept
    table = demo_dataset.episode_table(out)
    assert (table.groupby("object").size() >= 2).all() and len(table.groupby("object")) == 18
    new_seeds = set(table.env_seed[table.episode_index >= ds.num_episodes])
    assert new_seeds and not new_seeds & old_seeds
    np.testing.assert_array_equal(
        ds2.hf_dataset.with_format("numpy")[: len(first_episode)][spec.ACTION_KEY], first_episode
    )
    runs = provenance.load_provenance(out)["runs"]
    assert len(runs) == 2 and runs[1]["seed_start"] > runs[0]["seed_start"]


def test_push_prepares_everything_then_stops_at_the_network(tiny, monkeypatch, capsys):
    import huggingface_hub.constants

    out, _ = tiny
    (out / cards.CARD_NAME).unlink()
    push.main([f"--root={out}", "--repo_id=test/demos", "--dry_run=true"])
    assert "dry run" in capsys.readouterr().out and (out / cards.CARD_NAME).is_file()

    (out / cards.CARD_NAME).unlink()
    monkeypatch.setattr(huggingface_hub.constants, "HF_HUB_OFFLINE", True)  # what HF_HUB_OFFLINE=1 sets
    with pytest.raises(SystemExit) as exc:
        push.main([f"--root={out}", "--repo_id=test/pushed", "--tags=[unit-test]"])
    captured = capsys.readouterr()
    assert exc.value.code == 1
    # It got as far as LeRobot's push_to_hub creating the repo, the first network call...
    assert "OfflineModeIsEnabled" in captured.err and "repos/create" in captured.err
    # ...with the card prepared: the one LeRobot pushes, naming the new repo, with our content and metadata.
    text = (out / cards.CARD_NAME).read_text()
    meta = cards.validate(text)
    assert {"LeRobot", "unit-test", "simulation"} <= set(meta["tags"])
    assert meta["task_categories"] == ["robotics"] and meta["license"] == "apache-2.0"
    assert "test/pushed" in text and "Yield per object" in text and "@article{lee2025blindgrasping" in text
    assert provenance.load_provenance(out)["teacher_sha256"] in text
    assert "18 episodes" in captured.out and "files" in captured.out

    with pytest.raises(SystemExit) as exc:
        push.main([f"--root={out / 'meta'}", "--repo_id=test/pushed"])
    assert exc.value.code == 2 and "not a LeRobot dataset" in capsys.readouterr().err


def test_bench_demos_reports_speeds(teacher, capsys):
    from lab.bench import demos_bench as bench_demos

    cfg = parse_config(
        bench_demos.BenchDemosConfig,
        [f"--teacher={teacher}", "--num_envs=6", "--objects=medium", "--curation=false", "--episodes_per_object=1",
         "--write_episodes=6", "--writer_pairs=1", "--json=true"],
    )  # fmt: skip
    result = bench_demos.run(cfg)
    assert result["curated_demos"] == 6 and result["rollouts"] >= 6
    assert result["curated_demos_per_cpu_minute"] > 0 and result["frames_written_per_s"] > 0
    assert result["frames_written_per_s_add_frame"] > 0 and result["writer_episodes"] == 6
    assert result["backend"] == "batch"
    # The same collection with the writer thread and in the loop, in pairs in the same run: the same demos, a ratio.
    assert result["writer_pair_demos"] == result["writer_pair_demos_in_loop"] == 6
    assert result["writer_throughput_ratio"] > 0 and len(result["writer_pair_ratios"]) == 1
    assert capsys.readouterr().out == ""  # --json: the dispatcher prints, run() stays quiet


def test_an_empty_curated_collection_is_a_one_line_error(teacher, tmp_path, capsys):
    """A barely trained teacher lifts nothing, so curation keeps nothing: say so, instead of leaving a folder
    that LeRobot later fails to load with an unrelated Hub error."""
    out = tmp_path / "empty"
    with pytest.raises(SystemExit) as exc:
        collect_cli.main(
            [
                f"--teacher={teacher}",
                f"--output_dir={out}",
                "--repo_id=test/empty",
                f"--num_envs={N_ENVS}",
                "--episodes_per_object=1",
                "--max_rollouts_per_object=1",
                "--progress=false",
            ]
        )
    assert exc.value.code == collect_cli.EXIT_EMPTY
    err = [line for line in capsys.readouterr().err.splitlines() if line.startswith("error:")]
    assert len(err) == 1 and "is empty" in err[0] and "--curation.enabled=false" in err[0]
    assert (
        json.loads((out / yield_report.REPORT_NAME).read_text())["total"]["kept"] == 0
    )  # the rollouts were counted
