"""Simulation throughput: raw physics vs the env's control step (obs, reward, resets), 1 thread and all cores.

Raw physics = `mujoco.batch.Batch.step(nstep=substeps)` on the env's own per-env models (same objects, same
randomization draw, same substeps and threads) with no observation or reward work. Env = `BatchedGraspEnv.step`.
Each block first runs the env from a saved physics state with random delta-theta actions (fingers hit objects),
recording the joint targets it commanded; then restores that state and replays the same targets through raw
stepping, so both do identical physics. Blocks alternate so that a noisy shared machine affects both alike. The
ratio env / raw is the overhead check (target >= 0.85).

`--backend warp`: the same on MuJoCo Warp; raw = Warp's `step` x substeps per object-type model, with the targets
uploaded, without downloading state (one row: Warp parallelizes over worlds on its device).
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass

import numpy as np
import torch

from lab.bench import BenchConfig
from lerobot_blindgrasp import spec
from lerobot_blindgrasp.sim.batched_config import GraspEnvConfig
from lerobot_blindgrasp.sim.batched_env import BatchedGraspEnv
from lerobot_blindgrasp.sim.gripper import PhysicsOptions


@BenchConfig.register_subclass("sim")
@dataclass
class BenchSimConfig(BenchConfig):
    """Simulation throughput: raw physics vs the env's control step, per physics thread count."""

    num_envs: int = 1026  # parallel envs
    steps: int = 40  # control steps per timed block
    blocks: int = 3  # alternating raw/env blocks per thread count
    threads: list[int] | None = None  # thread counts, e.g. [1,2] (default: 1 and all CPUs)
    backend: str = "batch"  # physics backend: batch or warp (warp: one run)

    def __post_init__(self):
        if self.backend not in ("batch", "warp"):
            raise ValueError(f"--bench.backend must be batch or warp, got {self.backend!r}")


def _measure(num_envs: int, nthread: int, steps: int, blocks: int, backend: str = "batch") -> dict:
    env = BatchedGraspEnv(GraspEnvConfig(num_envs=num_envs, seed=0, nthread=nthread, backend=backend))
    env.reset()
    return {"backend": backend, "threads": env.physics.nthread, **time_env(env, steps, blocks)}


def time_env(env: BatchedGraspEnv, steps: int, blocks: int) -> dict:
    """The env's control step against raw physics replaying its joint targets, on an env already reset."""
    k, num_envs = env.cfg.physics.substeps, env.num_envs
    rng = np.random.default_rng(0)
    actions = rng.uniform(-0.15, 0.15, (steps, num_envs, spec.NUM_JOINTS))
    for a in actions[:5]:  # warm-up, and get fingers moving
        env.step(a)
    raw_t = env_t = 0.0
    ctrl = env.physics.ctrl
    for _ in range(blocks):
        saved = env.physics.snapshot()
        targets = []
        t = time.perf_counter()
        for a in actions:
            _, _, _, _, info = env.step(a)
            targets.append(info["joint_target"])
        env_t += time.perf_counter() - t
        after_env = env.physics.snapshot()
        env.physics.restore(saved)
        t = time.perf_counter()
        for target in targets:
            ctrl[:] = torch.as_tensor(target)  # the backend's ctrl is a tensor over the physics' own rows
            env.physics.raw_step(k)  # physics only: no observation, reward or state download
        raw_t += time.perf_counter() - t
        env.physics.restore(after_env)
    n_ctrl = blocks * steps * num_envs
    raw_ctrl = n_ctrl / raw_t
    env_ctrl = n_ctrl / env_t
    return {
        "raw_physics_steps_per_s": raw_ctrl * k,
        "raw_control_steps_per_s": raw_ctrl,
        "env_control_steps_per_s": env_ctrl,
        "env_over_raw": env_ctrl / raw_ctrl,
    }


def run(cfg: BenchSimConfig) -> dict:
    threads = cfg.threads or sorted({1, os.cpu_count() or 1})
    if cfg.backend == "warp":
        threads = [0]  # Warp parallelizes over worlds on its device; MuJoCo threads do not apply
    rows = [_measure(cfg.num_envs, n, cfg.steps, cfg.blocks, cfg.backend) for n in threads]
    base = rows[0]["env_control_steps_per_s"]
    for r in rows:
        r["env_speedup_vs_first"] = r["env_control_steps_per_s"] / base
    physics = PhysicsOptions()
    result = {"num_envs": cfg.num_envs, "substeps": physics.substeps, "timestep_s": physics.timestep, "rows": rows}
    if not cfg.json:
        print(
            f"blindgrasp-bench sim ({cfg.backend}): {cfg.num_envs} envs, {physics.substeps} x {physics.timestep * 1e3:g} ms "
            f"substeps per {spec.CONTROL_HZ:g} Hz control step"
        )
        print("| threads | raw physics steps/s | raw ctrl steps/s | env ctrl steps/s | env / raw | env speed-up |")
        print("|---:|---:|---:|---:|---:|---:|")
        for r in rows:
            print(
                f"| {r['threads']} | {r['raw_physics_steps_per_s']:,.0f} | {r['raw_control_steps_per_s']:,.0f} | "
                f"{r['env_control_steps_per_s']:,.0f} | {r['env_over_raw']:.2f} | {r['env_speedup_vs_first']:.2f}x |"
            )
    return result
