"""Teacher sample allocation (env share per object) and the whole-loop PPO benchmark."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from lerobot_blindgrasp.sim import objects
from lerobot_blindgrasp.sim.batched_config import GraspEnvConfig, allocate_objects
from lerobot_blindgrasp.sim.batched_env import BatchedGraspEnv

# Harder objects (small, capsules) weighted up, as tried in teacher_cpu_v2.md of the research record (docs/research.md).
HARD_FIRST = tuple(
    {"large": 0.5, "medium": 1.0, "small": 1.5}[objects.get_object(n).size_label]
    * (1.5 if objects.get_object(n).mjcf_type == "capsule" else 1.0)
    for n in objects.PAPER_OBJECTS
)


def test_weighted_allocation_follows_weights_and_interleaves():
    w = HARD_FIRST
    idx = allocate_objects(1026, 18, w)
    counts = np.bincount(idx, minlength=18)
    assert counts.sum() == 1026 and counts.min() >= 1
    expected = np.asarray(w) / np.sum(w) * 1026
    assert np.abs(counts - expected).max() <= 2  # every object at least one env, then shares by weight
    small_capsule = objects.PAPER_OBJECTS.index("capsule_small")
    large_cuboid = objects.PAPER_OBJECTS.index("cuboid_a_large")
    assert counts[small_capsule] > 4 * counts[large_cuboid]
    # Any prefix of the batch already mixes every object (no long run of one object).
    assert set(idx[:60]) == set(range(18))


def test_even_weights_are_the_paper_round_robin():
    assert (allocate_objects(100, 18, None) == np.arange(100) % 18).all()
    assert (np.bincount(allocate_objects(36, 18, (1.0,) * 18)) == 2).all()


def test_env_uses_the_weighted_allocation_and_rejects_bad_weights():
    env = BatchedGraspEnv(GraspEnvConfig(num_envs=40, object_weights=HARD_FIRST))
    counts = {n: env.object_names.count(n) for n in objects.PAPER_OBJECTS}
    assert counts["capsule_small"] > counts["cuboid_a_large"]
    with pytest.raises(ValueError, match="one positive weight per object"):
        GraspEnvConfig(num_envs=4, object_weights=(1.0, -1.0))


def test_the_replayed_raw_physics_leaves_the_env_as_it_was_and_is_timed():
    """The bench replays each physics call right after it (same state, same targets): the env must go on exactly
    as without the replay, bit for bit, resets included."""
    import torch

    from lab.bench.sim_bench import ReplayedPhysics

    cfg = GraspEnvConfig(num_envs=6, seed=3, nthread=1, episode_s=0.2)  # 4-step episodes: resets within the run
    plain, replayed = BatchedGraspEnv(cfg), BatchedGraspEnv(cfg)
    actions = np.random.default_rng(0).uniform(-0.2, 0.2, (6, 6, 9))
    with ReplayedPhysics(replayed.physics) as replay:
        for env in (plain, replayed):
            env.reset()
            env.out = [env.step_tensors(torch.as_tensor(a)) for a in actions]
    assert "step" not in vars(replayed.physics)  # the backend's own step again
    for a, b in zip(plain.out, replayed.out, strict=True):
        assert all(torch.equal(a[0][k], b[0][k]) for k in a[0]) and torch.equal(a[1], b[1])
        assert torch.equal(a[2], b[2]) and torch.equal(a[3], b[3])
    assert torch.equal(plain.physics.qpos, replayed.physics.qpos) and plain.episode.sum() > 0
    assert replay.raw_s > 0 and replay.extra_s > replay.raw_s


@pytest.mark.slow
def test_bench_teacher_reports_collection_update_and_raw_physics():
    out = subprocess.run(
        [
            sys.executable,
            "-m",
            "lab.bench",
            "--bench.type=teacher",
            "--bench.preset=quick",
            "--bench.num_envs=18",
            "--bench.iterations=1",
            "--bench.threads=1",
            "--bench.update_threads=2",
            "--bench.json=true",
        ],
        capture_output=True,
        text=True,
        timeout=300,
        check=True,
        cwd=Path(__file__).resolve().parents[2],  # the lab runs from the repository root
    ).stdout
    r = json.loads(out)  # stdout holds only the JSON (rsl-rl's model printout goes to stderr)
    assert r["num_envs"] == 18 and r["hidden_dims"] == [128, 64]
    assert (r["physics_threads"], r["torch_threads"], r["update_threads"]) == (1, 1, 2)
    assert r["collect_s_per_it"] > 0 and r["update_s_per_it"] > 0 and r["raw_control_steps_per_s"] > 0
    assert 0 < r["collect_cores_busy"] < 1.5 and 0 < r["update_cores_busy"] < 2.5  # 1 physics, 2 update threads
    assert r["update_over_collect"] == pytest.approx(r["update_s_per_it"] / r["collect_s_per_it"])
    assert r["loop_over_raw"] == pytest.approx(r["loop_env_steps_per_s"] / r["raw_control_steps_per_s"])
    raw_s = 24 * 18 / r["raw_control_steps_per_s"]  # one iteration of 24 steps x 18 envs
    assert r["overhead_ms_per_step"] == pytest.approx(1e3 * (r["collect_s_per_it"] - raw_s) / 24)


@pytest.mark.slow
def test_bench_teacher_times_a_trained_checkpoint_and_refuses_another_presets(tmp_path, capsys):
    import signal

    from lab.bench.teacher_bench import BenchTeacherConfig, run
    from lerobot_blindgrasp.teacher import train

    previous = signal.getsignal(signal.SIGTERM)
    try:
        ckpt = train.train(
            train.TrainTeacherConfig(
                output_dir=tmp_path / "run", preset="quick", iterations=1, num_envs=18, threads=1, export=False
            )
        )
    finally:
        signal.signal(signal.SIGTERM, previous)
    r = run(BenchTeacherConfig(preset="quick", num_envs=18, iterations=1, threads=1, checkpoint=ckpt, json=True))
    assert r["checkpoint"] == str(ckpt) and r["update_s_per_it"] > 0 and r["raw_control_steps_per_s"] > 0
    with pytest.raises(SystemExit, match="not a checkpoint of preset 'cpu'"):
        run(BenchTeacherConfig(preset="cpu", num_envs=18, iterations=1, threads=1, checkpoint=ckpt, json=True))
    with pytest.raises(ValueError, match="drop --hidden_dims"):
        BenchTeacherConfig(preset="quick", checkpoint=ckpt, hidden_dims=[64])
    with pytest.raises(FileNotFoundError, match="no file"):
        BenchTeacherConfig(preset="quick", checkpoint=tmp_path / "model_9.pt")


def test_the_update_runs_with_its_own_torch_threads_and_acting_gets_its_count_back():
    import torch

    from lerobot_blindgrasp.teacher.train import with_torch_threads

    previous = torch.get_num_threads()
    seen = []

    def update(fail=False):
        seen.append(torch.get_num_threads())
        if fail:
            raise RuntimeError("nan in the loss")
        return {"loss": 1.0}

    try:
        torch.set_num_threads(1)
        threaded = with_torch_threads(update, 2)
        assert threaded() == {"loss": 1.0} and seen == [2] and torch.get_num_threads() == 1
        with pytest.raises(RuntimeError, match="nan"):
            threaded(fail=True)
        assert seen == [2, 2] and torch.get_num_threads() == 1  # restored when the update raises too
    finally:
        torch.set_num_threads(previous)


def test_the_critic_beside_the_actor_acts_bit_identically_in_its_own_thread():
    """`critic_beside_actor`: the critic's forward runs in a second thread while the actor's runs; actions, values,
    log-probs and distribution parameters are rsl-rl's own `act`'s, bit for bit, under the caller's inference mode."""
    import contextlib
    import threading

    import torch
    from rsl_rl.runners import OnPolicyRunner

    from lerobot_blindgrasp import presets
    from lerobot_blindgrasp.teacher.train import build_env_config, critic_beside_actor
    from lerobot_blindgrasp.teacher.vecenv import RslRlGraspEnv

    preset = presets.get("cpu", "teacher")
    env = BatchedGraspEnv(build_env_config(preset, 36, seed=1, nthread=1))
    with contextlib.redirect_stdout(None):
        runner = OnPolicyRunner(RslRlGraspEnv(env), preset.runner_cfg(), log_dir=None, device="cpu")
    alg, critic = runner.alg, runner.alg.critic
    obs = runner.env.get_observations()
    threads = []
    critic.register_forward_hook(lambda *_: threads.append(threading.get_ident()))

    def acted():
        torch.manual_seed(7)  # the actor samples its actions
        with torch.inference_mode():
            actions = alg.act(obs)
        t = alg.transition
        out = [actions, t.values, t.actions_log_prob, *t.distribution_params]
        alg.transition.clear()
        return out

    own = acted()
    critic_beside_actor(alg, "cpu")
    beside = acted()
    assert all(torch.equal(a, b) for a, b in zip(own, beside, strict=True))
    assert beside[1].is_inference() and alg.critic is critic  # the caller's mode; the critic module back in place
    assert threads[0] == threading.get_ident() and threads[1] != threading.get_ident()
    act = alg.act
    critic_beside_actor(alg, "cuda")  # on a GPU the forwards are queued on the device: no thread
    assert alg.act is act


