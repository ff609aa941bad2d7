"""Whole-loop PPO throughput: collection vs update time per iteration, against raw physics at the same env count.

    blindgrasp-bench --bench.type=teacher --bench.preset=cpu --bench.iterations=6 --bench.json=true
    blindgrasp-bench --bench.type=teacher --bench.preset=cpu --bench.checkpoint=runs/teacher_cpu/model_1397.pt

Builds the preset's env and rsl-rl `OnPolicyRunner` exactly as `blindgrasp-train-teacher` does (no logging to
disk), runs a warm-up iteration and then `--iterations` timed ones. Per iteration it splits wall time into
collection (env steps + the actor/critic forward passes rsl-rl does while acting) and update (`PPO.update`).
In the same process it times raw physics (`Batch.step` with the same per-env models, substeps and threads, no
observation, reward or policy work) for as many control steps, so the ratio whole-loop / raw says how much of the
machine the learner leaves to physics. Measured in one run because the machine may be shared.

Overrides (`--bench.hidden_dims`, `--bench.mini_batches`, `--bench.epochs`, `--bench.torch_threads`,
`--bench.update_threads`, `--bench.num_envs`) let levers be compared side by side without editing a preset.
`--bench.profile_update=true` adds one more iteration whose PPO update runs under cProfile, split into rsl-rl's parts
(forward, backward, optimizer step, clipping, minibatch generator).
"""

from __future__ import annotations

import contextlib
import resource
import sys
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import torch

from lerobot_blindgrasp.bench import BenchConfig
from lerobot_blindgrasp.presets import teacher as presets


@BenchConfig.register_subclass("teacher")
@dataclass
class BenchTeacherConfig(BenchConfig):
    """Whole-loop PPO throughput: collection vs update time per iteration, against raw physics."""

    preset: str = "cpu"  # teacher preset
    iterations: int = 5  # timed PPO iterations (after one warm-up)
    num_envs: int | None = None  # default: the preset's
    threads: int = 0  # physics threads (0: all CPUs)
    torch_threads: int = 1  # torch threads while acting (as blindgrasp-train-teacher)
    update_threads: int = 0  # torch threads for the PPO update (0: as many as the physics threads, as training)
    hidden_dims: list[int] | None = None  # actor and critic MLP widths, e.g. [256,128] (default: the preset's)
    mini_batches: int | None = None  # PPO minibatches (default: the preset's)
    epochs: int | None = None  # PPO epochs (default: the preset's)
    backend: str = "batch"  # physics backend: batch or warp
    # A training checkpoint (model_<it>.pt) of this preset to time instead of an untrained policy: a policy that
    # grasps keeps its fingers in contact, which makes physics dearer, so collection takes longer than at iteration 0.
    checkpoint: Path | None = None
    # After the timed iterations, one more whose PPO update runs under cProfile: its time split into rsl-rl's parts.
    profile_update: bool = False

    def __post_init__(self):
        presets.get_preset(self.preset)  # unknown preset: a clear error before anything heavy
        if self.backend not in ("batch", "warp"):
            raise ValueError(f"--bench.backend must be batch or warp, got {self.backend!r}")
        if self.checkpoint is not None:
            self.checkpoint = Path(self.checkpoint)
            if not self.checkpoint.is_file():
                raise FileNotFoundError(f"--checkpoint: no file at {self.checkpoint}")
            if self.hidden_dims:
                raise ValueError("--checkpoint fixes the MLP widths: drop --hidden_dims")


def _preset(cfg: BenchTeacherConfig) -> presets.TeacherPreset:
    preset = presets.get_preset(cfg.preset)
    runner = preset.runner_cfg()
    if cfg.hidden_dims:
        runner["actor"]["hidden_dims"] = list(cfg.hidden_dims)
        runner["critic"]["hidden_dims"] = list(cfg.hidden_dims)
    if cfg.mini_batches:
        runner["algorithm"]["num_mini_batches"] = cfg.mini_batches
    if cfg.epochs:
        runner["algorithm"]["num_learning_epochs"] = cfg.epochs
    return replace(preset, runner=runner)


