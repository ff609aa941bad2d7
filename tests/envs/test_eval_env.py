"""The sim env lerobot-eval sees: the gymnasium wrapper's contract and the `--env.type=blindgrasp` config."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from lerobot.envs.configs import EnvConfig
from lerobot.envs.factory import make_env, make_env_config
from lerobot.envs.utils import NEW_ROLLOUT_OPTION, env_to_policy_features, preprocess_observation
from lerobot.utils.constants import ACTION, OBS_STATE

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.envs import BlindGraspEnvConfig
from lerobot_blindgrasp.sim import gym_env, objects, randomization
from lerobot_blindgrasp.sim.batched_config import GraspEnvConfig
from lerobot_blindgrasp.sim.batched_env import BatchedGraspEnv
from lerobot_blindgrasp.sim.objects import object_for_task_id, task_id
from lerobot_blindgrasp.sim.scripted import PinchLiftScript


def _true_q(env: gym.Env) -> np.ndarray:
    return env.unwrapped._sim.joint_positions()[0]


def _rollout(env: gym.Env, seed: int | None, actions: np.ndarray) -> np.ndarray:
    obs, _ = env.reset(seed=seed)
    out = [obs["agent_pos"]]
    for a in actions:
        obs, *_ = env.step(a)
        out.append(obs["agent_pos"])
    return np.array(out)


# --- the gymnasium wrapper ----------------------------------------------------------------------------------
def test_spaces_task_and_episode_length():
    env = gym_env.make_env("sphere_small")
    assert env.observation_space == gym.spaces.Dict(
        {"agent_pos": gym.spaces.Box(-np.inf, np.inf, (spec.STATE_DIM,), np.float32)}
    )
    assert env.action_space.shape == (spec.ACTION_DIM,) and env.action_space.dtype == np.float32
    np.testing.assert_allclose(env.action_space.low, spec.JOINT_LOWER, rtol=1e-6)
    np.testing.assert_allclose(env.action_space.high, spec.JOINT_UPPER, rtol=1e-6)
    assert env.metadata["render_fps"] == spec.CONTROL_HZ == 20
    assert env.get_wrapper_attr("_max_episode_steps") == spec.EPISODE_STEPS == 200
    assert env.get_wrapper_attr("task") == "grasp and lift the small sphere"
    assert env.get_wrapper_attr("task_description") == env.get_wrapper_attr("task")

    obs, info = env.reset(seed=0)
    assert env.observation_space.contains(obs) and info["is_success"] is False
    # o_t is the joint positions (the start pose, pi/9 of reset noise at most) followed by the three forces.
    q = obs["agent_pos"][spec.STATE_JOINT_SLICE]
    assert np.all(np.abs(q - spec.HOME_POSE) < spec.RESET_JOINT_NOISE_RAD + 0.03)
    # Holding the pose never lifts anything; the episode is truncated after exactly 10 s, not terminated.
    hold = _true_q(env).astype(np.float32)
    for t in range(1, 1000):  # noqa: B007 (t is read after the loop)
        obs, reward, terminated, truncated, info = env.step(hold)
        if terminated or truncated:
            break
    assert (t, terminated, truncated, info["is_success"]) == (spec.EPISODE_STEPS, False, True, False)


def test_action_is_an_absolute_target_clipped_to_0p3_rad_from_the_current_position():
    env = gym_env.BlindGraspGymEnv("cylinder_a_medium", dr=randomization.NO_DR)
    env.reset(seed=1)
    q = _true_q(env)
    target = q.copy()
    target[1] += 0.1  # within the bound: commanded as is
    target[4] += 1.0  # beyond: the servo gets q + 0.3
    target[7] -= 1.0
    *_, info = env.step(target.astype(np.float32))
    expected = q.copy()
    expected[1] += 0.1
    expected[4] += spec.ACTION_BOUND_RAD
    expected[7] -= spec.ACTION_BOUND_RAD
    np.testing.assert_allclose(info["joint_target"], expected, atol=1e-5)
    # And the joints follow: within one 50 ms step they move a good part of the way, in the right direction.
    moved = _true_q(env) - q
    assert moved[1] > 0.03 and moved[4] > 0.1 and moved[7] < -0.1
    # Targets beyond the joint limits are clipped to them, like the real gripper.
    for _ in range(10):
        q = _true_q(env)
        *_, info = env.step(np.full(spec.NUM_JOINTS, 5.0, dtype=np.float32))
        np.testing.assert_allclose(
            info["joint_target"], np.minimum(q + spec.ACTION_BOUND_RAD, spec.JOINT_UPPER), atol=1e-5
        )
    assert np.isclose(info["joint_target"], spec.JOINT_UPPER).sum() >= 6  # abduction and proximal got there


def _scripted_lift(**env_kwargs):
    """A pinch-and-lift of the centred medium cylinder until the episode ends: (per-step success, terminated,
    truncated, last observation, last info)."""
    env = gym_env.make_env("cylinder_a_medium", dr=randomization.CENTRED_EVAL_DR, **env_kwargs)
    env.reset(seed=0)
    script = PinchLiftScript(object_radius=0.03, grasp_height=0.045, lift_m=0.03)
    success = []
    for t in range(spec.EPISODE_STEPS):
        obs, _, terminated, truncated, info = env.step(script.target(t).astype(np.float32))
        success.append(info["is_success"])
        if terminated or truncated:
            return success, terminated, truncated, obs, info
    raise AssertionError("the episode never ended")


def test_scripted_lift_of_the_medium_cylinder_is_a_success():
    success, terminated, truncated, obs, info = _scripted_lift()
    assert truncated and not terminated
    # Success needs the lift held for 1 s: the pinch is done by step 35 and the lift by ~step 60, so success
    # latches about 20 steps later, and stays.
    first = success.index(True)
    assert 60 <= first <= 100, first
    assert all(success[first:])
    assert info["lift_m"] > spec.SUCCESS_LIFT_M
    # All three fingertips feel the object, in newtons, in what the policy sees (with noise) and in truth.
    assert np.all(info["uniaxial_force_n"] > 1.0) and np.all(obs["agent_pos"][spec.STATE_FORCE_SLICE] > 0.0)


def test_with_end_on_success_the_episode_ends_where_its_success_latches():
    """lerobot-eval's default: the same success at the same step, and the episode terminates there."""
    full, ended_full, truncated_full, _, _ = _scripted_lift(render_mode=None, end_on_success=False)
    short, ended_short, truncated_short, _, _ = _scripted_lift(render_mode=None, end_on_success=True)
    assert (ended_full, truncated_full) == (False, True) and (ended_short, truncated_short) == (True, False)
    first = full.index(True)
    assert short == full[: first + 1]  # the same rollout up to the step success latched, which ends it


