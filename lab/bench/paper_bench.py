"""The `paper` preset at its env count, in one run: the figures a GPU run is judged by, in one JSON.

    python -m lab.bench --bench.type=paper --bench.backend=warp --bench.output=paper_run.json     # 9000 envs
    python -m lab.bench --bench.type=paper --bench.num_envs=36 --bench.demo_s=20 --bench.output=smoke.json

`scripts/gpu_run.sh` runs it on a GPU machine. Stages, in order, each bounded in time; the JSON at --bench.output
is rewritten (atomically) after each, so a run killed at its limit keeps the stages it finished, and a later run
with other --bench.stages (same preset, env count and backend) adds its stages to the same JSON:
1. `warmup`: a small env of every catalogue object (with Warp: one model per object geometry type) stepped once,
   which makes Warp compile every kernel the run uses, or load it from its kernel cache (~/.cache/warp); with the
   `onemodel` stage, its one model too.
2. `loop`: the preset's env and rsl-rl runner at --bench.num_envs, built once as `blindgrasp-train-teacher` builds
   them. Then the env alone against raw physics (the sim bench), and the whole PPO loop (the teacher bench:
   collection, the update), each physics call replayed as raw physics right after it from the same state, one
   iteration at a time until --bench.iterations, or until --bench.loop_s seconds of them have passed.
3. `demos`: `blindgrasp-collect-demos` (the shipped teacher unless --bench.teacher) in its own process at
   --bench.demo_num_envs envs, stopped after --bench.demo_s seconds of collecting the way Ctrl-C stops it. The
   clock starts when the collector has built its env (it records the run in collection.json then): curated demos
   per second of collection, not of start-up.

4. `onemodel` (not run unless named in --bench.stages; `scripts/gpu_run.sh` names it): the object groups' captured
   graphs back to back (the backend's path) against one model with a geom of each type per object
   (`onemodel_bench.py`), both at --bench.num_envs: built, checked to step the same physics along a side grasp
   (--bench.onemodel_check_steps control steps), then timed in alternating blocks; no timing block starts after
   --bench.onemodel_s seconds of the stage.

`headline` holds the four figures of the issue (env steps/s with training, collection / raw physics, update /
collection, curated demos/s) and the hours they give for Table III's 972 M env steps and the paper's 89,500 demos.
Each is measured on the device this runs on; a stage that did not run leaves its figures null.
"""

from __future__ import annotations

import contextlib
import os
import platform
import signal
import subprocess
import sys
import tempfile
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path

from lab.bench import BenchConfig

STAGES = ("warmup", "loop", "demos", "onemodel")
DEFAULT_STAGES = ("warmup", "loop", "demos")  # onemodel: only when named
TABLE_III_ENV_STEPS = 9000 * 24 * 4500  # envs x steps per env x iterations (Table III)
PAPER_DEMOS = 89_500  # the paper's curated demos


@BenchConfig.register_subclass("paper")
@dataclass
class BenchPaperConfig(BenchConfig):
    """The paper preset at its env count: PPO loop, raw physics, env and demo collection, one JSON."""

    preset: str = "paper"  # teacher preset
    num_envs: int | None = None  # default: the preset's (9000)
    backend: str = "warp"  # physics: warp (the GPU if there is one, else Warp's CPU device) or batch
    stages: list[str] = field(default_factory=lambda: list(DEFAULT_STAGES))  # of warmup, loop, demos, onemodel
    iterations: int = 3  # timed PPO iterations at most (after one warm-up iteration)
    loop_s: float = 120.0  # no timed PPO iteration starts after this many seconds of them
    env_steps: int = 24  # control steps per block of the env-alone timing (one PPO rollout's length)
    env_blocks: int = 2  # alternating env / raw blocks
    demo_s: float = 60.0  # seconds of demo collection, counted from the collector's built env
    demo_num_envs: int | None = None  # default: num_envs
    demo_start_s: float = 420.0  # the collector's start-up (imports, teacher, env build) may take this long
    onemodel_s: float = 60.0  # onemodel: no timing block starts after this many seconds of the stage
    onemodel_check_steps: int = 16  # onemodel: control steps of the side grasp both paths replay
    onemodel_steps: int = 8  # onemodel: control steps per timing block (up to 4 blocks per path)
    teacher: Path | None = None  # demos: teacher folder or checkpoint (default: the shipped teacher)
    output: Path | None = None  # the JSON, rewritten after each stage (default: printed only)

    def __post_init__(self):
        from lerobot_blindgrasp import presets

        presets.get(self.preset, "teacher")
        if self.backend not in ("batch", "warp"):
            raise ValueError(f"--bench.backend must be batch or warp, got {self.backend!r}")
        unknown = set(self.stages) - set(STAGES)
        if unknown:
            raise ValueError(f"--bench.stages: unknown {sorted(unknown)}; choose from {', '.join(STAGES)}")


