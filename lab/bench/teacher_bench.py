"""Whole-loop PPO throughput: collection vs update time per iteration, against raw physics at the same env count.

    python -m lab.bench --bench.type=teacher --bench.preset=cpu --bench.iterations=6 --bench.json=true
    python -m lab.bench --bench.type=teacher --bench.preset=cpu --bench.checkpoint=runs/teacher_cpu/model_1397.pt

Builds the preset's env and rsl-rl `OnPolicyRunner` exactly as `blindgrasp-train-teacher` does (no logging to
disk), runs a warm-up iteration and then `--iterations` timed ones. Per iteration it splits wall time into
collection (env steps + the actor/critic forward passes rsl-rl does while acting) and update (`PPO.update`).
Each physics call of the collection is replayed right after it as raw physics (`Batch.step` with the same per-env
models, substeps, threads, state and joint targets, no observation, reward or policy work; `sim_bench.ReplayedPhysics`),
so collection and the same physics see the same load on a shared machine: whole-loop / raw says how much of the
machine the learner leaves to physics, and collection / raw what the env and the acting forward cost.

Overrides (`--bench.hidden_dims`, `--bench.mini_batches`, `--bench.epochs`, `--bench.torch_threads`,
`--bench.update_threads`, `--bench.num_envs`) set the timed loop. `--bench.update_variants=[5x4@1,5x4@2,5x2@2]`
re-runs the PPO update on the last rollout under each EPOCHSxMINIBATCHES@THREADS, interleaved, from the same weights:
the levers on the update, compared within one run.
`--bench.profile_update=true` adds one more iteration whose PPO update runs under cProfile, split into rsl-rl's parts
(forward, backward, optimizer step, clipping, minibatch generator).
"""

from __future__ import annotations

import contextlib
import copy
import os
import re
import resource
import sys
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import torch

from lab.bench import BenchConfig, sim_bench
from lerobot_blindgrasp import presets
from lerobot_blindgrasp.presets.teacher_configs import TeacherPreset


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
    # PPO updates re-run on the last rollout, side by side: EPOCHSxMINIBATCHES@THREADS each, e.g. ["5x4@1","5x4@2"]
    update_variants: list[str] = field(default_factory=list)
    variant_rounds: int = 2  # interleaved rounds of the variants (the fastest of each is kept)

    def __post_init__(self):
        presets.get(self.preset, "teacher")  # unknown preset: a clear error before anything heavy
        if self.backend not in ("batch", "warp"):
            raise ValueError(f"--bench.backend must be batch or warp, got {self.backend!r}")
        if self.checkpoint is not None:
            self.checkpoint = Path(self.checkpoint)
            if not self.checkpoint.is_file():
                raise FileNotFoundError(f"--checkpoint: no file at {self.checkpoint}")
            if self.hidden_dims:
                raise ValueError("--checkpoint fixes the MLP widths: drop --hidden_dims")
        for text in self.update_variants:
            parse_variant(text)


def _preset(cfg: BenchTeacherConfig) -> TeacherPreset:
    preset = presets.get(cfg.preset, "teacher")
    runner = preset.runner_cfg()
    if cfg.hidden_dims:
        runner["actor"]["hidden_dims"] = list(cfg.hidden_dims)
        runner["critic"]["hidden_dims"] = list(cfg.hidden_dims)
    if cfg.mini_batches:
        runner["algorithm"]["num_mini_batches"] = cfg.mini_batches
    if cfg.epochs:
        runner["algorithm"]["num_learning_epochs"] = cfg.epochs
    return replace(preset, runner=runner)


def _build(cfg: BenchTeacherConfig):
    """The preset's env, rsl-rl runner and device, as blindgrasp-train-teacher builds them (no log dir)."""
    from rsl_rl.runners import OnPolicyRunner

    from lerobot_blindgrasp.sim.batched_env import BatchedGraspEnv
    from lerobot_blindgrasp.teacher.train import build_env_config, critic_beside_actor
    from lerobot_blindgrasp.teacher.vecenv import RslRlGraspEnv

    preset = _preset(cfg)
    num_envs = cfg.num_envs or preset.num_envs
    torch.set_num_threads(cfg.torch_threads)
    env = BatchedGraspEnv(build_env_config(preset, num_envs, seed=1, nthread=cfg.threads, backend=cfg.backend))
    device = "cpu"
    if cfg.backend == "warp":
        from lerobot_blindgrasp.teacher.distributed import default_torch_device

        device = default_torch_device()  # the GPU if there is one: sim and learner on the same device
    vec = RslRlGraspEnv(env, device=device)
    # rsl-rl prints the models on construction; with --json=true stdout must hold only the JSON.
    with contextlib.redirect_stdout(sys.stderr):  # no log dir: nothing written
        runner = OnPolicyRunner(vec, preset.runner_cfg(), log_dir=None, device=device)
    if cfg.checkpoint is not None:
        try:
            runner.load(str(cfg.checkpoint))
        except (RuntimeError, KeyError) as e:  # state-dict shapes or keys of another preset
            raise SystemExit(f"{cfg.checkpoint} is not a checkpoint of preset {preset.name!r}: {e}") from None
    critic_beside_actor(runner.alg, device)
    return preset, env, runner, device


