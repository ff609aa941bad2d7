"""The batched env's contract: rewards (paper eq. for r_t, r_i, r_l, r_a, r_ar), termination, time-out,
randomization ranges, seeded determinism, bad input and physics failures."""

from __future__ import annotations

import math
from dataclasses import replace

import mujoco
import numpy as np
import pytest
import torch

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.sim import objects, randomization, rewards
from lerobot_blindgrasp.sim.batched_config import GraspEnvConfig
from lerobot_blindgrasp.sim.batched_env import BatchedGraspEnv

CFG = rewards.PAPER_REWARD


# --- reward terms against hand-computed values --------------------------------------------------------------------
def _step(n: int, **given) -> rewards.StepQuantities:
    """Step quantities for n envs: zeros except what a test gives."""
    zeros = {
        "lift": np.zeros(n),
        "d_xy": np.zeros(n),
        "uniaxial_force": np.zeros((n, 3)),
        "q": np.zeros((n, 9)),
        "action": np.zeros((n, 9)),
        "prev_action": np.zeros((n, 9)),
        "tip_object_distance": np.zeros((n, 3)),
        "tip_object_force": np.zeros((n, 3)),
    }
    return rewards.StepQuantities(
        **{k: torch.as_tensor(v, dtype=torch.float64) for k, v in {**zeros, **given}.items()}
    )


def test_r_task_hand_computed():
    lift = np.array([0.0, 0.0075, 0.03, 0.05, 0.0075, 0.0075])
    d = np.array([0.0, 0.025, 0.025, 0.0, 0.12, 0.025])
    n = np.array([1, 2, 3, 1, 3, 0])
    force = (np.arange(3)[None] < n[:, None]) * 1.0  # n tips at 1 N, the rest at 0
    got = rewards.r_task(_step(6, lift=lift, d_xy=d, uniaxial_force=force), CFG)
    # h_t = 0.03: (1 - sqrt((0.03 - 0.0075)/0.03)) (1 - sqrt(0.025/0.1)) = (1 - sqrt(0.75)) * 0.5
    expected = [
        0.0,  # resting object: height factor 0
        (1 - math.sqrt(0.75)) * 0.5,
        0.5,  # at h_t: only the centring factor
        1.0,  # above h_t, centred
        0.0,  # outside the 10 cm workspace
        0.0,  # no fingertip contact
    ]
    np.testing.assert_allclose(got, expected, atol=1e-12)


def test_r_incentive_needs_all_three_contacts_above_0_1_newton():
    f = np.array([[0.2, 0.3, 5.0], [0.2, 0.3, 0.1], [0.0, 0.0, 0.0], [0.11, 0.11, 0.11]])
    np.testing.assert_array_equal(rewards.num_contacts(f), [3, 2, 0, 3])
    np.testing.assert_array_equal(rewards.r_incentive(_step(4, uniaxial_force=f), CFG), [1.0, 0.0, 0.0, 1.0])


def test_r_joint_limit_sums_violations():
    q = spec.HOME_POSE.copy()[None].repeat(2, 0)
    q[1, 0] = spec.JOINT_UPPER[0] + 0.1
    q[1, 4] = spec.JOINT_LOWER[4] - 0.05
    np.testing.assert_allclose(rewards.r_joint_limit(_step(2, q=q), CFG), [0.0, 0.15], atol=1e-12)


def test_r_action_and_rate():
    a = np.array([[0.1] * 9, [0.3, -0.3] + [0.0] * 7])
    prev = np.array([[0.0] * 9, [0.3, 0.3] + [0.0] * 7])
    s = _step(2, action=a, prev_action=prev)
    np.testing.assert_allclose(rewards.r_action(s, CFG), [0.09, 0.18])
    np.testing.assert_allclose(rewards.r_action_rate(s, CFG), [0.09, 0.36])


def test_total_uses_paper_weights_and_an_ablation_drops_a_term_by_name():
    terms = {k: np.array([1.0]) for k in rewards.TERM_NAMES}
    assert rewards.total(terms, CFG)[0] == pytest.approx(1.0 + 0.2 - 500 - 0.04 - 0.01)
    ablated = CFG.without("incentive")
    assert rewards.total(terms, ablated)[0] == pytest.approx(1.0 - 500 - 0.04 - 0.01)
    assert CFG.weight("incentive") == 0.2  # the paper's config itself is untouched
    with pytest.raises(ValueError, match="unknown reward term"):
        CFG.without("incentives")