def run(cfg: BenchPaperConfig) -> dict:
    from lerobot_blindgrasp import presets

    num_envs = cfg.num_envs or presets.get(cfg.preset, "teacher").num_envs
    result = {"preset": cfg.preset, "num_envs": num_envs, "backend": cfg.backend, "machine": machine(cfg.backend)}
    result["stages"] = _earlier_stages(cfg, result)
    for name, stage in (("warmup", _warmup), ("loop", _loop), ("demos", _demos), ("onemodel", _onemodel)):
        if name not in cfg.stages:
            continue
        t = time.perf_counter()
        try:
            out = stage(cfg, num_envs)
        except Exception as e:  # noqa: BLE001  (a failed stage is recorded; the next ones still run)
            out = {"error": f"{type(e).__name__}: {e}", "traceback": traceback.format_exc()[-3000:]}
        out["stage_s"] = time.perf_counter() - t
        result["stages"][name] = out
        result["headline"] = headline(result["stages"])
        _save(cfg, result)
    result.setdefault("headline", headline(result["stages"]))
    if not cfg.json:
        _print(result)
    return result


def _earlier_stages(cfg: BenchPaperConfig, result: dict) -> dict:
    """The stages an earlier run of the same preset, env count and backend wrote to --bench.output, less those this
    run repeats: a run split over two calls (a machine's per-call limit) still ends in one JSON."""
    import json

    if cfg.output is None or not Path(cfg.output).is_file():
        return {}
    earlier = json.loads(Path(cfg.output).read_text())
    if any(earlier.get(k) != result[k] for k in ("preset", "num_envs", "backend")):
        return {}
    return {k: v for k, v in earlier.get("stages", {}).items() if k not in cfg.stages}


def _save(cfg: BenchPaperConfig, result: dict) -> None:
    if cfg.output is not None:
        from lerobot_blindgrasp import durable

        Path(cfg.output).parent.mkdir(parents=True, exist_ok=True)
        durable.atomic_write_json(cfg.output, result, indent=2)


def machine(backend: str) -> dict:
    """What ran it: the device and the versions that set the figures."""
    import importlib.metadata as md

    import torch

    versions = {}
    for dist in ("torch", "mujoco", "mujoco-warp", "warp-lang", "rsl-rl-lib"):
        with contextlib.suppress(md.PackageNotFoundError):
            versions[dist] = md.version(dist)
    gpu = torch.cuda.get_device_name(0) if torch.cuda.is_available() else None
    return {
        "gpu": gpu,
        "device": gpu or f"cpu ({os.cpu_count()} cores)",
        "cpu_cores": os.cpu_count(),
        "processor": platform.processor() or platform.machine(),
        "load_avg_at_start": os.getloadavg(),
        "versions": versions,
        "physics": backend,
    }


