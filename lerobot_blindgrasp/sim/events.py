"""The sim's events besides the physics step, one term each (like `rewards.py`); all off at the paper's settings
except Table II's training pushes. Each keeps per-env state on the envs' device, restarts envs in `reset(ids, ...)`
and acts on masks (no index lists that would wait on the device); draws are keyed on env seeds, so an env's events
are the same in any batch."""

from __future__ import annotations

import torch

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.sim import randomization

# Control steps (0.5 s) from the first lift to the hold push: half-way through the 1 s hold success needs.
HOLD_PUSH_AFTER_STEPS = spec.SUCCESS_HOLD_STEPS // 2


def set_object_force(xfrc: torch.Tensor, body: int, mask: torch.Tensor, force, add: bool = False) -> None:
    """Write (or add) a force (N, world frame; (n, 3) or a number) on the object of the envs in `mask`, in place."""
    f = xfrc[:, body, :3]
    new = f + force if add else torch.as_tensor(force, dtype=f.dtype, device=f.device).expand_as(f)
    f.copy_(torch.where(mask[:, None], new, f))


class Pushes:
    """Table II's random force: a push of U[-0.3, 0.3] N per axis for one control step, at random times."""

    def __init__(self, dr: randomization.DomainRandomization, seeds: torch.Tensor):
        self.on = dr.external_force
        self.schedule = randomization.PushSchedule(dr, seeds)

    def reset(self, ids: torch.Tensor) -> None:
        if self.on:
            self.schedule.reset(ids)

    def __call__(self, xfrc: torch.Tensor, body: int) -> None:
        """Before a control step: end last step's pushes, start the ones now due."""
        if not self.on:
            return
        ended, due, force = self.schedule.step()
        set_object_force(xfrc, body, ended, 0.0)
        set_object_force(xfrc, body, due, force)


class HoldPush:
    """One push of `hold_push_n` in a random 3-D direction, lasting one control period, 0.5 s into each hold."""

    def __init__(self, dr: randomization.DomainRandomization, seeds: torch.Tensor):
        self.dr, self.seeds = dr, seeds
        self.given = torch.zeros(len(seeds), dtype=torch.bool, device=seeds.device)  # this episode's was given
        self.pushing = torch.zeros(len(seeds), dtype=torch.bool, device=seeds.device)

    def reset(self, ids: torch.Tensor) -> None:
        self.given[ids] = False
        self.pushing[ids] = False

    def start(self, xfrc: torch.Tensor, body: int, lifted_steps: torch.Tensor, episode: torch.Tensor) -> None:
        """After a control step: push the envs whose object has now been lifted for HOLD_PUSH_AFTER_STEPS."""
        if not self.dr.hold_push_n:
            return
        due = (lifted_steps == HOLD_PUSH_AFTER_STEPS) & ~self.given
        force = randomization.draw_hold_push(self.dr, self.seeds, episode)  # kept only where due
        set_object_force(xfrc, body, due, force, add=True)
        self.given |= due
        self.pushing |= due

    def end(self, xfrc: torch.Tensor, body: int) -> None:
        """After the physics of the control period a push was set for: it is over."""
        if not self.dr.hold_push_n:
            return
        set_object_force(xfrc, body, self.pushing, 0.0)
        self.pushing[:] = False


class ActionLatency:
    """A ring of the last k + 1 targets: the servos get the one sent k control steps ago."""

    def __init__(self, steps: int, n: int, device: torch.device):
        self.steps = steps
        self.ring = torch.zeros((steps + 1, n, spec.NUM_JOINTS), dtype=torch.float64, device=device)  # newest last

    def reset(self, ids: torch.Tensor, q0: torch.Tensor) -> None:
        self.ring[:, ids] = q0  # a late target: the servos hold the start pose until the first arrives

    def __call__(self, target: torch.Tensor) -> torch.Tensor:
        if not self.steps:
            return target
        self.ring = torch.roll(self.ring, -1, dims=0)
        self.ring[-1] = target
        return self.ring[0].clone()


class ObservationLatency:
    """A ring of the last k + 1 observations (the policy gets the one k steps old); final and first are undelayed."""

    def __init__(self, steps: int):
        self.steps = steps
        self.ring: dict[str, torch.Tensor] = {}  # key -> (steps + 1, n, dim), newest last

    def start(self, obs: dict[str, torch.Tensor]) -> None:
        """After a full reset: every slot holds the first observation."""
        if self.steps:
            self.ring = {k: v[None].repeat(self.steps + 1, 1, 1) for k, v in obs.items()}

    def restart(self, ids: torch.Tensor, fresh: dict[str, torch.Tensor]) -> None:
        """Envs `ids` auto-reset: their slots hold their new episode's first observation."""
        for k, ring in self.ring.items():
            ring[:, ids] = fresh[k]

    def __call__(self, obs: dict[str, torch.Tensor], done: torch.Tensor) -> dict[str, torch.Tensor]:
        if not self.steps:
            return obs
        out = {}
        for k, v in obs.items():
            ring = torch.roll(self.ring[k], -1, dims=0)
            ring[-1] = v
            self.ring[k] = ring
            out[k] = torch.where(done[:, None], v, ring[0])
        return out


class ServoModel:
    """The servo beyond a position actuator: velocity limit, backlash and period jitter (`substep_servo`)."""

    def __init__(self, dr: randomization.DomainRandomization, seeds: torch.Tensor):
        self.dr, self.seeds = dr, seeds
        n = len(seeds)
        kw = {"dtype": torch.float64, "device": seeds.device}
        self.setpoint = torch.zeros((n, spec.NUM_JOINTS), **kw)  # velocity-limited servo setpoint
        self.last_target = torch.zeros((n, spec.NUM_JOINTS), **kw)  # the target in force before this step's
        self.on = dr.substep_servo

    def reset(self, ids: torch.Tensor, q0: torch.Tensor) -> None:
        self.setpoint[ids] = q0
        self.last_target[ids] = q0

    def step(self, env, target: torch.Tensor, ids) -> torch.Tensor:
        """One control period of `env`'s physics, one substep at a time; returns the envs whose physics failed."""
        dr, n_sub, dt = self.dr, env.cfg.physics.substeps, env.cfg.physics.timestep
        delay = torch.zeros(env.num_envs, dtype=torch.int64, device=target.device)
        if dr.period_jitter_s:
            counter = env.episode * 100_003 + env.episode_length
            delay = randomization.draw_jitter_substeps(dr, self.seeds, counter, n_sub)
        failed = torch.zeros(env.num_envs, dtype=torch.bool, device=target.device)
        for k in range(n_sub):
            goal = torch.where((k >= delay)[:, None], target, self.last_target)
            if dr.velocity_limit_rad_s:
                step = dr.velocity_limit_rad_s * dt
                self.setpoint = self.setpoint + (goal - self.setpoint).clamp(-step, step)
            else:
                self.setpoint = goal
            cmd = self.setpoint
            if dr.backlash_rad:
                q = env.physics.qpos[:, : spec.NUM_JOINTS]
                err = cmd - q
                cmd = q + torch.sign(err) * (err.abs() - dr.backlash_rad / 2).clamp_min(0.0)
            env.set_targets(cmd)
            failed |= env.physics.step(1) if ids is None else env.physics.step(1, ids)
        return failed
