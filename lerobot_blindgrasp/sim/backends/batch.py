"""The CPU backend: `mujoco.batch.Batch` (MuJoCo >= 3.17), one MjModel per env, stepped in C on all cores with
the GIL released, bit-identical at any thread count. The state tensors are `torch.from_numpy` views of the batch's
live bindings."""

from __future__ import annotations

import warnings

import mujoco
import numpy as np
import torch
from mujoco import batch as mjbatch


def _ids(ids) -> np.ndarray:
    return ids.cpu().numpy() if isinstance(ids, torch.Tensor) else np.asarray(ids)


class BatchBackend:
    name = "batch"
    device = torch.device("cpu")

    def __init__(self, models: list[mujoco.MjModel], nthread: int = 0):
        self.num_envs = n = len(models)
        self.batch = mjbatch.Batch(models[0], nsim=n, nthread=nthread)
        self.batch.set_models(models)
        self._np_qpos, self._np_qvel = self.batch.bind("qpos"), self.batch.bind("qvel")
        self.qpos, self.qvel = torch.from_numpy(self._np_qpos), torch.from_numpy(self._np_qvel)
        self.ctrl = torch.from_numpy(self.batch.bind("ctrl"))
        self.xfrc_applied = torch.from_numpy(self.batch.bind("xfrc_applied"))
        with warnings.catch_warnings():  # the binding is read-only: MuJoCo computes it, and the env only reads it
            warnings.filterwarnings("ignore", "The given NumPy array is not writable")
            self.sensordata = torch.from_numpy(self.batch.bind("sensordata"))
        self._warnings_seen = np.zeros(n, dtype=np.int64)
        # Each sim's state row as mj_resetData leaves it, which `reset` copies in: a call loads the whole state from
        # its row (the batch is not persistent), so the copy is the reset, without a call into the batch per reset.
        self.batch.reset(stage=mujoco.mjtStage.mjSTAGE_NONE)
        self._state = torch.from_numpy(self.batch.state)
        self._reset_state = self._state.clone()

    @property
    def nthread(self) -> int:
        return self.batch.nthread

    def reset(self, ids) -> None:
        # the model's defaults, as mj_resetData: zero velocity, warm-start and applied forces
        ids = torch.as_tensor(ids)
        self._state.index_copy_(0, ids, self._reset_state.index_select(0, ids))

    def forward(self, ids) -> None:
        ids = _ids(ids)
        self.batch.forward(ids)
        # warnings raised by the reset itself are not failures of the next step
        self._warnings_seen[ids] = self.batch.warning[ids, :, 1].sum(axis=1)

    def step(self, nstep: int, ids: np.ndarray | None = None) -> torch.Tensor:
        """`nstep` physics steps for all envs, or only `ids`; returns the failed envs (bool tensor)."""
        failed = np.zeros(self.num_envs, dtype=bool)
        try:
            self.batch.step(ids=ids, nstep=nstep)
        except mjbatch.SimulationError as e:  # those sims kept their old state; the env resets them
            failed[e.ids] = True
        warn = self.batch.warning[:, :, 1].sum(axis=1)
        failed |= warn > self._warnings_seen
        # numpy on the bindings themselves: a few calls, where torch would add its per-op cost at small batches
        failed |= ~np.isfinite(self._np_qpos).all(axis=1) | ~np.isfinite(self._np_qvel).all(axis=1)
        self._warnings_seen = warn
        return torch.from_numpy(failed)

    # --- benchmarks and rendering ----------------------------------------------------------------------------
    def snapshot(self):
        return self.batch.state.copy()

    def restore(self, state) -> None:
        self.batch.state[:] = state

    def raw_step(self, nstep: int) -> None:
        self.batch.step(nstep=nstep)

    def get_data(self, i: int, model: mujoco.MjModel | None = None) -> mujoco.MjData:
        """Env i's current state (the batch holds its own models; `model` is the Warp backend's argument)."""
        return self.batch.get_data(i)

    def close(self) -> None:
        self.batch = None
