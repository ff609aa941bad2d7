"""Physics backends behind one task definition.

`BatchedGraspEnv` (batched_env.py) owns the task: resets and their randomization draws, actions, pushes,
observations, rewards, success and termination, all torch over the env axis. A backend owns only the physics state
of N envs and how it is stepped. Both backends expose the same surface:

- `device`: the torch device the state tensors live on; the env keeps its own task state there too.
- `qpos`, `qvel`, `ctrl`, `xfrc_applied`, `sensordata`: (N, ...) float tensors on `device` that SHARE MEMORY with
  the physics state (no copies): the env reads them after a step and writes them in place (`a[ids] = rows`,
  `a[:, cols]`). `step()` and `forward()` leave `qpos`, `qvel` and `sensordata` current. Writes to `ctrl` and
  `xfrc_applied` take effect at the next `step()`; writes to `qpos`/`qvel` at the next `forward(ids)`.
- `reset(ids)`: back to the model's defaults with zero velocity, warm-start and applied force (the env then writes
  the episode's start pose and calls `forward(ids)`); `ids` an index tensor or array.
- `forward(ids)`: recompute derived quantities (sensors) for those envs only.
- `step(nstep) -> failed (N,) bool tensor on device`: `nstep` physics steps for all envs; `failed` marks envs whose
  physics went unstable during this call (the env resets them).
- `snapshot()` / `restore(s)` and `raw_step(nstep)`: physics alone, for the benchmarks' raw-stepping baseline.

`batch` (default): `mujoco.batch.Batch`, float64 MuJoCo in C on CPU threads, one MjModel per env; its tensors are
`torch.from_numpy` views of the batch's live bindings.
`warp`: MuJoCo Warp (float32, GPU; runs on CPU for development), one Warp model per object geometry type with
per-world model fields (see warp.py).
"""

from __future__ import annotations

BACKENDS = ("batch", "warp")


def check_backend(name: str) -> str:
    if name not in BACKENDS:
        raise ValueError(f"unknown physics backend {name!r}; choose from {', '.join(BACKENDS)}")
    return name
