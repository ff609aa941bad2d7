"""Physics backends: `BatchedGraspEnv` owns the task; a backend owns only N envs' physics state and its stepping.

Both expose `device` and the (N, ...) tensors `qpos`, `qvel`, `ctrl`, `xfrc_applied`, `sensordata`, which SHARE
MEMORY with the physics and are read and written in place: writes to ctrl/xfrc_applied act at the next `step()`,
to qpos/qvel at the next `forward(ids)`. `reset(ids)`: model defaults, zero velocity, warm-start and applied force;
`forward(ids)`: recompute sensors; `step(nstep) -> failed` (N,) bool (unstable envs, which the env resets);
`snapshot()` / `restore(s)` / `raw_step(nstep)`: physics alone, for the benchmarks.

`batch` (default): `mujoco.batch.Batch`, float64 MuJoCo on CPU threads. `warp`: MuJoCo Warp (float32, GPU), see warp.py."""

from __future__ import annotations

BACKENDS = ("batch", "warp")


def check_backend(name: str) -> str:
    if name not in BACKENDS:
        raise ValueError(f"unknown physics backend {name!r}; choose from {', '.join(BACKENDS)}")
    return name