def _raw_control_steps_per_s(env, steps: int) -> float:
    """Raw stepping of the env's backend (`Batch.step`, or Warp's `step` per model) from its current state,
    replaying the env's own last targets."""
    saved = env.physics.snapshot()
    ctrl = env.physics.ctrl
    target = ctrl.copy()
    t = time.perf_counter()
    for _ in range(steps):
        ctrl[:] = target
        env.physics.raw_step(env.cfg.physics.substeps)
    wall = time.perf_counter() - t
    env.physics.restore(saved)
    return steps * env.num_envs / wall


def run(cfg: BenchTeacherConfig) -> dict:
    from rsl_rl.runners import OnPolicyRunner

    from lerobot_blindgrasp.sim.batched_env import BatchedGraspEnv
    from lerobot_blindgrasp.teacher.train import build_env_config, update_thread_count, with_torch_threads
    from lerobot_blindgrasp.teacher.vecenv import RslRlGraspEnv

    preset = _preset(cfg)
    num_envs = cfg.num_envs or preset.num_envs
    torch.set_num_threads(cfg.torch_threads)
    env = BatchedGraspEnv(build_env_config(preset, num_envs, seed=1, nthread=cfg.threads, backend=cfg.backend))
    device = "cpu"
    if cfg.backend == "warp":
        from lerobot_blindgrasp.teacher.distributed import default_device

        device = default_device()  # the GPU if there is one: sim and learner on the same device
    vec = RslRlGraspEnv(env, device=device)
    runner_cfg = preset.runner_cfg()
    steps_per_it = runner_cfg["num_steps_per_env"]
    # rsl-rl prints the models on construction; with --json=true stdout must hold only the JSON.
    with contextlib.redirect_stdout(sys.stderr):
        runner = OnPolicyRunner(vec, runner_cfg, log_dir=None, device=device)  # no log dir: nothing written
    if cfg.checkpoint is not None:
        try:
            runner.load(str(cfg.checkpoint))
        except (RuntimeError, KeyError) as e:  # state-dict shapes or keys of another preset
            raise SystemExit(f"{cfg.checkpoint} is not a checkpoint of preset {preset.name!r}: {e}") from None
    update_times: list[float] = []
    update_cpu: list[float] = []  # process CPU seconds (all threads) spent inside the updates
    update_threads = update_thread_count(cfg, env)
    inner_update = with_torch_threads(runner.alg.update, update_threads)

    def timed_update():
        t, c = time.perf_counter(), time.process_time()
        out = inner_update()
        update_times.append(time.perf_counter() - t)
        update_cpu.append(time.process_time() - c)
        return out

    runner.alg.update = timed_update
    runner.learn(1, init_at_random_ep_len=True)  # warm-up: allocations, first normalizer stats
    update_times.clear()
    update_cpu.clear()
    t, c = time.perf_counter(), time.process_time()
    runner.learn(cfg.iterations)
    wall = time.perf_counter() - t
    cpu = time.process_time() - c
    profiled: dict = {}
    if cfg.profile_update:  # after the timing, so cProfile's overhead is in none of the figures above
        runner.alg.update = _profiled(inner_update, profiled)
        runner.learn(1)
    update = float(np.sum(update_times))
    collect = wall - update
    raw = _raw_control_steps_per_s(env, steps_per_it * 2)
    env_steps = cfg.iterations * steps_per_it * num_envs
    loop = env_steps / wall
    result = {
        "preset": preset.name,
        "num_envs": num_envs,
        "backend": cfg.backend,
        "device": device,
        "physics_threads": env.physics.nthread,
        "torch_threads": cfg.torch_threads,
        "update_threads": update_threads,
        "hidden_dims": runner_cfg["actor"]["hidden_dims"],
        "mini_batches": runner_cfg["algorithm"]["num_mini_batches"],
        "epochs": runner_cfg["algorithm"]["num_learning_epochs"],
        "iterations": cfg.iterations,
        "checkpoint": str(cfg.checkpoint) if cfg.checkpoint else None,
        "collect_s_per_it": collect / cfg.iterations,
        "update_s_per_it": update / cfg.iterations,
        "update_over_collect": update / collect,
        # Cores kept busy in each phase (process CPU time / wall time): what is left for overlapping the two.
        "collect_cores_busy": (cpu - float(np.sum(update_cpu))) / collect,
        "update_cores_busy": float(np.sum(update_cpu)) / update,
        "loop_env_steps_per_s": loop,
        "raw_control_steps_per_s": raw,
        "loop_over_raw": loop / raw,
        # Peak resident memory of this process (env models + rollout storage + nets), for sizing bigger runs.
        "max_rss_gb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20,
    }
    if profiled:
        result["update_parts"] = profiled
    if not cfg.json:
        print(
            f"blindgrasp-bench teacher: preset {preset.name}, {num_envs} envs, {cfg.backend} backend on {device}, "
            f"{env.physics.nthread} physics threads, "
            f"torch threads {cfg.torch_threads} acting / {update_threads} updating, MLP {result['hidden_dims']}, "
            f"{result['epochs']} epochs x {result['mini_batches']} minibatches"
        )
        print(
            "| collect s/it | update s/it | update / collect | loop steps/s | raw ctrl steps/s | loop / raw "
            "| cores busy collect / update | peak RSS GB |"
        )
        print("|---:|---:|---:|---:|---:|---:|---:|---:|")
        print(
            f"| {result['collect_s_per_it']:.2f} | {result['update_s_per_it']:.2f} | "
            f"{result['update_over_collect']:.2f} | {loop:,.0f} | {raw:,.0f} | {result['loop_over_raw']:.2f} "
            f"| {result['collect_cores_busy']:.1f} / {result['update_cores_busy']:.1f} | {result['max_rss_gb']:.2f} |"
        )
        if profiled:
            print(
                "PPO update (cProfile, one iteration): "
                + ", ".join(f"{k} {v:.0%}" for k, v in profiled.items() if k != "total_s")
                + f" of {profiled['total_s']:.2f} s"
            )
    return result