def test_render_gives_rgb_frames_of_the_scene():
    with pytest.raises(RuntimeError, match="reset"):
        gym_env.BlindGraspGymEnv("cuboid_a_medium").render()
    env = gym_env.make_env("cuboid_a_medium")
    env.reset(seed=0)
    frame = env.render()
    assert frame.shape == (240, 320, 3) and frame.dtype == np.uint8
    assert frame.std() > 10  # a scene, not a blank buffer
    env.step(np.full(spec.NUM_JOINTS, 0.5, dtype=np.float32))  # fingers move: the picture changes
    assert np.abs(env.render().astype(int) - frame).mean() > 0.5
    big = gym_env.make_env("cuboid_a_medium", render_width=640, render_height=480, render_shadows=True)
    big.reset(seed=0)
    assert big.render().shape == (480, 640, 3)


def test_render_stride_repeats_frames_between_renders_and_starts_fresh_each_episode():
    with pytest.raises(ValueError, match="render_stride"):
        gym_env.make_env("cuboid_a_medium", render_stride=0)
    env = gym_env.make_env("cuboid_a_medium", render_stride=3)
    closing = np.full(spec.NUM_JOINTS, 0.5, dtype=np.float32)
    env.reset(seed=0)
    frames = [env.render()]
    for _ in range(4):
        env.step(closing)
        frames.append(env.render())
    # steps 0-2 show the step-0 frame, step 3 a new one (the fingers have moved), step 4 repeats it
    assert frames[1] is frames[0] and frames[2] is frames[0]
    assert np.abs(frames[3].astype(int) - frames[0]).mean() > 0.5 and frames[4] is frames[3]
    env.reset(seed=0)  # a new episode renders at once, not the last frame of the previous one
    assert np.array_equal(env.render(), frames[0]) and env.render() is not frames[0]
    # the lerobot-eval config passes it through
    assert BlindGraspEnvConfig(task="cuboid_a_medium", render_stride=4).gym_kwargs["render_stride"] == 4


