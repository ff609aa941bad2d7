"""Physics backends: `BatchedGraspEnv` owns the task; a backend owns only N envs' physics state and its stepping.

Both expose `device` and (N, ...) tensors `qpos`, `qvel`, `ctrl`, `xfrc_applied`, `sensordata` that SHARE MEMORY
with the physics: writes to ctrl/xfrc_applied act at the next `step()`, to qpos/qvel at the next `forward(ids)`.
`reset(ids)` restores model defaults at rest; `forward(ids)` recomputes sensors; `step(nstep)` returns the (N,) bool
of envs whose physics went unstable; `snapshot`/`restore`/`raw_step` serve the benchmarks.

`batch` (default): `mujoco.batch.Batch`, float64 MuJoCo on CPU threads. `warp`: MuJoCo Warp (float32, GPU)."""

from __future__ import annotations

BACKENDS = ("batch", "warp")


def check_backend(name: str) -> str:
    if name not in BACKENDS:
        raise ValueError(f"unknown physics backend {name!r}; choose from {', '.join(BACKENDS)}")
    return name