def test_every_term_is_named_after_its_equation_and_records_round_trip():
    assert rewards.TERM_NAMES == ("task", "incentive", "joint_limit", "action", "action_rate", "reach", "touch")
    assert [fn.__name__ for fn in rewards.TERMS.values()] == [f"r_{k}" for k in rewards.TERM_NAMES]
    shaped = replace(CFG.with_weights(reach=0.5, touch=0.5), reach_scale=20.0)
    record = shaped.as_record()
    assert record["w_reach"] == 0.5 and record["w_incentive"] == 0.2 and record["reach_scale"] == 20.0
    assert rewards.RewardConfig.from_record(record) == shaped
    # A teacher's recorded config (its teacher_config.json) reads back as the preset it was trained with.
    assert rewards.RewardConfig.from_record(CFG.as_record()) == CFG
    with pytest.raises(ValueError, match="unknown reward setting"):
        rewards.RewardConfig.from_record({**record, "touch_max_downward": 0.5})


def test_touch_counts_tips_pressing_on_the_object():
    force = np.array([[5.0, 5.0, 5.0], [0.05, 5.0, 5.0]])  # N on the object per tip
    np.testing.assert_allclose(rewards.r_touch(_step(2, tip_object_force=force), CFG), [1.0, 2 / 3])


def test_env_logs_each_term_and_reward_is_their_weighted_sum():
    env = BatchedGraspEnv(GraspEnvConfig(num_envs=4, seed=0))
    env.reset()
    a = np.full((4, 9), 0.1)
    _, r, _, _, info = env.step(a)
    assert set(info["terms"]) == set(rewards.TERM_NAMES)
    np.testing.assert_allclose(info["terms"]["action"], 0.09)
    np.testing.assert_allclose(r, rewards.total(info["terms"], CFG))


# --- episode ends ---------------------------------------------------------------------------------------------------
def test_time_out_is_reported_separately_from_termination():
    env = BatchedGraspEnv(GraspEnvConfig(num_envs=2, seed=0, episode_s=0.5, dr=randomization.NO_DR))
    env.reset()
    for t in range(10):
        _, _, term, trunc, info = env.step(np.zeros((2, 9)))
        if t < 9:
            assert not trunc.any() and not term.any()
    assert trunc.all() and not term.any()
    assert info["final"]["truncated"].all()
    assert (env.episode_length == 0).all()  # auto-reset
    assert (env.episode == 1).all()


def test_object_leaving_the_workspace_terminates():
    env = BatchedGraspEnv(GraspEnvConfig(num_envs=2, seed=0, dr=randomization.NO_DR))
    env.reset()
    qpos = env._qpos.clone()
    qpos[0, 9:11] = torch.tensor([0.08, 0.08])  # 11.3 cm from the centre
    env._qpos[0] = qpos[0]
    _, _, term, trunc, info = env.step(np.zeros((2, 9)))
    np.testing.assert_array_equal(term, [True, False])
    assert not trunc.any()
    assert info["final"]["env_ids"].tolist() == [0]
    assert np.linalg.norm(env.object_position()[0, :2]) < 0.01  # reset to the centre (no xy randomization)


# --- randomization ------------------------------------------------------------------------------------------------
def test_domain_randomization_stays_in_table_ii_ranges():
    dr = randomization.PAPER_DR
    n = 2000
    seeds = np.arange(n, dtype=np.uint64)
    p = randomization.draw_physics(dr, seeds)
    for name, (lo, hi) in {
        "object_friction": dr.object_friction,
        "robot_friction": dr.robot_friction,
        "object_mass_scale": dr.object_mass_scale,
        "kp_scale": dr.kp_scale,
        "kv_scale": dr.kv_scale,
    }.items():
        v = getattr(p, name)
        assert v.min() >= lo and v.max() <= hi, name
        assert v.max() - v.min() > 0.8 * (hi - lo), f"{name} does not cover its range"
    # Gains are log-uniform: the median scale is the geometric mean.
    assert np.median(p.kp_scale) == pytest.approx(math.sqrt(0.3 * 3.0), rel=0.1)
    q0, xy = (t.numpy() for t in randomization.draw_reset(dr, seeds, np.zeros(n, dtype=np.int64)))
    off = q0 - spec.HOME_POSE
    assert np.abs(off).max() <= math.pi / 9 and np.abs(off).max() > 0.9 * math.pi / 9
    assert np.abs(xy).max() <= 0.03 and np.abs(xy).max() > 0.028
    force, steps = (t.numpy() for t in randomization.draw_push(dr, seeds, np.zeros(n, dtype=np.int64)))
    assert np.abs(force).max() <= 0.3
    assert steps.min() >= 1 and steps.max() <= 10 * spec.CONTROL_HZ


