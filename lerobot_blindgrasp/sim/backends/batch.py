"""The CPU backend: `mujoco.batch.Batch` (MuJoCo >= 3.17), one MjModel per env, stepped in C on all cores.

Every env's state is a row; the batch loads rows into a thread-local MjData and steps them with the GIL released;
results are bit-identical at any thread count. `qpos` etc. are the batch's live bindings of those rows.
"""

from __future__ import annotations

import mujoco
import numpy as np
from mujoco import batch as mjbatch


class BatchBackend:
    name = "batch"

    def __init__(self, models: list[mujoco.MjModel], nthread: int = 0):
        self.num_envs = n = len(models)
        self.models = models
        self.batch = mjbatch.Batch(models[0], nsim=n, nthread=nthread)
        self.batch.set_models(models)
        self.qpos = self.batch.bind("qpos")
        self.qvel = self.batch.bind("qvel")
        self.ctrl = self.batch.bind("ctrl")
        self.xfrc_applied = self.batch.bind("xfrc_applied")
        self.sensordata = self.batch.bind("sensordata")
        self._warm = self.batch.bind("qacc_warmstart")
        self._warnings_seen = np.zeros(n, dtype=np.int64)

    @property
    def nthread(self) -> int:
        return self.batch.nthread

    def reset(self, ids: np.ndarray) -> None:
        self.batch.reset(ids, stage=mujoco.mjtStage.mjSTAGE_NONE)
        self.qvel[ids] = 0.0
        self._warm[ids] = 0.0
        self.xfrc_applied[ids] = 0.0

    def forward(self, ids: np.ndarray) -> None:
        self.batch.forward(ids)
        # warnings raised by the reset itself are not failures of the next step
        self._warnings_seen[ids] = self.batch.warning[ids, :, 1].sum(axis=1)

    def step(self, nstep: int, ids: np.ndarray | None = None) -> np.ndarray:
        """`nstep` physics steps for all envs, or only `ids` (the others keep their state)."""
        failed = np.zeros(self.num_envs, dtype=bool)
        try:
            self.batch.step(ids=ids, nstep=nstep)
        except mjbatch.SimulationError as e:  # those sims kept their old state; the env resets them
            failed[e.ids] = True
        warn = self.batch.warning[:, :, 1].sum(axis=1)
        failed |= warn > self._warnings_seen
        failed |= ~np.isfinite(self.qpos).all(axis=1) | ~np.isfinite(self.qvel).all(axis=1)
        self._warnings_seen = warn
        return failed

    # --- benchmarks and rendering ----------------------------------------------------------------------------
    def snapshot(self):
        return self.batch.state.copy()

    def restore(self, state) -> None:
        self.batch.state[:] = state

    def raw_step(self, nstep: int) -> None:
        self.batch.step(nstep=nstep)

    def get_data(self, i: int) -> mujoco.MjData:
        return self.batch.get_data(i)

    def close(self) -> None:
        self.batch = None
