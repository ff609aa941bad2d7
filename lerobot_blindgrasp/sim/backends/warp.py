"""The GPU backend: MuJoCo Warp (`pip install lerobot_policy_blindgrasp[gpu]`), also runnable on CPU for development.

Layout. MuJoCo Warp steps `nworld` copies of one model; model fields whose spec starts with "*" may carry one row
per world (`put_model(mjm, batch_sizes={field: nworld})`, indexed `worldid % rows` in every kernel). Objects of the
same geom type (box, cylinder, capsule, sphere) compile to models of identical structure that differ only in such
fields (geom size and bounds, mass, inertia, rest pose), so envs are grouped by the object's geom type: one Warp
model and one Data per group, each with its share of worlds. Within a group every field that differs between the
envs' randomized CPU models (the same `MjModel`s the batch backend steps: Table II friction, mass, inertia, servo
gains, and the constants `mj_setConst` derives from them) is batched per world and filled from those models, so
both backends simulate the same parameters. Fields that differ but cannot be batched raise at construction.

State. The env reads and writes host (float64) mirrors of qpos, qvel, ctrl, xfrc_applied and sensordata, as CPU
tensors over numpy arrays (`torch.from_numpy`, shared memory; `device` is the CPU);
`step` uploads ctrl and forces, steps each group, and downloads qpos, qvel and sensordata (about 100 floats per env
per control step). The `nstep` substeps of each group run as one captured graph: a CUDA graph on a GPU, Warp's
API capture on its CPU device (replayed natively, without the Python launch overhead of each kernel, which on CPU
is most of a step's time; the replay is bit-identical to stepping kernel by kernel).

Differences from the batch backend:
- float32 throughout (MuJoCo Warp's `float`), against float64 on CPU;
- contacts: MuJoCo Warp's own collision pipeline (primitive colliders and GJK/EPA with multi-contact for
  capsule/cylinder pairs) against CPU MuJoCo's; contact points and counts differ slightly;
- all PhysicsOptions are supported by mujoco-warp 4.0 (Newton solver, elliptic cones, impratio, noslip
  iterations, implicitfast, dense Jacobian); the solver (or its line search) stopping at its iteration cap
  is reported by Warp as an overflow bit, which is not a failure here (CPU MuJoCo stops there silently);
- failures are buffer overflows (contacts, constraints) and non-finite state; CPU MuJoCo's per-sim
  `SimulationError` (bad qacc) has no Warp counterpart, so such a world shows up as non-finite instead.
"""

from __future__ import annotations

import dataclasses
import os

import mujoco
import numpy as np
import torch

try:
    import mujoco_warp as mjw
    import warp as wp
    from mujoco_warp._src import types as mjw_types  # field specs: which Model fields may be batched per world
except ImportError as e:  # pragma: no cover - exercised only without the extra
    raise ImportError("the warp backend needs MuJoCo Warp: pip install 'lerobot_policy_blindgrasp[gpu]'") from e

# Per-world rows are allowed for Model array fields whose first dimension is "*".
_WARP_FIELDS = {f.name: f.type for f in dataclasses.fields(mjw_types.Model)}
_BATCHABLE = {k for k, t in _WARP_FIELDS.items() if getattr(t, "shape", ())[:1] == ("*",)}
# Unbatchable Warp fields that may still differ between objects: read only by features this model leaves off.
_UNUSED = {"dof_length"}  # velocity weighting for sleeping islands (sleep is disabled)

# Per-world contact and constraint capacity. The claw against one object makes at most ~30 contacts (3 tips and
# 6 link geoms on the object and the table, the object on the table); elliptic condim-4 contacts take 4 rows each,
# plus 9 joint limits and 15 dof friction-loss rows. A world that overflows is reported failed and reset.
# Solver or line search stopping at its iteration limit is not a failure: CPU MuJoCo stops there silently too.
_NOT_FAILURES = int(mjw_types.OverflowType.ITERATIONS | mjw_types.OverflowType.LS_ITERATIONS)

NCONMAX = 48
NJMAX = 224


def default_device() -> str:
    """The GPU of this process (torchrun's LOCAL_RANK) if CUDA is there, else the CPU."""
    wp.init()
    if wp.is_cuda_available():
        return f"cuda:{int(os.environ.get('LOCAL_RANK', '0'))}"
    return "cpu"


@dataclasses.dataclass
class _Group:
    ids: np.ndarray  # env ids of this group's worlds, in world order
    model: object  # mjw.Model
    data: object  # mjw.Data
    graph: object = None  # captured substeps
    graph_nstep: int = 0


def _array_fields(m: mujoco.MjModel) -> dict[str, np.ndarray]:
    out = {}
    for name in dir(m):
        if name.startswith("_"):
            continue
        v = getattr(m, name, None)
        if isinstance(v, np.ndarray) and v.size:
            out[name] = v
    return out


