"""Batched blind-grasp environment: N grippers, one object each, torch over the env axis on the physics' device.
Terms live in their own modules; physics runs in a backend (`backends/__init__.py` has the contract).

Step (Sec. III-B): a_t in R^9 is clipped to +-0.3 rad, the servo target q_t + a_t to the joint limits (as the real
robot does), and `substeps` physics steps cover one 50 ms control period. Episodes last 10 s and terminate when the
object leaves the 10 cm workspace; envs auto-reset inside `step` (rsl-rl never calls reset), and `info["final"]`
describes the episodes that ended. Under a joint calibration offset, readings and absolute targets are in the
offset frame (`delta_for_target`), as with a real servo's wrong homing offset."""

from __future__ import annotations

import logging
from concurrent.futures import Future, ThreadPoolExecutor

import mujoco
import numpy as np
import torch

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.sim import (
    events,
    gripper,
    objects,
    observations,
    randomization,
    rewards,
    rng,
    sensors,
    termination,
)
from lerobot_blindgrasp.sim.backends.batch import BatchBackend
from lerobot_blindgrasp.sim.batched_config import GraspEnvConfig, allocate_objects
from lerobot_blindgrasp.sim.host import on_host

log = logging.getLogger(__name__)


class BatchedGraspEnv:
    """reset() -> obs; step(action (N, 9)) -> (obs, reward, terminated, truncated, info), obs = {"policy": (N, 12)
    o_t, "privileged": (N, 92)}. `reset_tensors`/`step_tensors` work in tensors on `device` (rsl-rl); `reset`/`step`
    in numpy on the host (views, not copies, on the CPU backend)."""

    def __init__(self, cfg: GraspEnvConfig):
        self.cfg = cfg
        n = self.num_envs = cfg.num_envs
        self.max_episode_steps = int(round(cfg.episode_s * spec.CONTROL_HZ))
        if cfg.env_seeds is not None:
            self.env_seeds = np.array([int(x) for x in cfg.env_seeds], dtype=np.uint64)
        else:
            self.env_seeds = (np.uint64(cfg.seed) + np.arange(n, dtype=np.uint64)).astype(np.uint64)
        self.object_index = allocate_objects(n, len(cfg.objects), cfg.object_weights)  # index into cfg.objects
        self.object_names = [cfg.objects[k] for k in self.object_index]
        obj_specs = [objects.scaled(objects.get_object(name), cfg.dr.object_size_scale) for name in cfg.objects]
        mjcf = [objects.object_mjcf(o, gripper.OBJECT_CONTYPE, gripper.OBJECT_CONAFFINITY) for o in obj_specs]
        self._templates = templates = [gripper.compile_model(xml, cfg.physics) for xml in mjcf]
        self.physics_draw = randomization.draw_physics(cfg.dr, self.env_seeds)  # (n,) on the CPU
        self.models = None  # warp: per-world fields on the device; env_model(i) builds env i's MjModel on demand
        if cfg.backend == "batch":
            self.models = [self.env_model(i) for i in range(n)]
            self.physics = BatchBackend(self.models, nthread=cfg.nthread)
        else:
            from lerobot_blindgrasp.sim.backends.warp import WarpBackend  # optional dependency

            self.physics = WarpBackend(
                templates, self.object_index, self.physics_draw, cfg.dr.torque_limit_scale, device=cfg.device
            )
        observations.check_state_layout(templates[0])
        self._init_task_state(templates[0], obj_specs)

    def _init_task_state(self, template: mujoco.MjModel, obj_specs: list[objects.ObjectSpec]) -> None:
        cfg, n = self.cfg, self.num_envs
        dev = self.device = self.physics.device
        f64 = {"dtype": torch.float64, "device": dev}
        self._seeds = rng.as_words(self.env_seeds, dev)
        self._noise_key = rng.stream_key(self._seeds, rng.STREAM_OBS_NOISE)
        # the step's observation noise, drawn in a helper thread on a CPU while the physics runs (`step_tensors`)
        self._noise_helper = ThreadPoolExecutor(1, thread_name_prefix="obs-noise") if dev.type == "cpu" else None
        self.sensor_draw = randomization.draw_sensors(cfg.dr, self._seeds)
        self.sensor_index = sensors.SensorIndex.from_model(template, dev)
        self._object_body = template.body("object").id
        p = self.physics  # its state tensors, read and written in place
        self._qpos, self._qvel, self._ctrl, self._xfrc = p.qpos, p.qvel, p.ctrl, p.xfrc_applied
        self._sensordata = p.sensordata
        self.rest_height = torch.tensor([obj_specs[k].rest_height for k in self.object_index], **f64)
        self._rest_quat = torch.tensor([obj_specs[k].rest_quat for k in self.object_index], **f64)
        self._joint_lower, self._joint_upper = (
            torch.as_tensor(x, **f64) for x in (spec.JOINT_LOWER, spec.JOINT_UPPER)
        )
        self._object_index = torch.as_tensor(self.object_index, device=dev)
        i64 = {"dtype": torch.int64, "device": dev}
        self.episode = torch.zeros(n, **i64)  # per-env episode counter (drives the reset draws)
        self.episode_length = torch.zeros(n, **i64)
        self.lifted_steps = torch.zeros(n, **i64)  # consecutive steps lifted >= SUCCESS_LIFT_M
        self.success = torch.zeros(n, dtype=torch.bool, device=dev)  # latched once held for SUCCESS_HOLD_S
        self.prev_action = torch.zeros((n, spec.NUM_JOINTS), **f64)
        self.episode_return = torch.zeros(n, **f64)
        self.episode_terms = {k: torch.zeros(n, **f64) for k in rewards.TERM_NAMES}
        self.physics_resets = 0  # envs reset because their physics went unstable
        # The event terms (sim/events.py); all but Table II's pushes are off at their defaults.
        self.pushes = events.Pushes(cfg.dr, self._seeds)
        self.hold_push = events.HoldPush(cfg.dr, self._seeds)
        self.action_latency = events.ActionLatency(cfg.dr.action_latency_steps, n, dev)
        self.obs_latency = events.ObservationLatency(cfg.dr.obs_latency_steps)
        self.servo = events.ServoModel(cfg.dr, self._seeds)
        self._all = torch.arange(n, device=dev)

    def env_model(self, i: int) -> mujoco.MjModel:
        """Env i's MjModel: its object with its Table II draw (what either backend simulates for env i)."""
        if self.models is not None:
            return self.models[i]
        template = self._templates[self.object_index[i]]
        return randomization.apply_physics_draw(template, self.physics_draw, i, self.cfg.dr.torque_limit_scale)

    def reset(self) -> dict[str, np.ndarray]:  # numpy on the host; reset_tensors on the device
        return on_host(self.reset_tensors())

    def reset_tensors(self) -> dict[str, torch.Tensor]:
        self.episode.zero_()
        self._reset_envs(self._all)
        obs = self._observe()
        self.obs_latency.start(obs)
        return obs

    def _reset_envs(self, ids: torch.Tensor) -> None:
        q0, xy = randomization.draw_reset(self.cfg.dr, self._seeds[ids], self.episode[ids])
        q0 = q0.clamp(self._joint_lower, self._joint_upper)
        self.physics.reset(ids)  # defaults; zero velocity, warm-start and applied forces
        qpos = self._qpos[ids]
        qpos[:, observations.JOINTS] = q0
        qpos[:, observations.OBJECT_POS] = torch.cat([xy, self.rest_height[ids, None]], dim=1)
        qpos[:, observations.OBJECT_QUAT] = self._rest_quat[ids]
        self._qpos[ids] = qpos
        self._ctrl[ids] = q0.to(self._ctrl.dtype)  # float32 where the tensor is Warp's own array (share_arrays)
        self.action_latency.reset(ids, q0)
        self.servo.reset(ids, q0)
        self.hold_push.reset(ids)
        self.physics.forward(ids)
        # index_fill_: one op each, where `x[ids] = 0` also makes a scalar tensor and goes through advanced indexing
        for v in (self.episode_length, self.lifted_steps, self.success, self.prev_action, self.episode_return):
            v.index_fill_(0, ids, 0)
        for v in self.episode_terms.values():
            v.index_fill_(0, ids, 0)
        self.pushes.reset(ids)

    def validate_action(self, action) -> torch.Tensor:
        a = self._f64(action)
        if a.shape != (self.num_envs, spec.NUM_JOINTS):
            raise ValueError(f"action must have shape ({self.num_envs}, {spec.NUM_JOINTS}), got {tuple(a.shape)}")
        if not isinstance(action, torch.Tensor) and not (ok := np.isfinite(a.numpy()).all(axis=1)).all():
            raise ValueError(f"action has NaN/inf entries for envs {np.flatnonzero(~ok)[:10].tolist()}")
        return a

    def step(self, action, active: np.ndarray | None = None):
        """One control step, numpy on the host. `active` (batch backend only): the envs to simulate; the rest wait."""
        return on_host(self.step_tensors(action, active))

    def step_tensors(self, action, active=None):
        """`step` on `device` tensors; a tensor action's NaN fails the physics (a check would wait on the device)."""
        ids = None if active is None else np.flatnonzero(on_host(active))
        if ids is not None and self.physics.name != "batch":
            raise NotImplementedError("stepping a subset of envs needs the batch backend")
        a = self.validate_action(action).clamp(-spec.ACTION_BOUND_RAD, spec.ACTION_BOUND_RAD)
        noise = self._draw_noise_beside()  # while the physics runs
        target, failed = self._actuate(a, ids)
        obs = self._observe(noise=noise)
        raw = self._raw
        terms, reward = self._rewards(raw, a, failed)
        self.episode_length += 1
        self.lifted_steps = termination.held_steps(self.lifted_steps, raw["lift"])
        self.success |= termination.is_success(self.lifted_steps)
        self.hold_push.start(self._xfrc, self._object_body, self.lifted_steps, self.episode)
        self.prev_action = a
        self.episode_return += reward
        for k, v in terms.items():
            self.episode_terms[k] += v
        terminated = termination.out_of_workspace(raw["d_xy"], self.cfg.reward.workspace_radius_m) | failed
        truncated = termination.timed_out(self.episode_length, self.max_episode_steps, terminated)
        info = {
            "success": self.success.clone(),
            "lift": raw["lift"],
            "n_contact": rewards.num_contacts(raw["uniaxial_clean"]),
            "uniaxial_force": raw["uniaxial_clean"],  # noise-free, after the deadband (N)
            "tip_object_force": raw["tip_object_force"],  # |net force| of each tip on the object (N)
            "tip_object_downward": raw["tip_object_downward"],  # its -F_z/|F| (1: pressing straight down)
            # the absolute targets sent (rad) in the joints' measured frame: what a demo under an offset must teach
            "joint_target": self._measured_frame(target),
            "terms": terms,
            "physics_failed": failed,
        }
        done = terminated | truncated
        ended = done.nonzero()[:, 0]  # the one wait on the device per step: which envs restart
        if ended.numel():
            self._end_episodes(ended, obs, info, terminated, truncated, failed)
        return self.obs_latency(obs, done), reward, terminated, truncated, info

    def _actuate(self, a: torch.Tensor, ids: np.ndarray | None) -> tuple[torch.Tensor, torch.Tensor]:
        """One control period of physics towards q + a, with its events; (the servos' target, the failed envs)."""
        q = self._qpos[:, observations.JOINTS]
        target = self.action_latency(torch.clamp(q + a, self._joint_lower, self._joint_upper))
        self.pushes(self._xfrc, self._object_body)
        if self.servo.on:
            failed = self.servo.step(self, target, ids)
        else:
            self._ctrl[:] = target
            # unstable envs are reset below
            failed = self.physics.step(self.cfg.physics.substeps, *(() if ids is None else (ids,)))
        self.servo.last_target = target
        self.hold_push.end(self._xfrc, self._object_body)  # it lasts the one control period it was set for
        return target, failed

    def _rewards(self, raw: dict, a: torch.Tensor, failed: torch.Tensor) -> tuple[dict, torch.Tensor]:
        """The reward terms (eq. 1-6, `rewards.py`) and their weighted sum; 0 where the physics failed."""
        step = rewards.StepQuantities(
            lift=raw["lift"],
            d_xy=raw["d_xy"],
            uniaxial_force=raw["uniaxial_clean"],
            q=raw["q"],
            action=a,
            prev_action=self.prev_action,
            tip_object_distance=raw["tip_object_distance"],
            tip_object_force=raw["tip_object_force"],
            contact_threshold_n=self.cfg.reward.contact_threshold_n,
        )
        terms = rewards.compute_terms(step, self.cfg.reward)
        reward = rewards.total(terms, self.cfg.reward).masked_fill(failed, 0.0)
        return terms, reward

    def _end_episodes(self, ids: torch.Tensor, obs: dict, info: dict, terminated, truncated, failed) -> None:
        """Describe the ended episodes in info["final"]; with autoreset, start the next ones in their rows of `obs`."""
        unstable = failed[ids]
        if unstable.any():
            self.physics_resets += int(unstable.sum())
            log.warning("physics unstable in envs %s; resetting them", ids[unstable][:10].tolist())
        info["final"] = {
            "env_ids": ids,
            "object_index": self._object_index[ids],
            "success": self.success[ids],
            "episode_return": self.episode_return[ids],
            "episode_length": self.episode_length[ids],
            "terminated": terminated[ids],
            "truncated": truncated[ids],
            "terms": {k: v[ids] for k, v in self.episode_terms.items()},
            "observation": {k: v[ids] for k, v in obs.items()},
        }
        if self.cfg.autoreset:
            self.episode[ids] += 1
            self._reset_envs(ids)
            fresh = self._observe(ids)
            for k in obs:
                obs[k][ids] = fresh[k]
            self.obs_latency.restart(ids, fresh)  # a new episode starts with its own observation

    def _f64(self, x) -> torch.Tensor:
        return torch.as_tensor(x, dtype=torch.float64, device=self.device)

    def _measured_frame(self, q: torch.Tensor, sel: slice | torch.Tensor = slice(None)) -> torch.Tensor:
        """Absolute joint positions of envs `sel` in the joints' measured frame (a copy)."""
        return self.sensor_draw.measured(q, sel) if self.cfg.dr.joint_calibration_rad else q.clone()

    def target_for_delta(self, delta):
        """The absolute targets (n, 9) in the measured frame that `step` commands for `delta` (numpy or tensor)."""
        q = self._qpos[:, observations.JOINTS]
        step = self._f64(delta).clamp(-spec.ACTION_BOUND_RAD, spec.ACTION_BOUND_RAD)
        out = self._measured_frame(torch.clamp(q + step, self._joint_lower, self._joint_upper))
        return out if isinstance(delta, torch.Tensor) else on_host(out)

    def delta_for_target(self, target, ids: slice | np.ndarray | None = None):
        """The step (n, 9) taking all envs (or `ids`) to absolute `target`s in the measured frame (numpy or tensor)."""
        sel = slice(None) if ids is None else ids
        sel = sel if isinstance(sel, slice) else torch.as_tensor(sel, device=self.device)
        q = self._measured_frame(self._qpos[sel, observations.JOINTS], sel)
        out = self._f64(target) - q
        return out if isinstance(target, torch.Tensor) else on_host(out)

    def _observe(self, ids: torch.Tensor | None = None, noise: Future | None = None) -> dict[str, torch.Tensor]:
        """Both observations for all envs or `ids`; for all envs, also the raw quantities the rewards read. `noise`:
        their noise draw, being made in the helper thread."""
        sel = slice(None) if ids is None else ids
        if noise is not None:
            noise = noise.result()
        else:
            noise = rng.normal(None, *self._noise_args(sel))
        state = [x[sel] for x in (self._qpos, self._qvel, self._sensordata, self.rest_height, self.prev_action)]
        raw, obs = observations.observe(
            *state[:3], self.sensor_index, *state[3:], noise, self.cfg.dr, self.sensor_draw.rows(sel)
        )
        if ids is None:
            self._raw = raw  # what this step's reward terms read (set by every full observation, reset first)
        return obs

    def _noise_args(self, sel: slice | torch.Tensor) -> tuple:
        """`rng.normal`'s arguments (after the seeds) for the observation noise of rows `sel` at their counters."""
        counter = self.episode[sel] * 100_003 + self.episode_length[sel]
        return rng.STREAM_OBS_NOISE, counter, observations.NOISE_DIM, self._noise_key[sel]

    def _draw_noise_beside(self) -> Future | None:
        """On a CPU, the step's observation noise drawn in the helper thread while MuJoCo steps: a pure function of
        the episode counters, which the physics does not change. Its tens of whole-batch ops then take a share of a
        physics core instead of running after the physics on this thread. Drawn beside this thread's own torch ops
        instead, it would slow both: two Python threads running small ops at once hand the GIL back and forth at
        every op, whereas MuJoCo steps without holding it."""
        if self._noise_helper is None:
            return None
        return self._noise_helper.submit(rng.normal, None, *self._noise_args(slice(None)))

    # --- helpers for tests, rendering and eval (numpy on the host) ---------------------------------------------
    def set_targets(self, cmd) -> None:
        """The servos' position targets (n, 9) for the next physics substep (the servo model steps substeps)."""
        self._ctrl[:] = self._f64(cmd)

    def joint_positions(self) -> np.ndarray:
        return on_host(self._qpos[:, observations.JOINTS]).copy()

    def object_position(self) -> np.ndarray:
        return on_host(self._qpos[:, observations.OBJECT_POS]).copy()

    def fingertip_positions(self) -> np.ndarray:
        """(N, 3 fingers, xyz) world positions of the tip sites (the load cells)."""
        return on_host(self.sensor_index.read(self._sensordata, "pos")).copy()

    def mj_model_data(self, i: int) -> tuple[mujoco.MjModel, mujoco.MjData]:
        """Env i's model and a forwarded MjData of its current state (for rendering)."""
        m = self.env_model(i)
        d = self.physics.get_data(i, m)
        mujoco.mj_forward(m, d)
        return m, d

    def close(self) -> None:
        if self._noise_helper is not None:
            self._noise_helper.shutdown(cancel_futures=True)
        self.physics.close()