def test_seed_makes_the_episode_reproducible():
    env = gym_env.make_env("capsule_medium")
    actions = np.random.default_rng(0).uniform(spec.JOINT_LOWER, spec.JOINT_UPPER, (15, 9)).astype(np.float32)
    a = _rollout(env, 7, actions)
    b = _rollout(env, 7, actions)
    np.testing.assert_array_equal(a, b)
    assert not np.allclose(a[0], _rollout(env, 8, actions)[0])  # another seed: another start pose and noise
    # The seed flows into the sim: episode 0 of BatchedGraspEnv with this object's eval-range seed for it.
    assert env.unwrapped._sim.cfg.seed == gym_env.start_seed(8, "capsule_medium")
    # Unseeded resets continue a seeded sequence reproducibly, and give new episodes.
    env.reset(seed=3)
    first = _rollout(env, None, actions)
    env2 = gym_env.make_env("capsule_medium")
    env2.reset(seed=3)
    np.testing.assert_array_equal(first, _rollout(env2, None, actions))
    assert not np.allclose(first[0], _rollout(env2, 3, actions)[0])


def test_each_object_gets_its_own_start_states_from_the_same_seed():
    """lerobot-eval passes the same seeds to every task; the env must not turn them into the same draws."""
    names = ("cuboid_a_medium", "cylinder_a_medium")
    sims = {}
    for name in names:
        env = gym_env.BlindGraspGymEnv(name, render_mode=None)
        _, info = env.reset(seed=1000)
        assert spec.SEED_RANGES["eval"].start <= info["env_seed"] < spec.SEED_RANGES["eval"].stop
        sims[name] = env.unwrapped._sim
    seeds = {n: int(s.env_seeds[0]) for n, s in sims.items()}
    assert seeds[names[0]] != seeds[names[1]]
    # Different physics draws (friction, gains, ...) and start poses, not just a different object.
    a, b = (sims[n] for n in names)
    assert not np.allclose(a.joint_positions(), b.joint_positions())
    ra, rb = a.physics_draw.row(0), b.physics_draw.row(0)
    assert any(not np.allclose(ra[k], rb[k]) for k in ra)
    # The same trial as the batched env's first episode with that seed (what the teacher eval builds).
    batched = BatchedGraspEnv(GraspEnvConfig(num_envs=2, objects=(names[0],), seed=seeds[names[0]] - 1,
                                             dr=randomization.EVAL_DR, autoreset=False))  # fmt: skip
    batched.reset()
    np.testing.assert_array_equal(batched.joint_positions()[1], a.joint_positions()[0])


def test_bad_input_raises_clear_errors():
    with pytest.raises(ValueError, match="unknown object"):
        gym_env.BlindGraspGymEnv("teapot")
    with pytest.raises(ValueError, match="render size"):
        gym_env.BlindGraspGymEnv(render_width=1920, render_height=1080)
    with pytest.raises(ValueError, match="render_mode"):
        gym_env.BlindGraspGymEnv(render_mode="human")
    env = gym_env.BlindGraspGymEnv()
    with pytest.raises(RuntimeError, match="reset"):
        env.step(np.zeros(9, dtype=np.float32))
    env.reset(seed=0)
    with pytest.raises(ValueError, match="9 absolute joint targets"):
        env.step(np.zeros(12, dtype=np.float32))
    with pytest.raises(ValueError, match="NaN"):
        env.step(np.full(9, np.nan, dtype=np.float32))
    with pytest.raises(ValueError, match="seed"):
        env.reset(seed=-1)
    with pytest.raises(ValueError, match="seed"):  # an index past one object's block would reach the next's
        env.reset(seed=spec.EVAL_TASK_STRIDE)


