"""`blindgrasp-train-teacher`: PPO teacher training with rsl-rl's OnPolicyRunner.

    blindgrasp-train-teacher --output_dir=runs/teacher   # the shipped teacher's recipe, --preset=cpu_bc_capsule

Re-running resumes from the newest checkpoint that loads; checkpoints are atomic, Ctrl-C saves one, and
`train_summary.json`, written last, marks a finished run.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import logging
import shutil
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import torch
from tqdm import tqdm

from lerobot_blindgrasp import durable, presets, spec
from lerobot_blindgrasp.cli import interrupts_as_keyboard_interrupt, parse_config, sleeping_openmp_threads
from lerobot_blindgrasp.presets import SHIPPED_TEACHER_PRESET
from lerobot_blindgrasp.presets.teacher_configs import TeacherPreset, Variant
from lerobot_blindgrasp.rollout.envs import env_config
from lerobot_blindgrasp.sim import objects, randomization
from lerobot_blindgrasp.sim.batched_config import GraspEnvConfig
from lerobot_blindgrasp.sim.batched_env import BatchedGraspEnv
from lerobot_blindgrasp.teacher import blind_approach, distributed
from lerobot_blindgrasp.teacher.checkpoints import atomic_save, export_actor, newest_loadable_checkpoint
from lerobot_blindgrasp.teacher.policy import CONFIG_NAME, latest_checkpoint, observation_layout
from lerobot_blindgrasp.teacher.vecenv import RslRlGraspEnv

log = logging.getLogger("blindgrasp.teacher")
# teacher_config.json keys that must match for a run to resume: they decide what is trained
RESUME_KEYS = (
    "preset",
    "variant",
    "num_envs",
    "runner",
    "reward",
    "object_weights",
    "actor_input",
    "joint_calibration_rad",
)


def build_env_config(
    preset: TeacherPreset, num_envs: int, seed: int, nthread: int = 0, backend: str = "batch"
) -> GraspEnvConfig:
    dr = randomization.PAPER_DR if preset.external_force else randomization.EVAL_DR
    dr = dataclasses.replace(dr, joint_calibration_rad=preset.joint_calibration_rad)
    return env_config(
        "train",
        objects.PAPER_OBJECTS,
        num_envs=num_envs,
        seed=seed,
        dr=dr,
        reward=preset.reward,
        nthread=nthread,
        object_weights=preset.object_weights,
        backend=backend,
    )


@dataclass
class TrainTeacherConfig:
    """PPO teacher training (paper Sec. III-B, Table III)."""

    output_dir: Path | None = None  # run directory; re-running with the same one resumes
    # a teacher preset (docs/reference.md lists them); default: the shipped teacher's staged recipe
    preset: str = SHIPPED_TEACHER_PRESET.name
    # env i uses seed + i (inside spec.SEED_RANGES["teacher_train"]); the torch seed
    seed: int = spec.TEACHER_TRAIN_SEED
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
        presets.get(self.preset, "teacher")  # unknown preset: a clear error before anything heavy


def train(cfg: TrainTeacherConfig) -> Path:
    """Train the preset (first the stages of a staged one) in cfg.output_dir; returns the last checkpoint."""
    preset = Variant(no_incentive=cfg.no_incentive, student_obs=cfg.student_obs).apply(
        presets.get(cfg.preset, "teacher")
    )
    num_envs = cfg.num_envs or preset.num_envs
    if preset.stages and newest_loadable_checkpoint(cfg.output_dir) is None:
        _train_stages(cfg, preset.stages)
    return _train_one(cfg, preset, num_envs, cfg.iterations or preset.max_iterations)


def _train_one(cfg: TrainTeacherConfig, preset: TeacherPreset, num_envs: int, iterations: int) -> Path:
    spec.check_seeds("teacher_train", cfg.seed, num_envs)
    out = cfg.output_dir
    out.mkdir(parents=True, exist_ok=True)
    device = cfg.device or distributed.default_torch_device()
    rank_envs, rank_seed = distributed.split_envs(num_envs, cfg.seed)  # (num_envs, seed) outside torchrun
    lead = distributed.world()[1] == 0  # only rank 0 writes files (rsl-rl already logs and saves on rank 0 only)
    torch.manual_seed(cfg.seed + distributed.world()[1])
    # One thread while acting: OpenMP threads spinning beside MuJoCo's made collection 2-3x slower on 2 cores.
    torch.set_num_threads(cfg.torch_threads)
    _check_or_write_config(out, _run_config(cfg, preset, num_envs, iterations), lead)
    env = BatchedGraspEnv(build_env_config(preset, rank_envs, rank_seed, cfg.threads, cfg.backend))
    bar = tqdm(total=iterations, desc=f"teacher[{preset.name}]", unit="it", dynamic_ncols=True)
    runner, done_its = _runner(cfg, preset, env, device, bar)
    remaining = iterations - done_its
    t0 = time.time()
    interrupted = _learn(runner, out, remaining, lead, bar)
    wall = time.time() - t0
    # A resume that finds every iteration done runs none: its count is the checkpoint's, not one past it.
    completed = runner.current_learning_iteration + 1 if remaining > 0 else done_its
    final = latest_checkpoint(out)
    if not lead:
        return final
    if cfg.export:
        export_actor(runner, out / "exported")
    from lerobot_blindgrasp.results.plots import plot_curves, teacher_curves

    if curves := teacher_curves(out):  # from the run's TensorBoard scalars
        plot_curves(out / "learning_curve.png", curves, f"Teacher PPO ({out.name})")
    steps = (completed - done_its) * preset.runner["num_steps_per_env"] * num_envs
    summary = {
        "checkpoint": str(final),
        "iterations": completed,
        "interrupted": interrupted,
        "wall_clock_s_this_session": wall,
        "env_steps_this_session": steps,
        "env_steps_per_s": steps / max(wall, 1e-9),
        "physics_resets": env.physics_resets,
    }
    durable.atomic_write_json(out / "train_summary.json", summary, indent=2)  # last: marks the run finished
    print(json.dumps(summary, indent=2))
    if interrupted:
        print(f"interrupted: saved {final}; run the same command to resume", file=sys.stderr)
        raise SystemExit(130)
    return final


def _run_config(cfg: TrainTeacherConfig, preset: TeacherPreset, num_envs: int, iterations: int) -> dict:
    """What teacher_config.json records of a run: every setting that decides it, and the command."""
    return {
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


def _check_or_write_config(out: Path, config: dict, lead: bool) -> None:
    """A new run records its config; a resumed one must have been started with the same RESUME_KEYS."""
    cfg_path = out / CONFIG_NAME
    if cfg_path.exists():
        old = json.loads(cfg_path.read_text())
        for key in RESUME_KEYS:
            if old.get(key) != config[key]:
                raise SystemExit(f"{out} holds a run with a different {key!r}; use another --output_dir")
    elif lead:
        durable.atomic_write_json(cfg_path, config, indent=2)


def _runner(cfg: TrainTeacherConfig, preset: TeacherPreset, env: BatchedGraspEnv, device: str, bar):
    """rsl-rl's runner on the env, resumed from the newest loadable checkpoint. Returns (runner, iterations done)."""
    steps_per_it = preset.runner["num_steps_per_env"]
    counter = {"steps": 0}

    def tick():
        counter["steps"] += 1
        if counter["steps"] % steps_per_it == 0:
            bar.update(1)

    reads_blind = blind_approach.reads_blind_group(preset.runner["obs_groups"])
    vec = RslRlGraspEnv(env, device=device, on_step=tick, blind_group=preset.actor_input if reads_blind else None)
    runner = distributed.runner_class(device)(vec, preset.runner_cfg(), log_dir=str(cfg.output_dir), device=device)
    runner.alg.update = with_torch_threads(runner.alg.update, update_thread_count(cfg, env))
    critic_beside_actor(runner.alg, device)
    runner.save = atomic_save(runner.save)
    ckpt = newest_loadable_checkpoint(cfg.output_dir)
    if ckpt is None:
        return runner, 0
    runner.load(str(ckpt))
    done_its = runner.current_learning_iteration + 1
    runner.current_learning_iteration = done_its
    if hasattr(runner.alg, "bc_iteration"):  # the scripted-demo cloning's decay continues where it stopped
        runner.alg.bc_iteration = done_its
    bar.update(done_its)
    log.info("resuming from %s (iteration %d)", ckpt, done_its)
    return runner, done_its


