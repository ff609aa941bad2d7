"""`blindgrasp-train-teacher`: PPO teacher training with rsl-rl's OnPolicyRunner.

    blindgrasp-train-teacher --output_dir=runs/teacher   # the shipped teacher's recipe, --preset=cpu_bc_capsule

The run directory gets TensorBoard logs (reward terms, success per object, fps, collection/learning time),
`model_<it>.pt` checkpoints every `save_interval` iterations, and `teacher_config.json`. Re-running the same
command resumes from the newest checkpoint that loads; Ctrl-C saves one before exiting. At the end the actor is
exported to TorchScript and ONNX (`exported/`), and `train_summary.json` is written last: it marks a finished run.

Crash safety: every checkpoint is written to a temporary file and renamed into place (`durable.atomic_path`), so a
kill during a save leaves the previous checkpoints and no `model_<it>.pt` that is cut short. A newest checkpoint
that does not load all the same (a copy gone wrong, a disk error) is renamed `*.corrupt` with a warning naming it,
and the run resumes from the one before. A kill costs at most the iterations since the last save (`save_interval`).
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import logging
import os
import re
import shutil
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import torch
from tqdm import tqdm

from lerobot_blindgrasp import durable, spec
from lerobot_blindgrasp.cli import interrupts_as_keyboard_interrupt, parse_config, sleeping_openmp_threads
from lerobot_blindgrasp.presets import SHIPPED_TEACHER_PRESET
from lerobot_blindgrasp.presets import teacher as presets
from lerobot_blindgrasp.sim import randomization
from lerobot_blindgrasp.sim.env import BatchedGraspEnv, GraspEnvConfig
from lerobot_blindgrasp.teacher import blind_approach, distributed
from lerobot_blindgrasp.teacher.policy import CONFIG_NAME, latest_checkpoint, observation_layout
from lerobot_blindgrasp.teacher.vecenv import RslRlGraspEnv

log = logging.getLogger("blindgrasp.teacher")
# teacher_config.json keys added after runs were made, with the value those runs had
_DEFAULTS = {"actor_input": blind_approach.ActorInput().as_record(), "joint_calibration_rad": 0.0}


def build_env_config(
    preset: presets.TeacherPreset, num_envs: int, seed: int, nthread: int = 0, backend: str = "batch"
) -> GraspEnvConfig:
    dr = randomization.PAPER_DR if preset.external_force else randomization.EVAL_DR
    if preset.joint_calibration_rad:
        dr = dataclasses.replace(dr, joint_calibration_rad=preset.joint_calibration_rad)
    return GraspEnvConfig(
        num_envs=num_envs,
        seed=seed,
        reward=preset.reward,
        dr=dr,
        nthread=nthread,
        object_weights=preset.object_weights,
        backend=backend,
    )


@dataclass
class TrainTeacherConfig:
    """PPO teacher training (paper Sec. III-B, Table III)."""

    output_dir: Path | None = None  # run directory; re-running with the same one resumes
    # cpu_bc_capsule (the shipped teacher's staged recipe: cpu, then two cloning stages; cpu_bc_joint is its
    # first cloning stage), cpu_bc_blind_approach (beyond the paper: it, fine-tuned with the object hidden from
    # the actor until a touch), paper (Table III), cpu, quick
    preset: str = SHIPPED_TEACHER_PRESET.name
    seed: int = (
        spec.TEACHER_TRAIN_SEED
    )  # env i uses seed + i (inside spec.SEED_RANGES["teacher_train"]); torch seed
    iterations: int | None = None  # override the preset's max iterations
    num_envs: int | None = None  # override the preset's number of envs
    no_incentive: bool = False  # 'Student w/o r_i' teacher: every contact-paying reward term at 0
    student_obs: bool = False  # 'RL w/ o_t' baseline: actor and critic see only o_t
    threads: int = 0  # physics threads (0: all CPUs)
    torch_threads: int = 1  # torch intra-op threads while acting (the forward passes between physics steps)
    update_threads: int = 0  # torch intra-op threads for the PPO update (0: as many as the physics threads)
    export: bool = True  # TorchScript/ONNX export of the actor at the end
    backend: str = "batch"  # physics: batch (mujoco.batch, CPU) or warp (MuJoCo Warp; pip install .[gpu])
    # torch device for PPO; None: cuda:<LOCAL_RANK> if CUDA is there, else cpu. Under torchrun (WORLD_SIZE > 1)
    # rsl-rl's multi-GPU mode runs one process per device and num_envs is split over the processes.
    device: str | None = None

    def __post_init__(self):
        if self.output_dir is None:
            raise ValueError("--output_dir is required (the run directory; re-running with it resumes)")
        self.output_dir = Path(self.output_dir)
        presets.get_preset(self.preset)  # unknown preset: a clear error before anything heavy


def train(cfg: TrainTeacherConfig) -> Path:
    preset = presets.Variant(no_incentive=cfg.no_incentive, student_obs=cfg.student_obs).apply(
        presets.get_preset(cfg.preset)
    )
    num_envs = cfg.num_envs or preset.num_envs
    iterations = cfg.iterations or preset.max_iterations
    spec.check_seeds("teacher_train", cfg.seed, num_envs)
    out = cfg.output_dir
    if preset.continues and newest_loadable_checkpoint(out) is None:
        _train_previous_stage(cfg, *preset.continues)
    out.mkdir(parents=True, exist_ok=True)
    device = cfg.device or distributed.default_device()
    rank_envs, rank_seed = distributed.split_envs(num_envs, cfg.seed)  # (num_envs, seed) outside torchrun
    lead = distributed.world()[1] == 0  # only rank 0 writes files (rsl-rl already logs and saves on rank 0 only)
    torch.manual_seed(cfg.seed + distributed.world()[1])
    # While acting, torch runs small forward passes between physics steps: OpenMP threads that spin there while
    # MuJoCo's threads hold the cores made collection 2-3x slower on a busy 2-core machine, so acting keeps one.
    torch.set_num_threads(cfg.torch_threads)

    config = {
        "preset": preset.name,
        "variant": {"no_incentive": cfg.no_incentive, "student_obs": cfg.student_obs},
        "num_envs": num_envs,
        "backend": cfg.backend,
        "seed": cfg.seed,
        "iterations": iterations,
        "runner": preset.runner_cfg(),
        "reward": preset.reward.as_record(),
        "external_force": preset.external_force,
        "object_weights": preset.object_weights and list(preset.object_weights),
        "actor_input": preset.actor_input.as_record(),
        "joint_calibration_rad": preset.joint_calibration_rad,
        "deviations": list(preset.deviations),
        # Lets a loader refuse this checkpoint once spec.PRIVILEGED_LAYOUT changes.
        "observation_layout": observation_layout(),
        "command": " ".join([Path(sys.argv[0]).name, *sys.argv[1:]]),
    }
    cfg_path = out / CONFIG_NAME
    if cfg_path.exists():
        old = json.loads(cfg_path.read_text())
        for key in (
            "preset",
            "variant",
            "num_envs",
            "runner",
            "reward",
            "object_weights",
            "actor_input",
            "joint_calibration_rad",
        ):
            # runs made before a key existed had its default
            if old.get(key, _DEFAULTS.get(key)) != config[key]:
                raise SystemExit(f"{out} holds a run with a different {key!r}; use another --output_dir")
    elif lead:
        durable.atomic_write_json(cfg_path, config, indent=2)

    env = BatchedGraspEnv(build_env_config(preset, rank_envs, rank_seed, cfg.threads, cfg.backend))
    bar = tqdm(total=iterations, desc=f"teacher[{preset.name}]", unit="it", dynamic_ncols=True)
    steps_per_it = preset.runner["num_steps_per_env"]
    counter = {"steps": 0}

    def tick():
        counter["steps"] += 1
        if counter["steps"] % steps_per_it == 0:
            bar.update(1)

    reads_blind = blind_approach.reads_blind_group(preset.runner["obs_groups"])
    vec = RslRlGraspEnv(env, device=device, on_step=tick, blind_group=preset.actor_input if reads_blind else None)
    runner = distributed.runner_class(device)(vec, preset.runner_cfg(), log_dir=str(out), device=device)
    runner.alg.update = with_torch_threads(runner.alg.update, update_thread_count(cfg, env))
    runner.save = atomic_save(runner.save)
    ckpt = newest_loadable_checkpoint(out)
    done_its = 0
    if ckpt is not None:
        runner.load(str(ckpt))
        done_its = runner.current_learning_iteration + 1
        runner.current_learning_iteration = done_its
        if hasattr(runner.alg, "bc_iteration"):  # the scripted-demo cloning's decay continues where it stopped
            runner.alg.bc_iteration = done_its
        bar.update(done_its)
        log.info("resuming from %s (iteration %d)", ckpt, done_its)
    remaining = iterations - done_its
    console = open(out / ("train_console.log" if lead else f"train_console_rank{distributed.world()[1]}.log"), "a")
    t0 = time.time()
    interrupted = False
    try:
        # SIGTERM/SIGHUP (a job scheduler, a closed terminal) behave like Ctrl-C: save and exit.
        with interrupts_as_keyboard_interrupt(), contextlib.redirect_stdout(console):
            if remaining > 0:  # rsl-rl prints a table per iteration; it goes to the console log
                # Random episode lengths on resume too: otherwise every env restarts at step 0 and, for a few
                # iterations, all of them are in the same phase of the episode (dips in the training curve).
                runner.learn(remaining, init_at_random_ep_len=True)
    except KeyboardInterrupt:
        interrupted = True
        if lead:
            runner.save(str(out / f"model_{runner.current_learning_iteration}.pt"))
    finally:
        console.close()
        bar.close()
    wall = time.time() - t0
    # A resume that finds every iteration done runs none: its count is the checkpoint's, not one past it.
    completed = runner.current_learning_iteration + 1 if remaining > 0 else done_its
    its_run = completed - done_its
    final = latest_checkpoint(out)
    if not lead:
        return final
    if cfg.export:
        export(runner, out / "exported")
    write_learning_curve(out)
    summary = {
        "checkpoint": str(final),
        "iterations": completed,
        "interrupted": interrupted,
        "wall_clock_s_this_session": wall,
        "env_steps_this_session": its_run * steps_per_it * num_envs,
        "env_steps_per_s": its_run * steps_per_it * num_envs / max(wall, 1e-9),
        "physics_resets": env.physics_resets,
    }
    durable.atomic_write_json(out / "train_summary.json", summary, indent=2)  # last: marks the run finished
    print(json.dumps(summary, indent=2))
    if interrupted:
        print(f"interrupted: saved {final}; run the same command to resume", file=sys.stderr)
        raise SystemExit(130)
    return final


def atomic_save(save):
    """rsl-rl's `OnPolicyRunner.save(path, infos)` (a plain torch.save, in place) made atomic: it writes a temp file
    beside `path`, which is renamed over `path` once complete."""

    def save_atomically(path, infos=None):
        with durable.atomic_path(path) as tmp:
            save(str(tmp), infos)

    return save_atomically


def newest_loadable_checkpoint(run_dir: Path) -> Path | None:
    """The newest model_<it>.pt that torch can read. Newer ones that cannot be read are renamed `<name>.corrupt`
    (kept for inspection, out of the way of every later resume) with a warning; killed saves' temp files go.
    Under torchrun only rank 0 renames or deletes; the other ranks skip the same files."""
    lead = distributed.world()[1] == 0
    if lead:
        for stale in durable.remove_stale_temps(run_dir):
            log.info("removed %s, the temp file of a save that was killed", stale)
    ckpts = sorted(Path(run_dir).glob("model_*.pt"), key=lambda p: int(re.findall(r"\d+", p.stem)[-1]))
    for ckpt in reversed(ckpts):
        try:
            torch.load(ckpt, map_location="cpu", weights_only=False)
            return ckpt
        except Exception as e:  # noqa: BLE001  (truncated zip, bad pickle, I/O error: all mean "cannot resume here")
            why = f"{type(e).__name__}: {str(e).splitlines()[0][:200] if str(e) else ''}"
            if lead:
                aside = ckpt.with_name(ckpt.name + ".corrupt")
                os.replace(ckpt, aside)
                log.warning(
                    "checkpoint %s cannot be read (%s); set aside as %s, resuming from the one before",
                    ckpt,
                    why,
                    aside.name,
                )
    return None


def update_thread_count(cfg, env) -> int:
    """Torch threads for the PPO update: `cfg.update_threads`, else as many as the physics threads (the cores
    collection just used), else the acting count (MuJoCo Warp has no CPU physics threads: `nthread` 0)."""
    return cfg.update_threads or env.physics.nthread or cfg.torch_threads


def with_torch_threads(update, threads: int):
    """`update` run with `threads` torch intra-op threads, then back to the acting count. Collection and update
    alternate, so the update may use the cores the physics threads use while collecting: on an idle 2-core
    machine two threads make the `cpu` preset's update 1.8x faster (`blindgrasp-bench --bench.type=teacher`)."""

    def threaded(*args, **kwargs):
        acting = torch.get_num_threads()
        torch.set_num_threads(threads)
        try:
            return update(*args, **kwargs)
        finally:
            torch.set_num_threads(acting)

    return threaded