def test_the_update_defaults_to_the_physics_threads_then_the_acting_threads():
    from types import SimpleNamespace

    from lerobot_blindgrasp.teacher.train import update_thread_count

    def env(nthread):
        return SimpleNamespace(physics=SimpleNamespace(nthread=nthread))

    def cfg(update_threads):
        return SimpleNamespace(update_threads=update_threads, torch_threads=1)

    assert update_thread_count(cfg(3), env(2)) == 3  # asked for
    assert update_thread_count(cfg(0), env(2)) == 2  # the cores collection used
    assert update_thread_count(cfg(0), env(0)) == 1  # Warp: no CPU physics threads


def test_progress_curves_sum_training_time_and_weigh_objects_equally(tmp_path):
    from torch.utils.tensorboard import SummaryWriter

    from lab.diagnosis.progress import plot_metrics, plot_progress, progress

    (tmp_path / "teacher_config.json").write_text(json.dumps({"num_envs": 10, "runner": {"num_steps_per_env": 4}}))
    # Two sessions (a resume): the second rewrites iteration 2, as rsl-rl does after loading model_2.pt.
    for session, its in ((0, range(3)), (1, range(2, 4))):
        w = SummaryWriter(str(tmp_path), filename_suffix=f".s{session}")
        for it in its:
            w.add_scalar("Perf/collection_time", 3.0, it)
            w.add_scalar("Perf/learning_time", 1.0 + session, it)
            for k, name in enumerate(objects.PAPER_OBJECTS):
                w.add_scalar(f"Success/{name}", 1.0 if k == 0 else 0.0, it)  # only cuboid_a_large succeeds
        w.close()
    p = progress(tmp_path, window=1)
    assert p["iteration"] == [0, 1, 2, 3]
    assert p["env_steps"] == [40, 80, 120, 160]
    assert p["wall_h"][-1] * 3600 == pytest.approx(4 + 4 + 5 + 5)  # the later session's value for iteration 2
    assert p["success_all18"][-1] == pytest.approx(1 / 18) and p["success_medium"][-1] == 0.0
    assert progress(tmp_path, window=1, until=2)["iteration"] == [0, 1, 2]  # one budget for side-by-side runs
    plot_progress({"run": tmp_path, "same run again": tmp_path}, tmp_path / "p.png", until=2)
    plot_metrics({"run": tmp_path}, ["Perf/learning_time", "Success/cuboid_a_large"], tmp_path / "m.png", until=2)
    assert (tmp_path / "m.png").stat().st_size > 1000
    assert (tmp_path / "p.png").stat().st_size > 1000