# --- --env.type=blindgrasp ----------------------------------------------------------------------------------
def test_env_config_is_registered_with_the_state_and_action_features():
    assert EnvConfig.get_choice_class("blindgrasp") is BlindGraspEnvConfig
    cfg = make_env_config("blindgrasp")
    assert cfg.fps == spec.CONTROL_HZ and cfg.task == "all" and cfg.objects == objects.PAPER_OBJECTS
    feats = env_to_policy_features(cfg)
    assert set(feats) == {OBS_STATE, ACTION}
    assert feats[OBS_STATE].shape == (spec.STATE_DIM,) and feats[ACTION].shape == (spec.ACTION_DIM,)
    with pytest.raises(ValueError, match="unknown object"):
        make_env_config("blindgrasp", task="teapot")


def test_task_ids_are_stable_catalogue_indices():
    task_ids = {task_id(n): n for n in objects.PAPER_OBJECTS}
    assert list(task_ids) == list(range(18)) and tuple(task_ids.values()) == objects.PAPER_OBJECTS
    for tid, name in task_ids.items():
        assert task_id(name) == tid and object_for_task_id(tid) == name
    with pytest.raises(ValueError):
        object_for_task_id(999)


def test_create_envs_gives_one_vector_env_per_object():
    envs = make_env(make_env_config("blindgrasp", task="all"), n_envs=1, use_async_envs=False)
    assert list(envs) == ["blindgrasp"] and sorted(envs["blindgrasp"]) == list(range(18))
    envs = make_env(make_env_config("blindgrasp", task="sphere_small,cylinder_a_medium"), n_envs=2)
    vecs = envs["blindgrasp"]
    assert sorted(vecs) == sorted([task_id("sphere_small"), task_id("cylinder_a_medium")])
    vec = vecs[task_id("sphere_small")]
    # What lerobot-eval's rollout does with it.
    obs, _ = vec.reset(seed=[1000, 1001], options={NEW_ROLLOUT_OPTION: True})
    batch = preprocess_observation(obs)
    assert batch[OBS_STATE].shape == (2, spec.STATE_DIM)
    assert not np.allclose(obs["agent_pos"][0], obs["agent_pos"][1])  # two seeds, two start poses
    assert list(vec.call("task_description")) == ["grasp and lift the small sphere"] * 2
    assert vec.call("_max_episode_steps")[0] == spec.EPISODE_STEPS
    assert vec.unwrapped.metadata["render_fps"] == spec.CONTROL_HZ
    assert vec.envs[0].render().shape == (240, 320, 3)
    _, _, _, _, info = vec.step(obs["agent_pos"][:, : spec.NUM_JOINTS])
    assert info["is_success"].shape == (2,) and not info["is_success"].any()
    vec.close()


def test_a_knocked_away_object_ends_the_episode_early_and_the_batch_runs_on():
    """What lerobot-eval does when one sub-env terminates: it keeps stepping the batch; the ended env holds."""
    envs = make_env(make_env_config("blindgrasp", task="sphere_small"), n_envs=2)
    vec = envs["blindgrasp"][task_id("sphere_small")]

    def flail():
        obs, _ = vec.reset(seed=[1000, 1001], options={NEW_ROLLOUT_OPTION: True})
        rng = np.random.default_rng(0)
        states, ended = [obs["agent_pos"]], np.full(2, -1)
        for t in range(spec.EPISODE_STEPS):
            obs, _, terminated, truncated, _ = vec.step(rng.uniform(spec.JOINT_LOWER, spec.JOINT_UPPER, (2, 9)))
            states.append(obs["agent_pos"])
            ended[(ended < 0) & terminated] = t + 1
            if (ended > 0).all():
                break
        return np.array(states), ended

    states, ended = flail()
    assert (ended > 0).all() and ended[0] != ended[1], ended  # flailing knocks the sphere out of the workspace
    first, last = np.argmin(ended), len(states) - 1
    assert np.ptp(states[ended[first] :, first], axis=0).max() == 0.0  # the ended env is frozen
    assert np.ptp(states[ended[first] :, 1 - first], axis=0).max() > 0.0  # the other one still moves
    # The next rollout starts afresh and, with the same seeds, replays exactly.
    states2, ended2 = flail()
    np.testing.assert_array_equal(ended, ended2)
    np.testing.assert_array_equal(states[:last], states2[:last])
    vec.close()