def _train_previous_stage(cfg: TrainTeacherConfig, name: str, iterations: int) -> None:
    """A staged preset starts from another preset's checkpoint (`TeacherPreset.continues`): train that one first,
    with the same seed, envs and variant, in <output_dir>/stages/<name> (which resumes like any run), then start
    this run from its last checkpoint."""
    final = train(
        dataclasses.replace(
            cfg, preset=name, iterations=iterations, export=False, output_dir=cfg.output_dir / "stages" / name
        )
    )
    if distributed.world()[1] == 0:  # under torchrun one rank copies; the others must not read a half-written file
        cfg.output_dir.mkdir(parents=True, exist_ok=True)
        with durable.atomic_path(cfg.output_dir / final.name) as tmp:  # a kill mid-copy leaves no half checkpoint
            shutil.copy2(final, tmp)
    if torch.distributed.is_initialized():
        # The next stage's runner keeps this process group (distributed.runner_class's gloo runner does not open a
        # second one). Closing and reopening it raced in CI. rsl-rl's own NCCL runner would try to open a second
        # one, so staged presets stay CPU recipes.
        torch.distributed.barrier()


def write_learning_curve(run_dir: Path) -> None:
    """learning_curve.png in the run directory, from its TensorBoard scalars."""
    from lerobot_blindgrasp.results.plots import plot_curves, teacher_curves

    curves = teacher_curves(run_dir)
    if curves:
        plot_curves(run_dir / "learning_curve.png", curves, f"Teacher PPO ({run_dir.name})")


def export(runner, path: Path) -> None:
    """TorchScript and ONNX of the actor's mean (the deterministic teacher), via rsl-rl's exporters."""
    # rsl-rl's exporters write in place; they write temp files here that are renamed once complete.
    with durable.atomic_path(path / "teacher.pt") as tmp:
        runner.export_policy_to_jit(str(path), tmp.name)
    try:
        with durable.atomic_path(path / "teacher.onnx") as tmp:
            runner.export_policy_to_onnx(str(path), tmp.name)
    except Exception as e:  # ONNX export depends on optional onnxscript versions; JIT is enough for us
        log.warning("ONNX export failed: %s", e)


def main(argv=None) -> None:
    sleeping_openmp_threads(restart=argv is None)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    logging.getLogger("blindgrasp").setLevel(logging.INFO)  # LeRobot's imports may have configured the root first
    train(parse_config(TrainTeacherConfig, argv))


if __name__ == "__main__":
    main()