def _timed_iterations(runner, env, update, iterations: int) -> list[dict]:
    """Per PPO iteration (rsl-rl's own `learn`): wall and process CPU seconds of collection and of the update, and
    raw physics replaying each physics call of the collection from the same state right after it
    (`sim_bench.ReplayedPhysics`), so that the two see the same load on a shared machine and do the same physics, resets
    included. The replays' wall and CPU time are taken out of the collection's."""
    spent: dict[str, float] = {}

    def timed_update():
        t, c = time.perf_counter(), time.process_time()
        out = update()
        spent.update(update=time.perf_counter() - t, update_cpu=time.process_time() - c)
        return out

    runner.alg.update = timed_update
    env_steps = runner.cfg["num_steps_per_env"] * env.num_envs
    rows = []
    for _ in range(iterations):
        with sim_bench.ReplayedPhysics(env.physics) as replay:
            t, c = time.perf_counter(), time.process_time()
            runner.learn(1)
            wall, cpu = time.perf_counter() - t, time.process_time() - c
        collect = wall - spent["update"] - replay.extra_s
        rows.append(
            {
                "collect_s": collect,
                "update_s": spent["update"],
                "collect_cpu_s": cpu - spent["update_cpu"] - replay.extra_cpu_s,
                "update_cpu_s": spent["update_cpu"],
                "collect_env_steps_per_s": env_steps / collect,
                "raw_control_steps_per_s": env_steps / replay.raw_s,
                "collect_over_raw": replay.raw_s / collect,
            }
        )
    return rows


def _summary(cfg: BenchTeacherConfig, preset, env, rows: list[dict], device: str, update_threads: int) -> dict:
    runner_cfg = preset.runner_cfg()
    total = {
        k: float(np.sum([r[k] for r in rows])) for k in ("collect_s", "update_s", "collect_cpu_s", "update_cpu_s")
    }
    steps_per_it = runner_cfg["num_steps_per_env"]
    env_steps = len(rows) * steps_per_it * env.num_envs
    loop = env_steps / (total["collect_s"] + total["update_s"])
    # Raw physics over the same iterations, as a rate: control steps over the summed raw time.
    raw = env_steps / float(np.sum([steps_per_it * env.num_envs / r["raw_control_steps_per_s"] for r in rows]))
    collect = env_steps / total["collect_s"]
    return {
        "preset": preset.name,
        "num_envs": env.num_envs,
        "backend": cfg.backend,
        "device": _device_name(device),
        "physics_threads": env.physics.nthread,
        "torch_threads": cfg.torch_threads,
        "update_threads": update_threads,
        "hidden_dims": runner_cfg["actor"]["hidden_dims"],
        "mini_batches": runner_cfg["algorithm"]["num_mini_batches"],
        "epochs": runner_cfg["algorithm"]["num_learning_epochs"],
        "iterations": len(rows),
        "checkpoint": str(cfg.checkpoint) if cfg.checkpoint else None,
        "collect_s_per_it": total["collect_s"] / len(rows),
        "update_s_per_it": total["update_s"] / len(rows),
        "update_over_collect": total["update_s"] / total["collect_s"],
        # Cores kept busy in each phase (process CPU time / wall time): what is left for overlapping the two.
        "collect_cores_busy": total["collect_cpu_s"] / total["collect_s"],
        "update_cores_busy": total["update_cpu_s"] / total["update_s"],
        "loop_env_steps_per_s": loop,
        "collect_env_steps_per_s": collect,
        "raw_control_steps_per_s": raw,
        "loop_over_raw": loop / raw,
        "collect_over_raw": collect / raw,
        # What collection adds to the physics per control step (all envs): the ratio above also moves with the
        # physics' own speed, which on a shared machine is the other processes' load; this moves far less.
        "overhead_ms_per_step": 1e3 * (total["collect_s"] - env_steps / raw) / (len(rows) * steps_per_it),
        "per_iteration": rows,
        # Peak resident memory of this process (env models + rollout storage + nets), for sizing bigger runs.
        "max_rss_gb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20,
    }


