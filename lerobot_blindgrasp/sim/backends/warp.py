"""The GPU backend: MuJoCo Warp (`pip install lerobot_policy_blindgrasp[gpu]`), also runnable on CPU.

Envs are grouped by the object's geom type: objects of one type compile to models differing only in fields that
MuJoCo Warp can batch per world ("*" specs), so each group is one Warp model (its first object's) and one Data.
Per world, on the device, the differing fields are gathered, Table II's draw is written by
`randomization.write_physics_draw` (float64, then cast to float32) and `mjw.set_const` recomputes the derived
constants; fields that differ but cannot be batched raise.

State: with one group holding every env in order (`share_arrays`), the contract's tensors ARE the Warp arrays
(float32, no copy); otherwise they are float64 copies exchanged with the groups each step. Substeps replay as one
captured graph (CUDA graph, or Warp's CPU capture), bit-identical to launching kernel by kernel.

Differences from the batch backend: float32; Warp's own collision pipeline (contacts differ slightly); failures are
buffer overflows and non-finite state (an iteration cap is not one, as on CPU)."""

from __future__ import annotations

import dataclasses
import os

import mujoco
import numpy as np
import torch

from lerobot_blindgrasp.sim import randomization

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
_DRAWN = (*randomization.PHYSICS_DRAW_FIELDS, randomization.TORQUE_LIMIT_FIELD)
# What mjw.set_const derives from the model (its docstring's list): one row per world, as the mass and inertia that
# Table II draws change some of them (subtree masses and centres of mass, the inverse weights of bodies and dofs).
_DERIVED = (
    "body_subtreemass",
    "geom_aabb",
    "geom_rbound",
    "tendon_length0",
    "eq_data",
    "cam_pos0",
    "cam_poscom0",
    "cam_mat0",
    "light_pos0",
    "light_poscom0",
    "light_dir0",
    "dof_invweight0",
    "body_invweight0",
    "tendon_invweight0",
    "actuator_acc0",
)

# Per-world contact and constraint capacity. The claw against one object makes at most ~30 contacts (3 tips and
# 6 link geoms on the object and the table, the object on the table); elliptic condim-4 contacts take 4 rows each,
# plus 9 joint limits and 15 dof friction-loss rows. A world that overflows is reported failed and reset.
# Solver or line search stopping at its iteration limit is not a failure: CPU MuJoCo stops there silently too.
_NOT_FAILURES = int(mjw_types.OverflowType.ITERATIONS | mjw_types.OverflowType.LS_ITERATIONS)

NCONMAX = 48
NJMAX = 224


def default_warp_device() -> str:
    """The GPU of this process (torchrun's LOCAL_RANK) if CUDA is there, else the CPU."""
    wp.init()
    if wp.is_cuda_available():
        return f"cuda:{int(os.environ.get('LOCAL_RANK', '0'))}"
    return "cpu"


_STATE = ("qpos", "qvel", "ctrl", "xfrc_applied", "sensordata")  # the contract's tensors
_INPUTS = ("ctrl", "xfrc_applied")  # written by the env, read by a step
_OUTPUTS = ("qpos", "qvel", "sensordata")  # written by a step


@dataclasses.dataclass
class _Group:
    ids: np.ndarray  # env ids of this group's worlds, in world order
    model: object  # mjw.Model
    data: object  # mjw.Data
    graph: object = None  # captured substeps
    graph_nstep: int = 0
    ids_t: torch.Tensor | None = None  # ids on the device
    view: dict | None = None  # the Data's state arrays as torch tensors (shared memory)


