"""`blindgrasp-train-teacher`: PPO teacher training with rsl-rl's OnPolicyRunner.

    blindgrasp-train-teacher --preset cpu --output-dir runs/teacher_cpu

The run directory gets TensorBoard logs (reward terms, success per object, fps, collection/learning time),
`model_<it>.pt` checkpoints every `save_interval` iterations, and `teacher_config.json`. Re-running the same
command resumes from the latest checkpoint; Ctrl-C saves one before exiting. At the end the actor is exported
to TorchScript and ONNX (`exported/`).
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import logging
import os
import signal
import sys
import time
from pathlib import Path

import torch
from tqdm import tqdm

from lerobot_blindgrasp.sim import randomization
from lerobot_blindgrasp.sim.env import BatchedGraspEnv, GraspEnvConfig
from lerobot_blindgrasp.teacher import presets
from lerobot_blindgrasp.teacher.policy import CONFIG_NAME, latest_checkpoint
from lerobot_blindgrasp.teacher.vecenv import RslRlGraspEnv

log = logging.getLogger("blindgrasp.teacher")


def build_env_config(preset: presets.TeacherPreset, num_envs: int, seed: int, nthread: int = 0) -> GraspEnvConfig:
    dr = randomization.PAPER_DR if preset.external_force else randomization.PAPER_DR.without_external_force()
    return GraspEnvConfig(
        num_envs=num_envs,
        seed=seed,
        reward=preset.reward,
        dr=dr,
        nthread=nthread,
        object_weights=preset.object_weights,
    )


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--preset", choices=sorted(presets.PRESETS), default="cpu")
    p.add_argument("--output-dir", required=True, type=Path)
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--iterations", type=int, default=None, help="override the preset's max iterations")
    p.add_argument("--num-envs", type=int, default=None, help="override the preset's number of envs")
    p.add_argument("--no-incentive", action="store_true", help="w2 = 0: the teacher of the 'Student w/o r_i' ablation")
    p.add_argument("--student-obs", action="store_true", help="'RL w/ o_t' baseline: actor and critic see only o_t")
    p.add_argument("--threads", type=int, default=0, help="physics threads (0: all CPUs)")
    p.add_argument("--torch-threads", type=int, default=1, help="torch intra-op threads for the PPO update")
    p.add_argument("--no-export", action="store_true")
    return p.parse_args(argv)


def train(args: argparse.Namespace) -> Path:
    preset = presets.Variant(no_incentive=args.no_incentive, student_obs=args.student_obs).apply(
        presets.get_preset(args.preset)
    )
    num_envs = args.num_envs or preset.num_envs
    iterations = args.iterations or preset.max_iterations
    out = args.output_dir
    out.mkdir(parents=True, exist_ok=True)
    torch.manual_seed(args.seed)
    # PPO on these small MLPs gains little from intra-op threads, and OpenMP threads that spin while MuJoCo's
    # threads (or any other process) hold the cores made the update 5-8x slower on a busy 2-core machine.
    torch.set_num_threads(args.torch_threads)

    config = {
        "preset": preset.name,
        "variant": {"no_incentive": args.no_incentive, "student_obs": args.student_obs},
        "num_envs": num_envs,
        "seed": args.seed,
        "iterations": iterations,
        "runner": preset.runner_cfg(),
        "reward": dataclasses.asdict(preset.reward),
        "external_force": preset.external_force,
        "object_weights": preset.object_weights and list(preset.object_weights),
        "deviations": list(preset.deviations),
        "command": " ".join([Path(sys.argv[0]).name, *sys.argv[1:]]),
    }
    cfg_path = out / CONFIG_NAME
    if cfg_path.exists():
        old = json.loads(cfg_path.read_text())
        for key in ("preset", "variant", "num_envs", "runner", "reward", "object_weights"):
            if old.get(key) != config[key]:
                raise SystemExit(f"{out} holds a run with a different {key!r}; use another --output-dir")
    else:
        cfg_path.write_text(json.dumps(config, indent=2))

    env = BatchedGraspEnv(build_env_config(preset, num_envs, args.seed, args.threads))
    bar = tqdm(total=iterations, desc=f"teacher[{preset.name}]", unit="it", dynamic_ncols=True)
    steps_per_it = preset.runner["num_steps_per_env"]
    counter = {"steps": 0}

    def tick():
        counter["steps"] += 1
        if counter["steps"] % steps_per_it == 0:
            bar.update(1)

    from rsl_rl.runners import OnPolicyRunner  # heavy import, after argument checks

    vec = RslRlGraspEnv(env, on_step=tick)
    runner = OnPolicyRunner(vec, preset.runner_cfg(), log_dir=str(out), device="cpu")
    ckpt = latest_checkpoint(out)
    done_its = 0
    if ckpt is not None:
        runner.load(str(ckpt))
        done_its = runner.current_learning_iteration + 1
        runner.current_learning_iteration = done_its
        bar.update(done_its)
        log.info("resuming from %s (iteration %d)", ckpt, done_its)
    remaining = iterations - done_its
    console = open(out / "train_console.log", "a")
    # SIGTERM (e.g. a job scheduler) behaves like Ctrl-C: save and exit.
    signal.signal(signal.SIGTERM, lambda *_: (_ for _ in ()).throw(KeyboardInterrupt()))
    t0 = time.time()
    interrupted = False
    try:
        if remaining > 0:
            with contextlib.redirect_stdout(console):  # rsl-rl prints a table per iteration; keep it in a file
                runner.learn(remaining, init_at_random_ep_len=done_its == 0)
    except KeyboardInterrupt:
        interrupted = True
        runner.save(str(out / f"model_{runner.current_learning_iteration}.pt"))
    finally:
        console.close()
        bar.close()
    wall = time.time() - t0
    its_run = runner.current_learning_iteration + 1 - done_its
    final = latest_checkpoint(out)
    if not args.no_export:
        export(runner, out / "exported")
    write_learning_curve(out)
    summary = {
        "checkpoint": str(final),
        "iterations": runner.current_learning_iteration + 1,
        "interrupted": interrupted,
        "wall_clock_s_this_session": wall,
        "env_steps_this_session": its_run * steps_per_it * num_envs,
        "env_steps_per_s": its_run * steps_per_it * num_envs / max(wall, 1e-9),
        "physics_resets": env.physics_resets,
    }
    (out / "train_summary.json").write_text(json.dumps(summary, indent=2))
    print(json.dumps(summary, indent=2))
    if interrupted:
        print(f"interrupted: saved {final}; run the same command to resume", file=sys.stderr)
        raise SystemExit(130)
    return final


def write_learning_curve(run_dir: Path) -> None:
    """learning_curve.png in the run directory, from its TensorBoard scalars."""
    from lerobot_blindgrasp.plots import plot_curves, teacher_curves

    curves = teacher_curves(run_dir)
    if curves:
        plot_curves(run_dir / "learning_curve.png", curves, f"Teacher PPO ({run_dir.name})")


def export(runner, path: Path) -> None:
    """TorchScript and ONNX of the actor's mean (the deterministic teacher), via rsl-rl's exporters."""
    runner.export_policy_to_jit(str(path), "teacher.pt")
    try:
        runner.export_policy_to_onnx(str(path), "teacher.onnx")
    except Exception as e:  # ONNX export depends on optional onnxscript versions; JIT is enough for us
        log.warning("ONNX export failed: %s", e)


def main(argv=None) -> None:
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    train(parse_args(argv))


if __name__ == "__main__":
    main()