# rsl-rl's PPO.update by part: (file path fragment, function name) whose cumulative time is that part's. Nested
# matches (decorator wrappers around the same call) count once: the largest.
UPDATE_PARTS = {
    "forward": ("torch/nn/modules/module.py", "_wrapped_call_impl"),  # actor + critic (and normalizer) forward
    "backward": ("torch/autograd/__init__.py", "backward"),
    "optimizer_step": ("torch/optim/", "step"),
    "clip_grad_norm": ("torch/nn/utils/clip_grad.py", "clip_grad_norm_"),
    "minibatch_generator": ("rsl_rl/storage/", "mini_batch_generator"),
    "log_prob_entropy_kl": ("rsl_rl/", "get_kl_divergence"),
}


def _profiled(update, into: dict):
    """`update` run under cProfile; its parts' shares of the update's time go into `into`."""
    import cProfile
    import pstats

    def wrapper():
        prof = cProfile.Profile()
        t = time.perf_counter()
        out = prof.runcall(update)
        total = time.perf_counter() - t
        stats = pstats.Stats(prof).stats  # (file, line, name) -> (calls, primitive calls, tottime, cumtime, ...)
        for part, (where, name) in UPDATE_PARTS.items():
            times = [v[3] for (f, _, n), v in stats.items() if n == name and where in f.replace("\\", "/")]
            into[part] = max(times, default=0.0) / total
        into["rest"] = max(0.0, 1 - sum(into[p] for p in UPDATE_PARTS))
        into["total_s"] = total
        return out

    return wrapper