def test_a_run_continued_in_another_directory_is_one_curve(tmp_path, capsys):
    """RUN_A+RUN_B: A up to B's first iteration, then B, with B's training time added to A's."""
    from torch.utils.tensorboard import SummaryWriter

    from lab.diagnosis.progress import main, progress

    for name, its, secs in (("a", range(5), 2.0), ("b", range(3, 6), 10.0)):  # b resumed a's model_2.pt
        d = tmp_path / name
        d.mkdir()
        (d / "teacher_config.json").write_text(json.dumps({"num_envs": 10, "runner": {"num_steps_per_env": 4}}))
        w = SummaryWriter(str(d))
        for it in its:
            w.add_scalar("Perf/collection_time", secs, it)
            w.add_scalar("Perf/learning_time", 0.0, it)
            for k, obj in enumerate(objects.PAPER_OBJECTS):  # b lifts cuboid_a_large, nothing else does
                w.add_scalar(f"Success/{obj}", float(name == "b" and k == 0), it)
        w.close()
    p = progress((tmp_path / "a", tmp_path / "b"), window=1)
    assert p["iteration"] == [0, 1, 2, 3, 4, 5] and p["env_steps"][-1] == 6 * 40
    assert np.diff(p["wall_h"]) * 3600 == pytest.approx([2, 2, 10, 10, 10])
    assert p["success_all18"][2] == 0.0 and p["success_all18"][3] == pytest.approx(1 / 18)
    chained = f"a then b={tmp_path / 'a'}+{tmp_path / 'b'}"
    main([f"--output={tmp_path / 'c.png'}", f"--runs=[{chained}]", "--metrics=[Success/cuboid_a_large]"])
    assert '"a then b"' in capsys.readouterr().out and (tmp_path / "c_metrics.png").is_file()