def test_env_models_carry_their_own_randomization_draw():
    env = BatchedGraspEnv(GraspEnvConfig(num_envs=3, seed=7))
    kp = [m.actuator_gainprm[0, 0] for m in env.models]
    assert len(set(kp)) == 3
    np.testing.assert_allclose(kp, 15.0 * env.physics_draw.kp_scale)
    mass0 = objects.get_object(env.object_names[0]).mass
    np.testing.assert_allclose(env.models[0].body("object").mass[0], mass0 * env.physics_draw.object_mass_scale[0])


def test_objects_are_assigned_evenly():
    env = BatchedGraspEnv(GraspEnvConfig(num_envs=36, seed=0))
    counts = np.bincount(env.object_index, minlength=18)
    assert (counts == 2).all()


# --- determinism --------------------------------------------------------------------------------------------------
def test_env_i_of_a_batch_equals_a_single_env_with_its_seed():
    names = ("sphere_small", "cuboid_b_large", "capsule_medium")
    batch = BatchedGraspEnv(GraspEnvConfig(num_envs=3, objects=names, seed=40))
    single = BatchedGraspEnv(GraspEnvConfig(num_envs=1, objects=(names[2],), seed=42))
    ob, os_ = batch.reset(), single.reset()
    np.testing.assert_array_equal(ob["privileged"][2], os_["privileged"][0])
    rng = np.random.default_rng(1)
    for _ in range(30):
        a = rng.uniform(-0.3, 0.3, (3, 9))
        ob, rb, *_ = batch.step(a)
        os_, rs, *_ = single.step(a[2:3])
        np.testing.assert_array_equal(ob["privileged"][2], os_["privileged"][0])
        assert rb[2] == rs[0]


def test_the_noise_drawn_beside_the_physics_is_the_one_drawn_after_it():
    """On a CPU the step's observation noise is drawn in a helper thread while MuJoCo steps; the env's outputs are
    bit for bit those of drawing it on the caller's thread after the physics, resets included."""
    import threading

    from lerobot_blindgrasp.sim import rng as sim_rng

    cfg = GraspEnvConfig(num_envs=6, seed=3, nthread=1, episode_s=0.2, dr=randomization.PAPER_DR)
    beside, after = BatchedGraspEnv(cfg), BatchedGraspEnv(cfg)
    after._noise_helper = None
    drawn_in = set()
    normal = sim_rng.normal

    def recording(*args, **kwargs):
        drawn_in.add(threading.current_thread().name.split("_")[0])
        return normal(*args, **kwargs)

    actions = np.random.default_rng(0).uniform(-0.3, 0.3, (8, 6, 9))
    for env in (beside, after):
        env.reset()
        env.out = []
        with pytest.MonkeyPatch.context() as mp:
            mp.setattr(sim_rng, "normal", recording)
            env.out = [env.step_tensors(torch.as_tensor(a)) for a in actions]
    assert drawn_in == {"obs-noise", "MainThread"} and beside.episode.sum() > 0  # resets draw on the caller's
    for b, a in zip(beside.out, after.out, strict=True):
        for k in b[0]:
            assert torch.equal(b[0][k].view(torch.int32), a[0][k].view(torch.int32))  # bits, signed zeros too
        assert torch.equal(b[1], a[1]) and torch.equal(b[2], a[2]) and torch.equal(b[3], a[3])
    beside.close()
    with pytest.raises(RuntimeError, match="shutdown"):  # close() ends the helper thread
        beside._noise_helper.submit(int)


