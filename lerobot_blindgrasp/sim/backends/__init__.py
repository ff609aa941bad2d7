"""Physics backends behind one task definition.

`BatchedGraspEnv` (env.py) owns the task: resets and their randomization draws, actions, pushes, observations,
rewards, success and termination, all numpy over the env axis. A backend owns only the physics state of N envs and
how it is stepped. Both backends expose the same surface:

- `qpos`, `qvel`, `ctrl`, `xfrc_applied`, `sensordata`: (N, ...) arrays the env indexes with numpy indexing (`a[ids]`,
  `a[:, cols]`, `a[ids] = rows`). `step()` and `forward()` leave `qpos`, `qvel` and `sensordata` current. Writes to
  `ctrl` and `xfrc_applied` take effect at the next `step()`; writes to `qpos`/`qvel` at the next `forward(ids)`.
- `reset(ids)`: back to the model's defaults with zero velocity, warm-start and applied force (the env then writes
  the episode's start pose and calls `forward(ids)`).
- `forward(ids)`: recompute derived quantities (sensors) for those envs only.
- `step(nstep) -> failed (N,) bool`: `nstep` physics steps for all envs; `failed` marks envs whose physics went
  unstable during this call (the env resets them).
- `snapshot()` / `restore(s)` and `raw_step(nstep)`: physics alone, for the benchmarks' raw-stepping baseline.

`batch` (default): `mujoco.batch.Batch`, float64 MuJoCo in C on CPU threads, one MjModel per env.
`warp`: MuJoCo Warp (float32, GPU; runs on CPU for development), one Warp model per object geometry type with
per-world model fields (see warp.py).
"""

from __future__ import annotations

BACKENDS = ("batch", "warp")


def check_backend(name: str) -> str:
    if name not in BACKENDS:
        raise ValueError(f"unknown physics backend {name!r}; choose from {', '.join(BACKENDS)}")
    return name