def _learn(runner, out: Path, remaining: int, lead: bool, bar) -> bool:
    """`remaining` PPO iterations, rsl-rl's table going to the console log. Returns whether it was interrupted
    (SIGINT, SIGTERM, SIGHUP: a checkpoint is saved first)."""
    console = open(out / ("train_console.log" if lead else f"train_console_rank{distributed.world()[1]}.log"), "a")
    try:
        with interrupts_as_keyboard_interrupt(), contextlib.redirect_stdout(console):
            if remaining > 0:
                # Random episode lengths, on resume too: envs all in one phase of the episode dip the curve.
                runner.learn(remaining, init_at_random_ep_len=True)
    except KeyboardInterrupt:
        if lead:
            runner.save(str(out / f"model_{runner.current_learning_iteration}.pt"))
        return True
    finally:
        console.close()
        bar.close()
    return False


def update_thread_count(cfg, env) -> int:
    """Torch threads for the PPO update: `cfg.update_threads`, else the physics threads (the cores collection just
    used), else the acting count (MuJoCo Warp has no CPU physics threads)."""
    return cfg.update_threads or env.physics.nthread or cfg.torch_threads


def with_torch_threads(update, threads: int):
    """`update` run with `threads` torch threads, then back to the acting count: collection and update alternate, so
    the update may use the physics threads' cores."""

    def threaded(*args, **kwargs):
        acting = torch.get_num_threads()
        torch.set_num_threads(threads)
        try:
            return update(*args, **kwargs)
        finally:
            torch.set_num_threads(acting)

    return threaded