def _timed_run(run_dir, iterations):
    """A teacher run directory with a config and `iterations` iterations of 3 s collection and 1 s update."""
    from torch.utils.tensorboard import SummaryWriter

    run_dir.mkdir(exist_ok=True)
    (run_dir / "teacher_config.json").write_text(json.dumps({"num_envs": 10, "runner": {"num_steps_per_env": 4}}))
    w = SummaryWriter(str(run_dir))
    for it in range(iterations):
        w.add_scalar("Perf/collection_time", 3.0, it)
        w.add_scalar("Perf/learning_time", 1.0, it)
    w.close()
    return run_dir


def test_progress_command_line_takes_the_figure_and_the_runs_as_named_flags(tmp_path, capsys):
    from lab.diagnosis.progress import main

    _timed_run(tmp_path, iterations=4)
    out = tmp_path / "figs" / "q.png"
    out.parent.mkdir()
    main(
        [
            f"--output={out}",
            f"--runs=[run={tmp_path}]",
            "--until=2",
            "--metrics=[Perf/learning_time,Perf/collection_time]",
        ]
    )
    assert json.loads(capsys.readouterr().out)["last"]["run"]["iteration"] == 2
    assert out.stat().st_size > 1000 and (out.parent / "q_metrics.png").stat().st_size > 1000
    with pytest.raises(SystemExit, match="give the runs"):
        main([f"--output={out}", "--until=2"])
    with pytest.raises(SystemExit, match="output"):  # the figure is required
        main([f"--runs=[run={tmp_path}]"])
    with pytest.raises(SystemExit):  # positional arguments are no longer accepted
        main([str(out), f"run={tmp_path}"])


def test_held_out_evals_are_marked_on_the_run_that_holds_their_checkpoint(tmp_path, capsys):
    from lab.diagnosis.progress import main
    from lerobot_blindgrasp.teacher.policy import file_sha256

    runs = {}
    for name in ("a", "b"):
        d = _timed_run(tmp_path / name, iterations=4)
        (d / "model_3.pt").write_bytes(name.encode() * 10)  # a distinct checkpoint per run
        runs[name] = d

    def eval_of(run, iteration, det, stoch):
        out = tmp_path / f"eval_{run}"
        out.mkdir()
        per_object = {  # success rates: `det` on one object, 0 on the others; objects weigh equally
            mode: {
                "per_object": {
                    o: {"success_rate": rate if k == 0 else 0.0} for k, o in enumerate(objects.PAPER_OBJECTS)
                }
            }
            for mode, rate in (("deterministic", det), ("stochastic", stoch))
        }
        (out / "eval.json").write_text(
            json.dumps(
                {
                    "iteration": iteration,
                    "checkpoint_sha256": file_sha256(runs[run] / "model_3.pt"),
                    "modes": per_object,
                }
            )
        )
        return out

    fig = tmp_path / "p.png"
    main(
        [f"--output={fig}", f"--runs=[A={runs['a']},B={runs['b']}]", f"--held_out=[{eval_of('b', 3, 0.9, 0.45)}]"]
    )
    held = json.loads(capsys.readouterr().out)["held_out"]
    assert list(held) == ["B"] and held["B"][0]["iteration"] == 3
    assert held["B"][0]["success_all18"] == pytest.approx({"deterministic": 0.05, "stochastic": 0.025})
    assert fig.stat().st_size > 1000
    (tmp_path / "stray").mkdir()
    (tmp_path / "stray" / "model_3.pt").write_bytes(b"another run")
    runs["a"], stray = tmp_path / "stray", eval_of("a", 3, 1.0, 1.0)
    with pytest.raises(SystemExit, match="none of the runs holds"):  # the runs plotted do not hold its weights
        main([f"--output={fig}", f"--runs=[B={runs['b']}]", f"--held_out=[{stray}]"])
    with pytest.raises(SystemExit, match="no eval.json"):
        main([f"--output={fig}", f"--runs=[B={runs['b']}]", f"--held_out=[{tmp_path / 'missing'}]"])