@dataclasses.dataclass
class _Worlds:
    ids: np.ndarray  # env ids of a group's worlds, in world order
    objects: np.ndarray  # their objects (indices into the templates)
    draw: randomization.PhysicsDraw  # every env's Table II draw
    torque_scale: float


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
        draw: randomization.PhysicsDraw,
        torque_limit_scale: float = 1.0,
        device: str | None = None,
        nconmax: int = NCONMAX,
        njmax: int = NJMAX,
        share_arrays: bool = True,
    ):
        """templates: one MjModel per object; object_index: each env's object; draw: every env's Table II draw;
        share_arrays: the state tensors are the Warp arrays themselves where possible (one group)."""
        self.wp_device = device or default_warp_device()
        self.device = torch.device(wp.device_to_torch(self.wp_device))
        self._cuda = self.device.type == "cuda"
        self.num_envs = n = len(object_index)
        self.nthread = 0  # not applicable; kept for the benchmarks' tables
        geom_type = np.array([tm.geom_type[tm.geom("object_geom").id] for tm in templates])
        self.groups: list[_Group] = []
        with wp.ScopedDevice(self.wp_device):
            for gt in np.unique(geom_type[object_index]):
                ids = np.flatnonzero(geom_type[object_index] == gt)
                world = _Worlds(ids, object_index[ids], draw, torque_limit_scale)
                self.groups.append(self._build_group(world, templates, nconmax, njmax))
        for g in self.groups:
            g.ids_t = torch.as_tensor(g.ids, device=self.device)
            g.view = {k: wp.to_torch(getattr(g.data, k)) for k in (*_STATE, "qacc_warmstart", "overflow")}
        # share_arrays: with one group holding every env in order, the contract's tensors ARE its Warp arrays
        # (float32, no copy at all); the task's terms write them with their dtype (see State above).
        self.shares_memory = (
            share_arrays and len(self.groups) == 1 and np.array_equal(self.groups[0].ids, np.arange(n))
        )
        for k in _STATE:
            v = self.groups[0].view[k]
            if self.shares_memory:
                setattr(self, k, v)
            else:
                setattr(self, k, torch.zeros((n, *v.shape[1:]), dtype=torch.float64, device=self.device))
        self._gather(_STATE)
        self._qpos0 = torch.zeros_like(self.qpos)
        for g in self.groups:
            q0 = wp.to_torch(g.model.qpos0)
            self._qpos0[g.ids_t] = q0[torch.arange(len(g.ids), device=self.device) % q0.shape[0]].to(
                self.qpos.dtype
            )
        self._zero_warm = torch.zeros(n, dtype=torch.bool, device=self.device)

    def _build_group(self, w: _Worlds, templates: list[mujoco.MjModel], nconmax: int, njmax: int) -> _Group:
        """One Warp model for the group: per-world rows for differing fields, Table II's and their derived ones."""
        objs = np.unique(w.objects)
        base, nw = templates[objs[0]], len(w.ids)
        fields0 = _array_fields(base)
        differ = {
            k
            for o in objs[1:]
            for k, v in _array_fields(templates[o]).items()
            if not np.array_equal(v, fields0[k])
        }
        # MjModel arrays Warp has no field for (e.g. the BVH) are never read by Warp's physics.
        unbatchable = sorted(k for k in differ if k in _WARP_FIELDS and k not in _BATCHABLE | _UNUSED)
        if unbatchable:
            raise NotImplementedError(f"model fields differ between worlds but cannot be batched: {unbatchable}")
        written = sorted((differ & _BATCHABLE) | set(_DRAWN))
        derived = [k for k in _DERIVED if k in _BATCHABLE and fields0.get(k, np.empty(0)).size]
        model = mjw.put_model(base, batch_sizes=dict.fromkeys({*written, *derived}, nw))
        model.opt.warn_overflow = int(model.opt.warn_overflow) & ~_NOT_FAILURES  # no print per iteration cap
        dev = wp.device_to_torch(self.wp_device)
        # Each world's rows in float64 on the device: its object's values, then its Table II draw written into
        # them (the same float64 arithmetic as the batch backend's MjModels), cast once to Warp's float32.
        local = torch.as_tensor(np.searchsorted(objs, w.objects), device=dev)
        rows = {
            k: torch.as_tensor(np.stack([getattr(templates[o], k) for o in objs]), device=dev)[local]
            for k in written
        }
        randomization.write_physics_draw(
            rows, randomization.DrawTargets.of(base), w.draw.rows(torch.as_tensor(w.ids), dev), w.torque_scale
        )
        wp.synchronize_device(self.wp_device)  # put_model's uploads done before torch reads and writes them
        for k in written:
            view = wp.to_torch(getattr(model, k)).view(nw, -1)
            # put_model copies these fields verbatim from MjModel; check it, so that writing rows is equivalent
            ref = view[0].cpu().numpy()
            if not np.allclose(ref, fields0[k].reshape(-1).astype(ref.dtype), rtol=1e-6, atol=0):
                raise NotImplementedError(f"Warp's {k} is not MjModel's {k}; per-world values cannot be written")
            view.copy_(rows[k].reshape(nw, -1))
        if self._cuda:  # torch's writes done before Warp's stream reads them
            torch.cuda.current_stream(dev).synchronize()
        data = mjw.make_data(base, nworld=nw, nconmax=nconmax, njmax=njmax)
        # The constants MuJoCo derives from mass and inertia (mj_setConst's), per world, on the device.
        mjw.set_const(model, data)
        # Load every kernel now: a graph capture (first step) records launches but cannot compile.
        mjw.step(model, data)
        mjw.reset_data(model, data)
        return _Group(ids=np.asarray(w.ids), model=model, data=data)

    # --- state transfer (on the device) -----------------------------------------------------------------------
    def _scatter(self, fields) -> None:
        """The env-ordered tensors into the groups' arrays (nothing to copy when they are the same memory)."""
        for g in [] if self.shares_memory else self.groups:
            for k in fields:
                g.view[k].copy_(getattr(self, k)[g.ids_t])
        if self._cuda:  # torch's writes done before Warp's stream reads them
            torch.cuda.current_stream(self.device).synchronize()

    def _gather(self, fields, groups=None) -> None:
        """The groups' arrays into the env-ordered tensors, after Warp's work is done."""
        if self._cuda:
            wp.synchronize_device(self.wp_device)
        for g in [] if self.shares_memory else groups or self.groups:
            for k in fields:
                getattr(self, k)[g.ids_t] = g.view[k].to(torch.float64)

    def _ids(self, ids) -> torch.Tensor:
        """Env ids as an index tensor on the device (a device tensor stays there: no wait on the device)."""
        return ids.to(self.device) if isinstance(ids, torch.Tensor) else torch.as_tensor(ids, device=self.device)

    # --- backend interface --------------------------------------------------------------------------------------
    def reset(self, ids) -> None:
        ids = self._ids(ids)
        self.qpos[ids] = self._qpos0[ids]
        self.qvel[ids] = 0.0
        self.ctrl[ids] = 0.0
        self.xfrc_applied[ids] = 0.0
        self._zero_warm[ids] = True

    def forward(self, ids) -> None:
        """Sensors of `ids` at their current state; the other envs keep their last step's sensors."""
        ids = self._ids(ids)
        mine = torch.zeros(self.num_envs, dtype=torch.bool, device=self.device)
        mine[ids] = True
        groups = [g for g in self.groups if bool(mine[g.ids_t].any())]
        keep = self.sensordata.clone()
        for g in groups:  # a reset world starts its solver cold, as MuJoCo's mj_resetData leaves it
            g.view["qacc_warmstart"][self._zero_warm[g.ids_t]] = 0.0
            self._zero_warm[g.ids_t] = False
        self._scatter(("qpos", "qvel", *_INPUTS))
        with wp.ScopedDevice(self.wp_device):
            for g in groups:
                mjw.forward(g.model, g.data)
        self._gather(("sensordata",), groups)
        self.sensordata[~mine] = keep[~mine]

    def _run(self, g: _Group, nstep: int) -> None:
        if g.graph is None or g.graph_nstep != nstep:
            with wp.ScopedCapture() as cap:  # records the launches; nothing runs until capture_launch
                for _ in range(nstep):
                    mjw.step(g.model, g.data)
            g.graph, g.graph_nstep = cap.graph, nstep
        wp.capture_launch(g.graph)

    def step(self, nstep: int) -> torch.Tensor:
        self._scatter(_INPUTS)
        with wp.ScopedDevice(self.wp_device):
            for g in self.groups:
                g.data.overflow.zero_()
                self._run(g, nstep)
        self._gather(_OUTPUTS)
        overflow = torch.zeros(self.num_envs, dtype=torch.int32, device=self.device)
        for g in self.groups:
            overflow[g.ids_t] = g.view["overflow"].to(torch.int32)
        failed = (overflow & ~_NOT_FAILURES) != 0
        return failed | ~torch.isfinite(self.qpos).all(1) | ~torch.isfinite(self.qvel).all(1)

    # --- benchmarks and rendering ----------------------------------------------------------------------------
    def snapshot(self):
        with wp.ScopedDevice(self.wp_device):
            dev = [{k: wp.clone(getattr(g.data, k)) for k in (*_STATE, "qacc_warmstart")} for g in self.groups]
        return dev, {k: getattr(self, k).clone() for k in _STATE}

    def restore(self, state) -> None:
        dev, env_ordered = state
        with wp.ScopedDevice(self.wp_device):
            for g, saved in zip(self.groups, dev):
                for k, v in saved.items():
                    wp.copy(getattr(g.data, k), v)
        for k, v in env_ordered.items():
            getattr(self, k).copy_(v)

    def raw_step(self, nstep: int) -> None:
        """Physics only: the commanded targets into the groups, every group stepped, wait; nothing gathered."""
        self._scatter(_INPUTS)
        with wp.ScopedDevice(self.wp_device):
            for g in self.groups:
                self._run(g, nstep)
            wp.synchronize_device(self.wp_device)

    def get_data(self, i: int, model: mujoco.MjModel) -> mujoco.MjData:
        """A CPU MjData holding env i's current state (for rendering)."""
        d = mujoco.MjData(model)
        d.qpos[:] = self.qpos[i].cpu().numpy()
        d.qvel[:] = self.qvel[i].cpu().numpy()
        d.ctrl[:] = self.ctrl[i].cpu().numpy()
        return d

    def close(self) -> None:
        self.groups = []
