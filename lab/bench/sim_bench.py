"""Simulation throughput: raw physics vs the env's control step (obs, reward, resets), 1 thread and all cores.

Raw physics = `mujoco.batch.Batch.step(nstep=substeps)` on the env's own per-env models (same objects, same
randomization draw, same substeps and threads) with no observation or reward work. Env = `BatchedGraspEnv.step`
with random delta-theta actions (fingers hit objects). Each physics call of the env is replayed right after it
from the same state with the same targets (`ReplayedPhysics`), so both do identical physics and a noisy shared
machine affects both alike. The ratio env / raw is the overhead check (target >= 0.85).

`--backend warp`: the same on MuJoCo Warp; raw = Warp's `step` x substeps per object-type model, with the targets
uploaded, without downloading state (one row: Warp parallelizes over worlds on its device).
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass

import numpy as np

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
    """The env's control step against raw physics replaying each of its physics calls right after it
    (`ReplayedPhysics`), on an env already reset: `blocks` x `steps` control steps of random actions."""
    k, num_envs = env.cfg.physics.substeps, env.num_envs
    rng = np.random.default_rng(0)
    actions = rng.uniform(-0.15, 0.15, (steps, num_envs, spec.NUM_JOINTS))
    for a in actions[:5]:  # warm-up, and get fingers moving
        env.step(a)
    with ReplayedPhysics(env.physics) as replay:
        t = time.perf_counter()
        for _ in range(blocks):
            for a in actions:
                env.step(a)
        env_t = time.perf_counter() - t - replay.extra_s
    n_ctrl = blocks * steps * num_envs
    raw_ctrl = n_ctrl / replay.raw_s
    env_ctrl = n_ctrl / env_t
    return {
        "raw_physics_steps_per_s": raw_ctrl * k,
        "raw_control_steps_per_s": raw_ctrl,
        "env_control_steps_per_s": env_ctrl,
        "env_over_raw": env_ctrl / raw_ctrl,
    }


class ReplayedPhysics:
    """`env.physics.step` that replays each call as raw physics right after it, in the same load moment: the state
    before the call is restored, the backend's `raw_step` (the same physics without the env's bookkeeping) is timed
    on it with the same joint targets, and the state after the call is put back. The backend is deterministic, so
    the env goes on exactly as without the replay. `raw_s`: the replays' wall time; `extra_s` and `extra_cpu_s`: the
    snapshots', restores' and replays' wall and CPU time, which a caller takes out of what it measured around the
    env's steps."""

    def __init__(self, physics):
        self.physics, self.step = physics, physics.step
        self.raw_s = self.extra_s = self.extra_cpu_s = 0.0

    def __call__(self, nstep: int):
        p, t0, c0 = self.physics, time.perf_counter(), time.process_time()
        before = p.snapshot()
        t1, c1 = time.perf_counter(), time.process_time()
        failed = self.step(nstep)
        t2, c2 = time.perf_counter(), time.process_time()
        after = p.snapshot()
        p.restore(before)
        _wait(p)
        t3 = time.perf_counter()
        p.raw_step(nstep)
        t4 = time.perf_counter()
        p.restore(after)
        _wait(p)
        self.raw_s += t4 - t3
        self.extra_s += (t1 - t0) + (time.perf_counter() - t2)
        self.extra_cpu_s += (c1 - c0) + (time.process_time() - c2)
        return failed

    def __enter__(self):
        self.physics.step = self  # the instance's step: what the env calls
        return self

    def __exit__(self, *exc):
        del self.physics.step


def _wait(physics) -> None:
    """Queued device work done (Warp on a GPU), so that a timer started next times only what follows."""
    if physics.device.type == "cuda":
        import warp as wp

        wp.synchronize_device(physics.wp_device)


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
