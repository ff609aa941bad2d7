"""Physics backends: `BatchedGraspEnv` owns the task; a backend owns only N envs' physics state and its stepping.

The surface both expose:
- `device`; `qpos`, `qvel`, `ctrl`, `xfrc_applied`, `sensordata`: (N, ...) tensors on `device` SHARING MEMORY with
  the physics state, read and written in place. `step()`/`forward()` leave qpos, qvel and sensordata current;
  writes to ctrl/xfrc_applied take effect at the next `step()`, to qpos/qvel at the next `forward(ids)`.
- `reset(ids)`: model defaults, zero velocity, warm-start and applied force; `forward(ids)`: recompute sensors.
- `step(nstep) -> failed`: (N,) bool tensor of envs whose physics went unstable (the env resets them).
- `snapshot()` / `restore(s)` / `raw_step(nstep)`: physics alone, for the benchmarks.

`batch` (default): `mujoco.batch.Batch`, float64 MuJoCo on CPU threads. `warp`: MuJoCo Warp (float32, GPU), see warp.py."""

from __future__ import annotations

BACKENDS = ("batch", "warp")


def check_backend(name: str) -> str:
    if name not in BACKENDS:
        raise ValueError(f"unknown physics backend {name!r}; choose from {', '.join(BACKENDS)}")
    return name