class WarpBackend:
    name = "warp"

    def __init__(
        self,
        templates: list[mujoco.MjModel],
        object_index: np.ndarray,
        env_model,
        device: str | None = None,
        nconmax: int = NCONMAX,
        njmax: int = NJMAX,
    ):
        """templates: one compiled MjModel per object; object_index: object of each env; env_model(i): env i's
        randomized MjModel (the same one the batch backend would step)."""
        self.wp_device = device or default_device()
        self.num_envs = n = len(object_index)
        self.nthread = 0  # not applicable; kept for the benchmarks' tables
        t0 = templates[0]
        self._h_qpos = np.tile(t0.qpos0, (n, 1))
        self._h_qvel = np.zeros((n, t0.nv))
        self._h_ctrl = np.zeros((n, t0.nu))
        self._h_xfrc_applied = np.zeros((n, t0.nbody, 6))
        self._h_sensordata = np.zeros((n, t0.nsensordata))
        # The backend contract (backends/__init__.py): tensors sharing memory with the state the env reads.
        self.device = torch.device("cpu")  # where the mirrors live; Warp runs on wp_device
        self.qpos, self.qvel = torch.from_numpy(self._h_qpos), torch.from_numpy(self._h_qvel)
        self.ctrl, self.xfrc_applied = torch.from_numpy(self._h_ctrl), torch.from_numpy(self._h_xfrc_applied)
        self.sensordata = torch.from_numpy(self._h_sensordata)
        self._zero_warm = np.zeros(n, dtype=bool)

        geom_type = np.array([tm.geom_type[tm.geom("object_geom").id] for tm in templates])
        self.groups: list[_Group] = []
        with wp.ScopedDevice(self.wp_device):
            for gt in np.unique(geom_type[object_index]):
                ids = np.flatnonzero(geom_type[object_index] == gt)
                self.groups.append(self._build_group(ids, [env_model(int(i)) for i in ids], nconmax, njmax))
        # env id -> (group, world)
        self._group_of = np.zeros(n, dtype=np.int64)
        self._world_of = np.zeros(n, dtype=np.int64)
        for k, g in enumerate(self.groups):
            self._group_of[g.ids] = k
            self._world_of[g.ids] = np.arange(len(g.ids))

    def _build_group(self, ids, models: list[mujoco.MjModel], nconmax: int, njmax: int) -> _Group:
        base = models[0]
        fields0 = _array_fields(base)
        differ: dict[str, list[np.ndarray]] = {}
        for m in models[1:]:
            for name, v in _array_fields(m).items():
                if name not in differ and not np.array_equal(v, fields0[name]):
                    differ[name] = []
        # MjModel arrays Warp has no field for (e.g. the BVH) are never read by Warp's physics.
        unbatchable = [k for k in differ if k in _WARP_FIELDS and k not in _BATCHABLE | _UNUSED]
        if unbatchable:
            raise NotImplementedError(f"model fields differ between worlds but cannot be batched: {unbatchable}")
        batched = [k for k in differ if k in _BATCHABLE]
        nw = len(models)
        model = mjw.put_model(base, batch_sizes=dict.fromkeys(batched, nw))
        model.opt.warn_overflow = int(model.opt.warn_overflow) & ~_NOT_FAILURES  # no print per iteration cap
        for k in batched:
            arr = getattr(model, k)
            ref = arr.numpy()
            # put_model copies these fields verbatim from MjModel; check it, so that writing rows is equivalent
            if not np.allclose(ref[0].reshape(-1), fields0[k].reshape(-1).astype(ref.dtype), rtol=1e-6, atol=0):
                raise NotImplementedError(f"Warp's {k} is not MjModel's {k}; per-world values cannot be copied")
            rows = np.stack([getattr(m, k) for m in models]).astype(ref.dtype)
            arr.assign(rows.reshape(ref.shape))
        data = mjw.make_data(base, nworld=nw, nconmax=nconmax, njmax=njmax)
        # Load every kernel now: a graph capture (first step) records launches but cannot compile.
        mjw.step(model, data)
        mjw.reset_data(model, data)
        return _Group(ids=np.asarray(ids), model=model, data=data)

    # --- state transfer ---------------------------------------------------------------------------------------
    @staticmethod
    def _upload(arr, host: np.ndarray) -> None:
        shape = tuple(arr.shape) + tuple(getattr(arr.dtype, "_shape_", ()))
        arr.assign(np.ascontiguousarray(host, dtype=np.float32).reshape(shape))

    def _push_state(self, g: _Group) -> None:
        d = g.data
        self._upload(d.qpos, self._h_qpos[g.ids])
        self._upload(d.qvel, self._h_qvel[g.ids])
        self._push_inputs(g)
        zero = self._zero_warm[g.ids]
        if zero.any():
            warm = d.qacc_warmstart.numpy().copy()
            warm[zero] = 0.0
            d.qacc_warmstart.assign(warm)
            self._zero_warm[g.ids] = False

    def _push_inputs(self, g: _Group) -> None:
        self._upload(g.data.ctrl, self._h_ctrl[g.ids])
        self._upload(g.data.xfrc_applied, self._h_xfrc_applied[g.ids])

    # --- backend interface --------------------------------------------------------------------------------------
    def reset(self, ids) -> None:
        ids = np.asarray(ids.cpu() if isinstance(ids, torch.Tensor) else ids)
        self._h_qpos[ids] = self._qpos0(ids)
        self._h_qvel[ids] = 0.0
        self._h_ctrl[ids] = 0.0
        self._h_xfrc_applied[ids] = 0.0
        self._zero_warm[ids] = True

    def _qpos0(self, ids: np.ndarray) -> np.ndarray:
        out = np.empty((len(ids), self._h_qpos.shape[1]))
        for k, g in enumerate(self.groups):
            mask = self._group_of[ids] == k
            if mask.any():
                q0 = g.model.qpos0.numpy()
                out[mask] = q0[self._world_of[ids[mask]] % q0.shape[0]]
        return out

    def forward(self, ids) -> None:
        ids = np.asarray(ids.cpu() if isinstance(ids, torch.Tensor) else ids)
        with wp.ScopedDevice(self.wp_device):
            for k, g in enumerate(self.groups):
                mine = ids[self._group_of[ids] == k]
                if mine.size == 0:
                    continue
                # Forward runs on all of the group's worlds; it only recomputes quantities derived from the state,
                # and only the reset worlds' sensors are read back (the others keep those of their last step).
                self._push_state(g)
                mjw.forward(g.model, g.data)
                self._h_sensordata[mine] = g.data.sensordata.numpy()[self._world_of[mine]]

    def _run(self, g: _Group, nstep: int) -> None:
        if g.graph is None or g.graph_nstep != nstep:
            with wp.ScopedCapture() as cap:  # records the launches; nothing runs until capture_launch
                for _ in range(nstep):
                    mjw.step(g.model, g.data)
            g.graph, g.graph_nstep = cap.graph, nstep
        wp.capture_launch(g.graph)

    def step(self, nstep: int) -> torch.Tensor:
        overflow = np.zeros(self.num_envs, dtype=np.int64)
        with wp.ScopedDevice(self.wp_device):
            for g in self.groups:
                self._push_inputs(g)
                g.data.overflow.zero_()
                self._run(g, nstep)
            for g in self.groups:  # downloads synchronize; all groups were launched first
                d = g.data
                self._h_qpos[g.ids] = d.qpos.numpy()
                self._h_qvel[g.ids] = d.qvel.numpy()
                self._h_sensordata[g.ids] = d.sensordata.numpy()
                overflow[g.ids] = d.overflow.numpy()
        failed = (overflow & ~_NOT_FAILURES) != 0
        failed |= ~np.isfinite(self._h_qpos).all(axis=1) | ~np.isfinite(self._h_qvel).all(axis=1)
        return torch.from_numpy(failed)

    # --- benchmarks and rendering ----------------------------------------------------------------------------
    def snapshot(self):
        with wp.ScopedDevice(self.wp_device):
            dev = [
                {
                    k: wp.clone(getattr(g.data, k))
                    for k in ("qpos", "qvel", "qacc_warmstart", "ctrl", "xfrc_applied")
                }
                for g in self.groups
            ]
        host = {k: getattr(self, f"_h_{k}").copy() for k in ("qpos", "qvel", "ctrl", "xfrc_applied", "sensordata")}
        return dev, host

    def restore(self, state) -> None:
        dev, host = state
        with wp.ScopedDevice(self.wp_device):
            for g, saved in zip(self.groups, dev):
                for k, v in saved.items():
                    wp.copy(getattr(g.data, k), v)
        for k, v in host.items():
            getattr(self, f"_h_{k}")[:] = v

    def raw_step(self, nstep: int) -> None:
        """Physics only: upload the commanded targets, step every group, wait; no state download."""
        with wp.ScopedDevice(self.wp_device):
            for g in self.groups:
                self._push_inputs(g)
                self._run(g, nstep)
            wp.synchronize_device(self.wp_device)

    def get_data(self, i: int, model: mujoco.MjModel) -> mujoco.MjData:
        """A CPU MjData holding env i's current state (for rendering)."""
        d = mujoco.MjData(model)
        d.qpos[:] = self._h_qpos[i]
        d.qvel[:] = self._h_qvel[i]
        d.ctrl[:] = self._h_ctrl[i]
        return d

    def close(self) -> None:
        self.groups = []