def critic_beside_actor(alg, device: str) -> None:
    """On a CPU, `alg.act` runs the critic's forward in a second thread beside the actor's. Between physics steps the
    physics threads' cores are idle, and the two MLPs are the acting step's largest cost. Each op runs with the
    torch thread count it would run with alone, and the critic draws no random numbers, so the actions and values are
    bit-identical to rsl-rl's own `act`. Its result reaches rsl-rl's `act` through `_CriticAhead`."""
    if torch.device(device).type != "cpu":
        return
    pool = ThreadPoolExecutor(1, thread_name_prefix="critic")
    act = alg.act

    def forward(critic, obs, inference: bool, grad: bool):
        # grad and inference mode are per thread: the caller's (rsl-rl acts under inference mode)
        with torch.inference_mode(inference), torch.set_grad_enabled(grad):
            return critic(obs)

    def act_beside(obs):
        critic = alg.critic
        future = pool.submit(forward, critic, obs, torch.is_inference_mode_enabled(), torch.is_grad_enabled())
        alg.critic = _CriticAhead(critic, future)
        try:
            return act(obs)
        finally:
            alg.critic = critic
            future.exception()  # the helper is done with `obs` before the caller goes on

    alg.act = act_beside


class _CriticAhead:
    """The critic while `critic_beside_actor`'s thread computes its forward: calling it returns that result; all else
    is the critic's."""

    def __init__(self, critic, future):
        self._critic, self._future = critic, future

    def __call__(self, obs):
        return self._future.result()

    def __getattr__(self, name):
        return getattr(self._critic, name)


def _train_stages(cfg: TrainTeacherConfig, stages: tuple[tuple[str, int], ...]) -> None:
    """Train each stage of a staged preset in order (same seed, envs and variant) in <output_dir>/stages/<name>, each
    from the previous one's last checkpoint; this run then starts from the last one's."""
    previous = None
    for name, iterations in stages:
        folder = cfg.output_dir / "stages" / name
        if previous is not None and newest_loadable_checkpoint(folder) is None:
            _copy_checkpoint(previous, folder)
        stage = dataclasses.replace(cfg, preset=name, iterations=iterations, export=False, output_dir=folder)
        preset = Variant(no_incentive=cfg.no_incentive, student_obs=cfg.student_obs).apply(
            presets.get(name, "teacher")
        )
        previous = _train_one(stage, preset, cfg.num_envs or preset.num_envs, iterations)
    _copy_checkpoint(previous, cfg.output_dir)


def _copy_checkpoint(ckpt: Path, folder: Path) -> None:
    """`ckpt` into `folder`, atomically, by one rank: the next stage resumes from it."""
    if distributed.world()[1] == 0:
        folder.mkdir(parents=True, exist_ok=True)
        with durable.atomic_path(folder / ckpt.name) as tmp:
            shutil.copy2(ckpt, tmp)
    if torch.distributed.is_initialized():
        # The next stage's gloo runner keeps this process group (reopening it raced in CI); rsl-rl's NCCL runner
        # would open a second one, so staged presets stay CPU recipes.
        torch.distributed.barrier()


def main(argv=None) -> None:
    sleeping_openmp_threads(restart=argv is None)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    logging.getLogger("blindgrasp").setLevel(logging.INFO)  # LeRobot's imports may have configured the root first
    train(parse_config(TrainTeacherConfig, argv))


if __name__ == "__main__":
    main()