def _warmup(cfg: BenchPaperConfig, num_envs: int) -> dict:
    """Every object once, one control step: every kernel compiled or loaded from the cache."""
    import numpy as np

    from lerobot_blindgrasp import spec
    from lerobot_blindgrasp.sim import objects
    from lerobot_blindgrasp.sim.batched_config import GraspEnvConfig
    from lerobot_blindgrasp.sim.batched_env import BatchedGraspEnv

    t = time.perf_counter()
    env = BatchedGraspEnv(GraspEnvConfig(num_envs=len(objects.PAPER_OBJECTS), seed=0, backend=cfg.backend))
    env.reset()
    env.step(np.zeros((env.num_envs, spec.NUM_JOINTS)))
    groups = len(getattr(env.physics, "groups", ())) or None
    env.close()
    out = {"envs": env.num_envs, "physics_groups": groups, "compile_or_load_s": time.perf_counter() - t}
    if "onemodel" in cfg.stages and cfg.backend == "warp":  # its kernels too (collision pairs of every type)
        from lab.bench import onemodel_bench

        t = time.perf_counter()
        for backend in onemodel_bench.build_pair(len(objects.PAPER_OBJECTS)):
            backend.close()
        out["one_model_compile_or_load_s"] = time.perf_counter() - t
    return out


def _loop(cfg: BenchPaperConfig, num_envs: int) -> dict:
    """Build once; the env alone against raw physics; then PPO iterations until the count or the time box."""
    from lab.bench import sim_bench, teacher_bench
    from lerobot_blindgrasp.teacher.train import update_thread_count, with_torch_threads

    t0 = time.perf_counter()
    tcfg = teacher_bench.BenchTeacherConfig(
        preset=cfg.preset, num_envs=num_envs, backend=cfg.backend, iterations=cfg.iterations, json=True
    )
    preset, env, runner, device = teacher_bench._build(tcfg)
    build_s = time.perf_counter() - t0
    env.reset()
    env_alone = sim_bench.time_env(env, cfg.env_steps, cfg.env_blocks)
    update = with_torch_threads(runner.alg.update, update_thread_count(tcfg, env))
    runner.alg.update = update
    t = time.perf_counter()
    runner.learn(1, init_at_random_ep_len=True)  # warm-up: allocations, first normalizer stats
    warmup_it_s = time.perf_counter() - t
    deadline = time.perf_counter() + cfg.loop_s
    rows = []
    while len(rows) < cfg.iterations and (not rows or time.perf_counter() < deadline):
        rows += teacher_bench._timed_iterations(runner, env, update, 1)
    loop = teacher_bench._summary(tcfg, preset, env, rows, device, update_thread_count(tcfg, env))
    env.close()
    return {"build_s": build_s, "warmup_iteration_s": warmup_it_s, "env_alone": env_alone, "ppo": loop}


def _demos(cfg: BenchPaperConfig, num_envs: int) -> dict:
    """blindgrasp-collect-demos in its own process; SIGINT (its graceful stop) after demo_s of collecting."""
    from lerobot_blindgrasp.demos import provenance

    n = cfg.demo_num_envs or num_envs
    with tempfile.TemporaryDirectory(prefix="blindgrasp-paper-demos-") as tmp:
        out = Path(tmp) / "demos"
        cmd = [sys.executable, "-m", "lerobot_blindgrasp.demos.collect_cli", f"--output_dir={out}"]
        cmd += ["--repo_id=bench/paper_demos", f"--num_envs={n}", f"--backend={cfg.backend}", "--progress=false"]
        cmd += ["--episodes_per_object=1000000"]  # never done: the clock stops it
        cmd += [f"--teacher={cfg.teacher}"] if cfg.teacher else []
        t_start = time.perf_counter()
        proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        t_ready = _wait_until_collecting(proc, out, t_start + cfg.demo_start_s)
        if t_ready is not None:
            with contextlib.suppress(subprocess.TimeoutExpired):
                proc.wait(timeout=cfg.demo_s)
        t_stop = time.perf_counter()
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT)
        try:
            _, err = proc.communicate(timeout=120)
        except subprocess.TimeoutExpired:
            proc.kill()
            _, err = proc.communicate()
        runs = provenance.load_provenance(out)["runs"] if (out / provenance.PROVENANCE_NAME).exists() else []
    if t_ready is None or not runs:
        return {"error": f"the collector did not start collecting (exit {proc.returncode}): {err[-2000:]}"}
    run = runs[-1]
    collecting_s = t_stop - t_ready
    return {
        "num_envs": n,
        "startup_s": t_ready - t_start,
        "collecting_s": collecting_s,
        "rollouts": run["rollouts"],
        "kept": run["kept"],
        "frames": run["frames"],
        "env_steps": run["env_steps"],
        "curated_demos_per_s": run["kept"] / collecting_s,
        "env_steps_per_s": run["env_steps"] / collecting_s,
        "collector_wall_s": run["wall_s"],
        "stop_reason": run["stop_reason"],
        "exit_code": proc.returncode,
    }