def _device_name(device: str) -> str:
    return torch.cuda.get_device_name(torch.device(device)) if device != "cpu" else f"cpu ({os.cpu_count()} cores)"


def run(cfg: BenchTeacherConfig) -> dict:
    from lerobot_blindgrasp.teacher.train import update_thread_count, with_torch_threads

    preset, env, runner, device = _build(cfg)
    threads = update_thread_count(cfg, env)
    update = with_torch_threads(runner.alg.update, threads)
    runner.alg.update = update
    runner.learn(1, init_at_random_ep_len=True)  # warm-up: allocations, first normalizer stats
    rows = _timed_iterations(runner, env, update, cfg.iterations)
    result = _summary(cfg, preset, env, rows, device, threads)
    if cfg.update_variants:  # on the last rollout, after the timing
        result["update_variants"] = update_variants(runner.alg, cfg.update_variants, cfg.variant_rounds)
    if cfg.profile_update:  # last, so cProfile's overhead is in none of the figures above
        profiled: dict = {}
        runner.alg.update = _profiled(update, profiled)
        runner.learn(1)
        result["update_parts"] = profiled
    if not cfg.json:
        _print_table(result)
    return result


def _print_table(result: dict) -> None:
    print(
        f"blindgrasp-bench teacher: preset {result['preset']}, {result['num_envs']} envs, {result['backend']} "
        f"backend on {result['device']}, {result['physics_threads']} physics threads, torch threads "
        f"{result['torch_threads']} acting / {result['update_threads']} updating, MLP {result['hidden_dims']}, "
        f"{result['epochs']} epochs x {result['mini_batches']} minibatches"
    )
    print(
        "| collect s/it | update s/it | update / collect | loop steps/s | collect steps/s | raw ctrl steps/s "
        "| loop / raw | collect / raw | cores busy collect / update | peak RSS GB |"
    )
    print("|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    r = result
    print(
        f"| {r['collect_s_per_it']:.2f} | {r['update_s_per_it']:.2f} | {r['update_over_collect']:.2f} "
        f"| {r['loop_env_steps_per_s']:,.0f} | {r['collect_env_steps_per_s']:,.0f} "
        f"| {r['raw_control_steps_per_s']:,.0f} | {r['loop_over_raw']:.2f} | {r['collect_over_raw']:.2f} "
        f"| {r['collect_cores_busy']:.1f} / {r['update_cores_busy']:.1f} | {r['max_rss_gb']:.2f} |"
    )
    for v in r.get("update_variants", []):
        print(f"PPO update {v['variant']}: {v['update_s']:.2f} s ({v['over_first']:.2f} x the first)")
    if "update_parts" in r:
        parts = r["update_parts"]
        print(
            "PPO update (cProfile, one iteration): "
            + ", ".join(f"{k} {v:.0%}" for k, v in parts.items() if k != "total_s")
            + f" of {parts['total_s']:.2f} s"
        )


def parse_variant(text: str) -> tuple[int, int, int]:
    """'EPOCHSxMINIBATCHES@THREADS' (e.g. '5x4@2') -> (epochs, mini_batches, threads)."""
    m = re.fullmatch(r"(\d+)x(\d+)@(\d+)", text.strip())
    if not m or min(int(g) for g in m.groups()) < 1:
        raise ValueError(
            f"an update variant is EPOCHSxMINIBATCHES@THREADS with each >= 1, e.g. 5x4@2; got {text!r}"
        )
    return int(m[1]), int(m[2]), int(m[3])


def update_variants(alg, variants: list[str], rounds: int) -> list[dict]:
    """The PPO update re-run on the same last rollout under each variant (epochs, minibatches, torch threads),
    interleaved round by round; each from the same weights and optimizer state (restored after each run). Per
    variant: the fastest of `rounds` runs."""
    saved = copy.deepcopy(alg.save())
    base = (alg.num_learning_epochs, alg.num_mini_batches)
    acting = torch.get_num_threads()
    best = [float("inf")] * len(variants)
    for _ in range(rounds):
        for k, text in enumerate(variants):
            alg.num_learning_epochs, alg.num_mini_batches, threads = parse_variant(text)
            torch.set_num_threads(threads)
            t = time.perf_counter()
            alg.update()  # rsl-rl's update leaves the rollout's tensors in place (clear() only rewinds)
            best[k] = min(best[k], time.perf_counter() - t)
            alg.load(copy.deepcopy(saved), None, True)
    alg.num_learning_epochs, alg.num_mini_batches = base
    torch.set_num_threads(acting)
    return [{"variant": v, "update_s": b, "over_first": b / best[0]} for v, b in zip(variants, best, strict=True)]


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
