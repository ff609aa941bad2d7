"""The one episode loop (`run_batch`: one episode per env; `stream`: auto-resetting envs, until stopped) and its
outcome record, `Episode`, whose `traces` hold what was recorded at each step (`TRACES`, and the caller's labels).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, fields

import numpy as np

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.sim import randomization
from lerobot_blindgrasp.sim.batched_env import BatchedGraspEnv
from lerobot_blindgrasp.sim.host import on_host

# Names of the per-episode randomization values an episode keeps (the Table II draw plus the reset's object offset).
PHYSICS_DRAW_NAMES: tuple[str, ...] = tuple(f.name for f in fields(randomization.PhysicsDraw))
RANDOMIZATION_NAMES: tuple[str, ...] = PHYSICS_DRAW_NAMES + ("object_x", "object_y")

# What the loop can record at every step: name -> (width, dtype). "state" is o_t before the step; the others are
# read from the step's info (_FROM_INFO).
TRACES: dict[str, tuple[int, type]] = {
    "state": (spec.STATE_DIM, np.float32),  # o_t before each step, what the student sees
    "action": (spec.ACTION_DIM, np.float32),  # absolute joint targets the env commanded (the LeRobot action)
    "task_reward": (1, np.float64),  # r_t after each step
    "uniaxial_force": (spec.NUM_FORCES, np.float64),  # noise-free, after the deadband (N)
    "lift": (1, np.float64),  # object height above its rest (m)
    "tip_object_force": (spec.NUM_FORCES, np.float64),  # |net force| of each tip on the object (N)
    "tip_object_downward": (spec.NUM_FORCES, np.float64),  # its -F_z/|F| (1: pressing straight down)
}
_FROM_INFO = {
    "action": lambda info: info["joint_target"],
    "task_reward": lambda info: info["terms"]["task"],
    "uniaxial_force": lambda info: info["uniaxial_force"],
    "lift": lambda info: info["lift"],
    "tip_object_force": lambda info: info["tip_object_force"],
    "tip_object_downward": lambda info: info["tip_object_downward"],
}

Actor = Callable[[dict[str, np.ndarray], BatchedGraspEnv], np.ndarray]  # (obs, env) -> delta-theta (n, 9)
# Extra traces the caller computes before each step: name -> (width, fn(obs, env) -> (n, width)).
Labels = dict[str, tuple[int, Callable[[dict[str, np.ndarray], BatchedGraspEnv], np.ndarray]]]


@dataclass
class Episode:
    """One finished episode of one env: what happened, and what was recorded of it."""

    object_name: str
    success: bool  # lifted >= 1.5 cm and held >= 1 s (the env's latch)
    left_workspace: bool  # terminated early: the object left the 10 cm workspace
    physics_failed: bool  # the physics went unstable
    length: int  # control steps
    max_lift: float  # highest lift while the episode ran (m)
    env_seed: int
    env_episode: int  # the env's episode counter: (env_seed, env_episode) reproduces the reset draw
    randomization: np.ndarray  # (len(RANDOMIZATION_NAMES),) the physics draw and the object's start offset
    traces: dict[str, np.ndarray] = field(default_factory=dict)  # name -> (length, width)

    # the recorded traces a demo dataset and curation read, by name
    state = property(lambda self: self.traces["state"])
    action = property(lambda self: self.traces["action"])
    task_reward = property(lambda self: self.traces["task_reward"])
    uniaxial_force = property(lambda self: self.traces["uniaxial_force"])


class _Recorder:
    """Per-env buffers of the recorded quantities over one episode's horizon."""

    def __init__(self, env: BatchedGraspEnv, names: tuple[str, ...], labels: Labels):
        n, horizon = env.num_envs, env.max_episode_steps
        unknown = set(names) - set(TRACES)
        if unknown:
            raise ValueError(f"unknown traces {sorted(unknown)}; choose from {', '.join(TRACES)}")
        self.names, self.labels, self.rows = names, labels, np.arange(n)
        shapes = {k: TRACES[k] for k in names} | {k: (w, np.float32) for k, (w, _) in labels.items()}
        self.buf = {k: np.zeros((n, horizon, w), dtype=d) for k, (w, d) in shapes.items()}

    def before(self, t: np.ndarray, obs: dict, env: BatchedGraspEnv) -> None:
        if "state" in self.buf:
            self.buf["state"][self.rows, t] = obs["policy"]
        for k, (_, fn) in self.labels.items():
            self.buf[k][self.rows, t] = fn(obs, env)

    def after(self, t: np.ndarray, info: dict) -> None:
        for k in self.names:
            if k != "state":
                self.buf[k][self.rows, t] = np.reshape(_FROM_INFO[k](info), (len(self.rows), -1))

    def cut(self, i: int, length: int) -> dict[str, np.ndarray]:
        out = {k: v[i, :length].copy() for k, v in self.buf.items()}
        for k, v in out.items():
            if v.shape[1] == 1 and k in TRACES:  # scalars per step as (length,)
                out[k] = v[:, 0]
        return out