def _onemodel(cfg: BenchPaperConfig, num_envs: int) -> dict:
    """The groups' graphs back to back against one model with per-world geometry (MuJoCo Warp only)."""
    if cfg.backend != "warp":
        return {"skipped": "one Warp model against the Warp groups: needs --bench.backend=warp"}
    from lab.bench import onemodel_bench

    steps, check = cfg.onemodel_steps, cfg.onemodel_check_steps
    return onemodel_bench.measure(num_envs, check, steps, blocks=4, budget_s=cfg.onemodel_s)


def _wait_until_collecting(proc, out: Path, deadline: float) -> float | None:
    """When the collector has built its env (its run shows in collection.json), or None if it exited first."""
    from lerobot_blindgrasp.demos import provenance

    while time.perf_counter() < deadline and proc.poll() is None:
        with contextlib.suppress(FileNotFoundError, ValueError, KeyError):
            if provenance.load_provenance(out)["runs"]:
                return time.perf_counter()
        time.sleep(0.2)
    return None


def headline(stages: dict) -> dict:
    """The issue's four figures, and the hours they give at the paper's counts; null where not measured."""
    ppo = (stages.get("loop") or {}).get("ppo") or {}
    demos = stages.get("demos") or {}
    env_alone = (stages.get("loop") or {}).get("env_alone") or {}
    one = stages.get("onemodel") or {}
    rate = ppo.get("loop_env_steps_per_s")
    demo_rate = demos.get("curated_demos_per_s")
    return {
        "env_steps_per_s_with_training": rate,
        "collection_over_raw_physics": ppo.get("collect_over_raw"),
        "collection_overhead_ms_per_step": ppo.get("overhead_ms_per_step"),
        "update_over_collection": ppo.get("update_over_collect"),
        "curated_demos_per_s": demo_rate,
        "raw_physics_control_steps_per_s": ppo.get("raw_control_steps_per_s"),
        "env_alone_control_steps_per_s": env_alone.get("env_control_steps_per_s"),
        "env_alone_over_raw": env_alone.get("env_over_raw"),
        "groups_raw_control_steps_per_s": (one.get("groups") or {}).get("raw_control_steps_per_s"),
        "one_model_raw_control_steps_per_s": (one.get("one") or {}).get("raw_control_steps_per_s"),
        "one_model_agrees": (one.get("check") or {}).get("agree"),
        "table_iii_hours": TABLE_III_ENV_STEPS / rate / 3600 if rate else None,
        "paper_demos_hours": PAPER_DEMOS / demo_rate / 3600 if demo_rate else None,
    }


def _print(result: dict) -> None:
    m = result["machine"]
    print(
        f"blindgrasp-bench paper: preset {result['preset']}, {result['num_envs']} envs, "
        f"{result['backend']} on {m['device']}"
    )
    for k, v in result["headline"].items():
        print(f"{k:<34} {'not measured' if v is None else f'{v:,.3f}'}")
    for name, stage in result["stages"].items():
        print(
            f"stage {name}: {stage['stage_s']:.1f} s" + (f", error: {stage['error']}" if "error" in stage else "")
        )
