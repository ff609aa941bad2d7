"""Teacher rollouts in the batched env, cut into finished episodes with what the dataset and curation need.

Every env runs its own episodes back to back (the env auto-resets), so no env idles while others finish. Per env,
step t logs:
- o_t: the student observation *before* the step (noisy joints + noisy forces, what the student will see);
- the action: the absolute joint targets the env commanded for Δθ_t (`info["joint_target"]`), the LeRobot action;
- r_t (`info["terms"]["task"]`) and the noise-free uniaxial forces, for curation.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.sim.env import BatchedGraspEnv

# Names of the per-episode randomization values we store (the Table II draw plus the reset's object offset).
PHYSICS_DRAW_NAMES: tuple[str, ...] = (
    "object_friction",
    "robot_friction",
    "object_mass_scale",
    "kp_scale",
    "kv_scale",
)
RANDOMIZATION_NAMES: tuple[str, ...] = PHYSICS_DRAW_NAMES + ("object_x", "object_y")


@dataclass
class Episode:
    """One finished rollout of one env."""

    object_name: str
    state: np.ndarray  # (T, 12) float32, o_t before each step
    action: np.ndarray  # (T, 9) float32, absolute joint targets (rad)
    task_reward: np.ndarray  # (T,) r_t after each step
    uniaxial_force: np.ndarray  # (T, 3) noise-free, after the deadband (N)
    success: bool  # env's success latch: lifted >= 1.5 cm and held >= 1 s within the rollout
    left_workspace: bool  # terminated early: the object left the 10 cm workspace
    physics_failed: bool  # the physics went unstable; such episodes are never written
    env_seed: int
    env_episode: int  # the env's episode counter; (env_seed, env_episode) reproduces the reset draw
    randomization: np.ndarray  # (len(RANDOMIZATION_NAMES),) float

    @property
    def length(self) -> int:
        return int(self.task_reward.shape[0])


TeacherFn = Callable[[dict[str, np.ndarray]], np.ndarray]


def run_episodes(env: BatchedGraspEnv, act: TeacherFn, should_stop: Callable[[], bool]) -> Iterator[Episode]:
    """Step `env` with `act` and yield episodes as they finish, until `should_stop()` is true between steps.

    Episodes still running when it stops are dropped (they are not finished demonstrations).
    """
    if not env.cfg.autoreset:
        raise ValueError("demo rollouts need an auto-resetting env (GraspEnvConfig.autoreset=True)")
    n, horizon = env.num_envs, env.max_episode_steps
    rows = np.arange(n)
    state = np.zeros((n, horizon, spec.STATE_DIM), dtype=np.float32)
    action = np.zeros((n, horizon, spec.ACTION_DIM), dtype=np.float32)
    task = np.zeros((n, horizon), dtype=np.float64)
    force = np.zeros((n, horizon, spec.NUM_FORCES), dtype=np.float64)
    failed = np.zeros(n, dtype=bool)

    obs = env.reset()
    start_xy = env.object_position()[:, :2]
    start_episode = env.episode.copy()
    while not should_stop():
        t = env.episode_length.copy()  # this step's index in each env's episode (the env resets it on done)
        state[rows, t] = obs["policy"]
        obs, _, _, _, info = env.step(act(obs))
        action[rows, t] = info["joint_target"]
        task[rows, t] = info["terms"]["task"]
        force[rows, t] = info["uniaxial_force"]
        failed |= info["physics_failed"]
        final = info.get("final")
        if final is None:
            continue
        ids = final["env_ids"]
        fresh_xy = env.object_position()[ids, :2]  # after the auto-reset: the next episodes' start
        for k, i in enumerate(ids):
            length = int(final["episode_length"][k])
            draw = env.physics_draw.row(i)
            yield Episode(
                object_name=env.object_names[i],
                state=state[i, :length].copy(),
                action=action[i, :length].copy(),
                task_reward=task[i, :length].copy(),
                uniaxial_force=force[i, :length].copy(),
                success=bool(final["success"][k]),
                left_workspace=bool(final["terminated"][k]) and not failed[i],
                physics_failed=bool(failed[i]),
                env_seed=int(env.env_seeds[i]),
                env_episode=int(start_episode[i]),
                randomization=np.array([*(draw[p] for p in PHYSICS_DRAW_NAMES), *start_xy[i]], dtype=np.float64),
            )
        failed[ids] = False
        start_xy[ids] = fresh_xy
        start_episode[ids] = env.episode[ids]
