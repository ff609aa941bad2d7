"""The sim's events: what happens to the envs besides the physics step, one named term each, as the reward terms
are (`rewards.py`). `BatchedGraspEnv` composes them; every one is off at the paper's settings except Table II's
pushes during training.

- `Pushes`: Table II's random pushes on the object (`randomization.PushSchedule` decides when and how hard).
- `HoldPush`: one push of `hold_push_n` on the object 0.5 s after it is first lifted in an episode.
- `ActionLatency`: the servos get the target sent `action_latency_steps` control steps ago.
- `ObservationLatency`: the policy gets the observation measured `obs_latency_steps` control steps ago.
- `ServoModel`: velocity limit, backlash and period jitter; the control period is then stepped one physics substep
  at a time (the setpoint moves towards the target at most `velocity_limit_rad_s`, the servo exerts no torque
  within +-backlash/2 of it, and a new target takes over from the previous one only after the step's random delay).

Each keeps its own per-env state, restarts envs in `reset(ids, ...)` and acts in one call per control step. Draws
are keyed on each env's seed and its own counters (`randomization`), so an env's events are the same in any batch.
"""

from __future__ import annotations

import numpy as np

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.sim import randomization

# The hold push comes this many control steps (0.5 s) after the object is first lifted in an episode: half-way
# through the 1 s hold that success needs.
HOLD_PUSH_AFTER_STEPS = spec.SUCCESS_HOLD_STEPS // 2


def set_object_force(xfrc, body: int, ids: np.ndarray, force, add: bool = False) -> None:
    """Write (or add) a force (N, world frame) on the object body of envs `ids` into the physics' applied forces."""
    rows = xfrc[ids]
    if add:
        rows[:, body, :3] += force
    else:
        rows[:, body, :3] = force
    xfrc[ids] = rows


class Pushes:
    """Table II's random force: a push of U[-0.3, 0.3] N per axis for one control step, at random times."""

    def __init__(self, dr: randomization.DomainRandomization, seeds: np.ndarray):
        self.on = dr.external_force
        self.schedule = randomization.PushSchedule(dr, seeds)

    def reset(self, ids: np.ndarray) -> None:
        if self.on:
            self.schedule.reset(ids)

    def __call__(self, xfrc, body: int) -> None:
        """Before a control step: end last step's pushes, start the ones now due."""
        if not self.on:
            return
        ended, due, force = self.schedule.step()
        if ended.size:
            set_object_force(xfrc, body, ended, 0.0)
        if due.size:
            set_object_force(xfrc, body, due, force)


class HoldPush:
    """One push of `hold_push_n` in a random 3-D direction, lasting one control period, 0.5 s into each hold."""

    def __init__(self, dr: randomization.DomainRandomization, seeds: np.ndarray):
        self.dr, self.seeds = dr, seeds
        self.given = np.zeros(len(seeds), dtype=bool)  # this episode's hold push was given
        self.pushing = np.zeros(len(seeds), dtype=bool)

    def reset(self, ids: np.ndarray) -> None:
        self.given[ids] = False
        self.pushing[ids] = False

    def start(self, xfrc, body: int, lifted_steps: np.ndarray, episode: np.ndarray) -> None:
        """After a control step: push the envs whose object has now been lifted for HOLD_PUSH_AFTER_STEPS."""
        if not self.dr.hold_push_n:
            return
        due = np.flatnonzero((lifted_steps == HOLD_PUSH_AFTER_STEPS) & ~self.given)
        if due.size:
            force = randomization.draw_hold_push(self.dr, self.seeds[due], episode[due])
            set_object_force(xfrc, body, due, force, add=True)
            self.given[due] = True
            self.pushing[due] = True

    def end(self, xfrc, body: int) -> None:
        """After the physics of the control period a push was set for: it is over."""
        ids = np.flatnonzero(self.pushing)
        if ids.size:
            set_object_force(xfrc, body, ids, 0.0)
            self.pushing[ids] = False


