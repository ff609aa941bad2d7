"""lerobot-eval's shared-sim vector env gives, step for step, what a sync vector env of frozen one-env sims gives."""

from functools import partial

import gymnasium as gym
import numpy as np
from lerobot.envs.utils import NEW_ROLLOUT_OPTION, freeze_after_episode_end

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.envs import BlindGraspEnvConfig
from lerobot_blindgrasp.envs.sim_vector import SharedSimVectorEnv
from lerobot_blindgrasp.sim import gym_env


def _rollout(vec, seeds, steps):
    """lerobot-eval's use: a seeded reset, then the same actions every time (env 0 flails, the others creep)."""
    obs, info = vec.reset(seed=seeds, options={NEW_ROLLOUT_OPTION: True})
    rng = np.random.default_rng(0)
    trace = [(obs["agent_pos"], info["env_seed"])]
    for _ in range(steps):
        q = obs["agent_pos"][:, : spec.NUM_JOINTS]
        action = q + rng.uniform(-0.05, 0.05, q.shape)
        action[0] = rng.uniform(spec.JOINT_LOWER, spec.JOINT_UPPER)
        obs, reward, terminated, truncated, info = vec.step(action.astype(np.float32))
        trace.append((obs["agent_pos"], reward, terminated, truncated, info["is_success"], info["lift_m"]))
    return trace


def test_the_shared_sim_replays_the_frozen_one_env_sims_exactly():
    cfg = BlindGraspEnvConfig(task="sphere_small")
    fns = [partial(gym_env.make_env, "sphere_small", **cfg.env_kwargs(i)) for i in range(3)]
    frozen = gym.vector.SyncVectorEnv(
        [freeze_after_episode_end(fn) for fn in fns], autoreset_mode=gym.vector.AutoresetMode.NEXT_STEP
    )
    shared = SharedSimVectorEnv(fns)
    steps = spec.EPISODE_STEPS + 3  # past the time limit: truncation and the frozen tail
    a, b = _rollout(frozen, [1000, 1001, 1002], steps), _rollout(shared, [1000, 1001, 1002], steps)
    ends = [t for t, row in enumerate(a[1:], 1) if row[2].any() or row[3].any()]
    assert ends[0] < spec.EPISODE_STEPS and a[ends[0]][2][0]  # the flailing env terminated early
    assert a[spec.EPISODE_STEPS][3][1:].all()  # the others ran into the time limit
    for t, (x, y) in enumerate(zip(a, b, strict=True)):
        for u, v in zip(x, y, strict=True):
            np.testing.assert_array_equal(u, v, err_msg=f"step {t}")
    # A second rollout on the same vector env starts afresh from its seeds.
    c = _rollout(shared, [1000, 1001, 1002], 5)
    for x, y in zip(a[:6], c, strict=True):
        for u, v in zip(x, y, strict=True):
            np.testing.assert_array_equal(u, v)
    assert shared.envs[0].render().shape == (240, 320, 3)
    frozen.close()
    shared.close()


def test_create_envs_shares_one_sim_per_object():
    vec = BlindGraspEnvConfig(task="cylinder_a_medium").create_envs(n_envs=2)["blindgrasp"]
    [env] = vec.values()
    assert isinstance(env, SharedSimVectorEnv)
    env.reset(seed=[1000, 1001])
    assert env.envs[0].unwrapped._sim is env.envs[1].unwrapped._sim
    # What lerobot-eval reads off a vector env besides reset and step.
    assert env.call("_max_episode_steps") == (spec.EPISODE_STEPS,) * 2
    assert len(set(env.call("task_description"))) == 1
    assert env.unwrapped.metadata["render_fps"] == env.envs[0].metadata["render_fps"]
    env.close()