def test_the_sim_alone_bounds_the_target_as_the_old_pre_clip_did():
    """The action is bounded once in the env: the gym env hands target - q to the sim, which clips the step to
    +-0.3 rad and the servo target to the joint limits. The gym env used to clip the target to the limits first;
    against a sim stepped that old way, on targets far beyond the limits, every commanded target, observation, lift
    and success is the same to the bit (only the reward's action penalty, which charges the commanded step,
    differs: it was the step to the limit)."""
    name = "sphere_small"
    env = gym_env.BlindGraspGymEnv(name, render_mode=None)
    obs, _ = env.reset(seed=3)
    old = BatchedGraspEnv(
        GraspEnvConfig(num_envs=1, objects=(name,), seed=env.env_seed, dr=randomization.EVAL_DR, nthread=1,
                       autoreset=False)
    )  # fmt: skip
    np.testing.assert_array_equal(obs["agent_pos"], old.reset()["policy"][0])
    rng = np.random.default_rng(0)
    beyond = 0
    for t in range(80):
        q = old.joint_positions()[0]
        target = q + rng.uniform(-1.0, 1.0, spec.NUM_JOINTS)
        if t % 3 == 0:
            target = rng.choice([-3.0, 3.0], spec.NUM_JOINTS)
        target = target.astype(np.float32)
        beyond += int(((target < spec.JOINT_LOWER) | (target > spec.JOINT_UPPER)).sum())
        obs, _, terminated, truncated, info = env.step(target)
        pre_clipped = np.clip(target.astype(np.float64), spec.JOINT_LOWER, spec.JOINT_UPPER)
        old_obs, _, old_term, old_trunc, old_info = old.step((pre_clipped - q)[None])
        np.testing.assert_array_equal(info["joint_target"], old_info["joint_target"][0].astype(np.float32))
        np.testing.assert_array_equal(obs["agent_pos"], old_obs["policy"][0])
        assert (info["lift_m"], info["is_success"]) == (old_info["lift"][0], old_info["success"][0])
        assert (terminated, truncated) == (old_term[0], old_trunc[0])
        if terminated or truncated:
            break
    assert beyond > 100  # the limits were exercised
    env.close()
    old.close()


def test_sim_and_real_env_configs_share_one_definition_of_features_and_spaces():
    from lerobot_blindgrasp import spaces
    from lerobot_blindgrasp.envs.real_env import BlindGraspRealEnvConfig

    sim, real = BlindGraspEnvConfig(task="medium"), BlindGraspRealEnvConfig(task="medium", success_mode="force")
    assert sim.features == real.features == spaces.env_features()
    assert sim.features_map == real.features_map == spaces.env_features_map()
    env = gym_env.BlindGraspGymEnv("cylinder_a_medium", render_mode=None)
    assert env.observation_space == spaces.observation_space() and env.action_space == spaces.action_space()


def test_only_the_first_render_episodes_get_the_full_video_rate():
    cfg = BlindGraspEnvConfig(task="cuboid_a_medium", render_stride=4, render_episodes=2)
    assert [cfg.env_kwargs(i)["render_stride"] for i in range(4)] == [4, 4, 20, 20]
    assert (
        BlindGraspEnvConfig(task="cuboid_a_medium").env_kwargs(9)["render_stride"] == 1
    )  # LeRobot's default: all
    vec = cfg.create_envs(n_envs=3)["blindgrasp"]
    envs = next(iter(vec.values())).envs
    assert [e.unwrapped.render_stride for e in envs] == [4, 4, 20]
    with pytest.raises(ValueError, match="render_episodes"):
        BlindGraspEnvConfig(task="cuboid_a_medium", render_episodes=-1)