class ActionLatency:
    """A ring of the last k + 1 targets: the servos get the one sent k control steps ago."""

    def __init__(self, steps: int, n: int):
        self.steps = steps
        self.ring = np.zeros((steps + 1, n, spec.NUM_JOINTS))  # newest last

    def reset(self, ids: np.ndarray, q0: np.ndarray) -> None:
        self.ring[:, ids] = q0  # a late target: the servos hold the start pose until the first arrives

    def __call__(self, target: np.ndarray) -> np.ndarray:
        if not self.steps:
            return target
        self.ring = np.roll(self.ring, -1, axis=0)
        self.ring[-1] = target
        return self.ring[0].copy()


class ObservationLatency:
    """A ring of the last k + 1 observations: the policy gets the one measured k control steps ago. An episode that
    just ended reports its own final observation, and a fresh one its first, undelayed."""

    def __init__(self, steps: int):
        self.steps = steps
        self.ring: dict[str, np.ndarray] = {}  # key -> (steps + 1, n, dim), newest last

    def start(self, obs: dict[str, np.ndarray]) -> None:
        """After a full reset: every slot holds the first observation."""
        if self.steps:
            self.ring = {k: np.repeat(v[None], self.steps + 1, axis=0) for k, v in obs.items()}

    def restart(self, ids: np.ndarray, fresh: dict[str, np.ndarray]) -> None:
        """Envs `ids` auto-reset: their slots hold their new episode's first observation."""
        for k, ring in self.ring.items():
            ring[:, ids] = fresh[k]

    def __call__(self, obs: dict[str, np.ndarray], done: np.ndarray) -> dict[str, np.ndarray]:
        if not self.steps:
            return obs
        out = {}
        for k, v in obs.items():
            ring = np.roll(self.ring[k], -1, axis=0)
            ring[-1] = v
            self.ring[k] = ring
            out[k] = np.where(done[:, None], v, ring[0])
        return out


class ServoModel:
    """The servo beyond a position actuator: velocity limit, backlash and period jitter (`substep_servo`)."""

    def __init__(self, dr: randomization.DomainRandomization, seeds: np.ndarray):
        self.dr, self.seeds = dr, seeds
        n = len(seeds)
        self.setpoint = np.zeros((n, spec.NUM_JOINTS))  # velocity-limited servo setpoint
        self.last_target = np.zeros((n, spec.NUM_JOINTS))  # the target in force before this step's arrives

    @property
    def on(self) -> bool:
        return self.dr.substep_servo

    def reset(self, ids: np.ndarray, q0: np.ndarray) -> None:
        self.setpoint[ids] = q0
        self.last_target[ids] = q0

    def step(self, env, target: np.ndarray, ids: np.ndarray | None) -> np.ndarray:
        """One control period of `env`'s physics, one substep at a time; returns the envs whose physics failed."""
        dr, n_sub, dt = self.dr, env.cfg.physics.substeps, env.cfg.physics.timestep
        delay = np.zeros(env.num_envs, dtype=np.int64)
        if dr.period_jitter_s:
            counter = env.episode * 100_003 + env.episode_length
            delay = randomization.draw_jitter_substeps(dr, self.seeds, counter, n_sub)
        failed = np.zeros(env.num_envs, dtype=bool)
        for k in range(n_sub):
            goal = np.where((k >= delay)[:, None], target, self.last_target)
            if dr.velocity_limit_rad_s:
                step = dr.velocity_limit_rad_s * dt
                self.setpoint = self.setpoint + np.clip(goal - self.setpoint, -step, step)
            else:
                self.setpoint = goal
            cmd = self.setpoint
            if dr.backlash_rad:
                q = env.joint_positions()
                err = cmd - q
                cmd = q + np.sign(err) * np.maximum(np.abs(err) - dr.backlash_rad / 2, 0.0)
            env.set_targets(cmd)
            failed |= env.physics.step(1) if ids is None else env.physics.step(1, ids)
        return failed