def _draw(env: BatchedGraspEnv, i: int, start_xy: np.ndarray) -> np.ndarray:
    row = env.physics_draw.row(i)
    return np.array([*(row[p] for p in PHYSICS_DRAW_NAMES), *start_xy[i]], dtype=np.float64)


def run_batch(
    env: BatchedGraspEnv,
    act: Actor,
    *,
    skip_final: bool = False,
    record: tuple[str, ...] = (),
    labels: Labels | None = None,
) -> list[Episode]:
    """One episode per env of an env without auto-reset, under `act`, until every one has ended (or, with
    `skip_final`, until every outcome is final). Returns the episodes in env order and closes the env."""
    if env.cfg.autoreset:
        raise ValueError("run_batch needs an env without auto-reset (one episode per env)")
    n, horizon = env.num_envs, env.max_episode_steps
    rec = _Recorder(env, record, labels or {})
    alive, success, left, failed = (np.zeros(n, bool) for _ in range(4))
    alive[:] = True
    length, max_lift = np.full(n, horizon), np.zeros(n)
    obs = env.reset()
    start_xy = env.object_position()[:, :2].copy()
    for t in range(horizon):
        rec.before(t, obs, env)
        delta = act(obs, env)
        obs, _, term, trunc, info = env.step(delta, active=(alive & ~success) if skip_final else None)
        rec.after(t, info)
        success |= info["success"] & alive
        max_lift = np.where(alive, np.maximum(max_lift, info["lift"]), max_lift)
        failed |= info["physics_failed"] & alive
        ended = alive & (term | trunc)
        left |= ended & term & ~failed
        length[ended] = t + 1
        alive &= ~(term | trunc)
        if not (alive & ~success if skip_final else alive).any():
            break
    episodes = [
        Episode(
            object_name=env.object_names[i],
            success=bool(success[i]),
            left_workspace=bool(left[i]),
            physics_failed=bool(failed[i]),
            length=int(length[i]),
            max_lift=float(max_lift[i]),
            env_seed=int(env.env_seeds[i]),
            env_episode=int(env.episode[i]),
            randomization=_draw(env, i, start_xy),
            traces=rec.cut(i, int(length[i])),
        )
        for i in range(n)
    ]
    env.close()
    return episodes


def stream(
    env: BatchedGraspEnv, act: Actor, should_stop: Callable[[], bool], *, record: tuple[str, ...] = ()
) -> Iterator[Episode]:
    """Step an auto-resetting env under `act` and yield episodes as they finish, until `should_stop()` is true
    between steps. Episodes still running then are dropped (they did not finish)."""
    if not env.cfg.autoreset:
        raise ValueError("stream needs an auto-resetting env (GraspEnvConfig.autoreset=True)")
    rec = _Recorder(env, record, {})
    failed, max_lift = np.zeros(env.num_envs, dtype=bool), np.zeros(env.num_envs)
    obs = env.reset()
    start_xy = env.object_position()[:, :2].copy()
    start_episode = on_host(env.episode).copy()
    while not should_stop():
        t = on_host(env.episode_length).copy()  # this step's index in each env's episode
        rec.before(t, obs, env)
        obs, _, _, _, info = env.step(act(obs, env))
        rec.after(t, info)
        failed |= info["physics_failed"]
        max_lift = np.maximum(max_lift, info["lift"])
        final = info.get("final")
        if final is None:
            continue
        ids = final["env_ids"]
        fresh_xy = env.object_position()[ids, :2]  # after the auto-reset: the next episodes' start
        for k, i in enumerate(ids):
            length = int(final["episode_length"][k])
            yield Episode(
                object_name=env.object_names[i],
                success=bool(final["success"][k]),
                left_workspace=bool(final["terminated"][k]) and not failed[i],
                physics_failed=bool(failed[i]),
                length=length,
                max_lift=float(max_lift[i]),
                env_seed=int(env.env_seeds[i]),
                env_episode=int(start_episode[i]),
                randomization=_draw(env, i, start_xy),
                traces=rec.cut(i, length),
            )
        failed[ids], max_lift[ids] = False, 0.0
        start_xy[ids] = fresh_xy
        start_episode[ids] = on_host(env.episode)[ids]