# --- bad input and physics failures ---------------------------------------------------------------------------------
def test_bad_inputs_are_rejected_clearly():
    with pytest.raises(ValueError, match="unknown object 'banana'"):
        GraspEnvConfig(objects=("banana",))
    env = BatchedGraspEnv(GraspEnvConfig(num_envs=2))
    env.reset()
    with pytest.raises(ValueError, match=r"shape \(2, 9\)"):
        env.step(np.zeros((2, 8)))
    a = np.zeros((2, 9))
    a[1, 3] = np.nan
    with pytest.raises(ValueError, match=r"NaN/inf entries for envs \[1\]"):
        env.step(a)


def test_physics_blow_up_resets_only_that_env_and_is_counted():
    env = BatchedGraspEnv(GraspEnvConfig(num_envs=3, seed=0))
    env.reset()
    for _ in range(3):
        env.step(np.zeros((3, 9)))
    qvel = env._qvel.clone()
    qvel[1, 9:] = 1e12  # a wild object velocity: MuJoCo flags the sim as unstable
    env._qvel[1] = qvel[1]
    before = env.joint_positions()
    _, r, term, _, info = env.step(np.zeros((3, 9)))
    assert env.physics_resets == 1
    np.testing.assert_array_equal(info["physics_failed"], [False, True, False])
    assert term[1] and r[1] == 0.0
    assert env.episode[1] == 1 and env.episode[0] == 0 and env.episode[2] == 0
    assert torch.isfinite(env._qpos).all()
    # The healthy envs kept stepping from where they were.
    assert np.abs(env.joint_positions()[[0, 2]] - before[[0, 2]]).max() < 0.1


# --- the backend contract -----------------------------------------------------------------------------------------
def test_batch_backend_state_is_torch_sharing_memory_with_the_physics():
    """qpos, qvel, ctrl, xfrc_applied and sensordata are float64 tensors over mujoco.batch's own rows: a physics
    step shows in them without a copy, and a write into them is what the physics steps from."""
    env = BatchedGraspEnv(GraspEnvConfig(num_envs=3, seed=0, nthread=1))
    env.reset()
    p = env.physics
    for name in ("qpos", "qvel", "ctrl", "xfrc_applied", "sensordata"):
        t, live = getattr(p, name), p.batch.bind(name)
        assert isinstance(t, torch.Tensor) and t.dtype == torch.float64 and t.device == p.device
        assert t.data_ptr() == live.__array_interface__["data"][0] and t.stride(0) * 8 == live.strides[0]
    before = p.qpos.clone()
    p.ctrl[:] = p.ctrl + 0.2  # the servos get new targets through the tensor
    failed = p.step(10)
    assert isinstance(failed, torch.Tensor) and not failed.any()
    np.testing.assert_array_equal(p.qpos.numpy(), p.batch.bind("qpos"))  # the same memory, after the step
    assert (p.qpos[:, :9] - before[:, :9]).abs().max() > 1e-3  # and the joints moved towards them
    env.close()


def test_batch_backend_reset_starts_envs_from_rest_and_leaves_the_others():
    """The reset (mj_resetData's defaults, copied into the envs' state rows) zeroes velocity, the solver's warm start
    and applied forces of the envs it resets, exactly as the batch's own reset would; the other envs keep their
    state."""
    env = BatchedGraspEnv(GraspEnvConfig(num_envs=3, seed=0, nthread=1))
    env.reset()
    p, warm = env.physics, env.physics.batch.bind("qacc_warmstart")
    p.ctrl[:] = p.ctrl + 0.2
    p.xfrc_applied[:, :, :3] = 0.3
    p.step(10)
    assert (p.qvel.abs().amax(dim=1) > 0).all()
    assert (np.abs(warm).max(axis=1) > 0).all()
    kept = p.qvel[2].clone()
    p.reset(torch.tensor([0, 1]))
    assert p.qvel[:2].abs().max() == 0 and (warm[:2] == 0).all() and p.xfrc_applied[:2].abs().max() == 0
    assert torch.equal(p.qvel[2], kept) and p.xfrc_applied[2, :, :3].abs().min() == 0.3
    rows = p.batch.state.copy()
    p.batch.reset([0, 1], stage=mujoco.mjtStage.mjSTAGE_NONE)
    np.testing.assert_array_equal(p.batch.state, rows)  # what mujoco.batch's reset writes, bit for bit
    env.close()
