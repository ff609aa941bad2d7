"""Physics checks of the robustness factors (`DomainRandomization` fields beyond Table II): each one does what a real
gripper with that error would do, and nothing at its default."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.hardware import xm430
from lerobot_blindgrasp.sim import objects, randomization
from lerobot_blindgrasp.sim.batched_config import GraspEnvConfig
from lerobot_blindgrasp.sim.batched_env import BatchedGraspEnv
from lerobot_blindgrasp.sim.events import HOLD_PUSH_AFTER_STEPS
from lerobot_blindgrasp.sim.scripted import PinchLiftScript

# The paper's sensor noise but no start-state randomization: the scripted pinch needs a centred object.
QUIET = replace(
    randomization.NO_DR, joint_noise_rad=spec.JOINT_NOISE_STD_RAD, force_noise_n=spec.FORCE_NOISE_STD_N
)


def _env(dr, obj="cylinder_a_medium", seed=7):
    env = BatchedGraspEnv(GraspEnvConfig(num_envs=1, objects=(obj,), seed=seed, dr=dr, autoreset=False, nthread=1))
    return env, env.reset()


def _pinch(env, first_obs, steps):
    """Drive the scripted pinch-and-lift; returns the observations (steps + 1) and infos (steps)."""
    script = PinchLiftScript(0.03, 0.045)
    obs, infos = [first_obs], []
    for _ in range(steps):
        o, _, _, _, info = env.step(script(env.joint_positions()))
        obs.append(o)
        infos.append(info)
    return obs, infos


def test_force_gain_doubles_the_reading_of_a_held_object_and_bias_range_dead_cell_act_on_it():
    base, o0 = _env(randomization.NO_DR)
    gain, g0 = _env(replace(randomization.NO_DR, force_gain=2.0))
    obs_a, _ = _pinch(base, o0, 60)
    obs_b, _ = _pinch(gain, g0, 60)
    fa = np.array([o["policy"][0, spec.STATE_FORCE_SLICE] for o in obs_a])
    fb = np.array([o["policy"][0, spec.STATE_FORCE_SLICE] for o in obs_b])
    assert (fa[-10:] > 1.0).all()  # all three tips hold the object
    np.testing.assert_array_equal(fb, 2 * fa)  # the gain moves no physics: exactly twice the same contact
    # The teacher reads the same load cells.
    sl = spec.PRIVILEGED_SLICES["uniaxial_force"]
    np.testing.assert_array_equal(obs_b[-1]["privileged"][0, sl], 2 * obs_a[-1]["privileged"][0, sl])

    dr = replace(randomization.NO_DR, force_bias_n=2.0, force_range_n=3.0, dead_force_sensor=1)
    env, e0 = _env(dr)
    obs_c, _ = _pinch(env, e0, 60)
    fc = np.array([o["policy"][0, spec.STATE_FORCE_SLICE] for o in obs_c])
    bias = env.sensor_draw.force_bias[0].numpy()
    assert set(np.abs(bias)) == {2.0}
    np.testing.assert_allclose(fc[0, [0, 2]], bias[[0, 2]])  # free tips read the bias
    assert (fc[:, 1] == 0).all()  # the dead cell
    assert np.abs(fc).max() <= 3.0 and (np.abs(fc[-10:, [0, 2]]) == 3.0).any()  # saturated at the range
    np.testing.assert_allclose(fc[-1, [0, 2]], np.clip(fa[-1, [0, 2]] + bias[[0, 2]], -3, 3), rtol=1e-6)


def test_observation_latency_of_one_step_returns_the_previous_observation():
    now, n0 = _env(QUIET)
    late, l0 = _env(replace(QUIET, obs_latency_steps=1))
    obs_now, _ = _pinch(now, n0, 15)
    obs_late, _ = _pinch(late, l0, 15)
    for k in ("policy", "privileged"):
        np.testing.assert_array_equal(obs_late[0][k], obs_now[0][k])  # the first observation, undelayed
        for t in range(1, 16):
            np.testing.assert_array_equal(obs_late[t][k], obs_now[t - 1][k])
    np.testing.assert_array_equal(late.joint_positions(), now.joint_positions())  # same physics


def test_action_latency_applies_each_target_one_step_later():
    env, _ = _env(replace(QUIET, action_latency_steps=1))
    q0 = env.joint_positions()[0]
    rng = np.random.default_rng(0)
    sent = []
    for t in range(6):
        a = rng.uniform(-0.2, 0.2, (1, spec.NUM_JOINTS))
        sent.append(np.clip(env.joint_positions() + a, spec.JOINT_LOWER, spec.JOINT_UPPER)[0])
        _, _, _, _, info = env.step(a)
        np.testing.assert_array_equal(info["joint_target"][0], q0 if t == 0 else sent[t - 1])


def test_torque_limit_caps_the_actuator_force():
    limit = 0.25 * xm430.STALL_TORQUE_NM
    capped, _ = _env(replace(randomization.NO_DR, torque_limit_scale=0.25))
    full, _ = _env(randomization.NO_DR)
    np.testing.assert_allclose(capped.env_model(0).actuator_forcerange, [[-limit, limit]] * spec.NUM_JOINTS)
    push = np.full((1, spec.NUM_JOINTS), 0.3)  # 0.3 rad x kp 15 = 4.5 N m asked of every servo
    forces = {}
    for name, env in (("capped", capped), ("full", full)):
        env.step(push)
        _, d = env.mj_model_data(0)
        forces[name] = np.abs(d.actuator_force)
    assert forces["capped"].max() == pytest.approx(limit)  # saturated at the lower limit
    assert forces["full"].max() > 1.5 * limit  # the uncapped servo pushes harder at the same moment


def test_calibration_offset_shifts_joint_readings_not_the_true_pose():
    off, o0 = _env(replace(randomization.NO_DR, joint_calibration_rad=0.05))
    ref, r0 = _env(randomization.NO_DR)
    reading = o0["policy"][0, spec.STATE_JOINT_SLICE].astype(np.float64)
    np.testing.assert_allclose(np.abs(reading - off.joint_positions()[0]), 0.05, atol=1e-6)
    assert len(set(np.sign(off.sensor_draw.joint_offset[0].numpy()))) == 2  # signs drawn per joint
    np.testing.assert_array_equal(off.joint_positions(), ref.joint_positions())  # same true start pose
    # Holding the pose the joints report, in their own (offset) frame, leaves the true pose where it was.
    for _ in range(10):
        o, *_ = off.step(off.delta_for_target(reading[None]))
        ref.step(ref.delta_for_target(r0["policy"][:, spec.STATE_JOINT_SLICE]))
    np.testing.assert_allclose(off.joint_positions(), ref.joint_positions(), atol=1e-5)


def test_under_a_calibration_offset_the_recorded_target_is_in_the_measured_frame():
    """What a demo collected under an offset records (`info["joint_target"]`) is the target the servos were sent
    in the frame the joints read: the true target + d. Commanding it back through `delta_for_target` from the same
    state reproduces the teacher's step; without an offset it is the true target."""
    env, _ = _env(replace(randomization.NO_DR, joint_calibration_rad=0.05))
    twin, _ = _env(replace(randomization.NO_DR, joint_calibration_rad=0.05))
    step = np.full((1, spec.NUM_JOINTS), 0.1)
    q = env.joint_positions().copy()
    *_, info = env.step(step)
    true_target = np.clip(q + step, spec.JOINT_LOWER, spec.JOINT_UPPER)
    np.testing.assert_allclose(
        info["joint_target"] - env.sensor_draw.joint_offset.numpy(), true_target, atol=1e-12
    )
    twin.step(twin.delta_for_target(info["joint_target"]))  # the student's path: an absolute measured-frame target
    np.testing.assert_allclose(twin.joint_positions(), env.joint_positions(), atol=1e-9)
    plain, _ = _env(randomization.NO_DR)
    q = plain.joint_positions().copy()
    *_, info = plain.step(step)
    np.testing.assert_allclose(info["joint_target"], np.clip(q + step, spec.JOINT_LOWER, spec.JOINT_UPPER))


def test_velocity_limit_and_backlash_shape_the_servo_motion():
    slow, _ = _env(replace(randomization.NO_DR, velocity_limit_rad_s=1.0))
    fast, _ = _env(randomization.NO_DR)
    q0 = fast.joint_positions()[0]
    step = np.zeros((1, spec.NUM_JOINTS))
    step[0, 0::3] = 0.3  # the abduction joints (no gravity torque at the start pose's symmetry)
    slow.step(step)
    fast.step(step)
    moved_slow = np.abs(slow.joint_positions()[0] - q0)[0::3]
    moved_fast = np.abs(fast.joint_positions()[0] - q0)[0::3]
    assert moved_slow.max() <= 1.0 * spec.CONTROL_DT + 0.005  # at most 1 rad/s x 50 ms
    assert moved_fast.min() > 0.1

    b = 0.2
    lash, _ = _env(replace(randomization.NO_DR, backlash_rad=b))
    target = lash.joint_positions()[0] + np.where(np.arange(spec.NUM_JOINTS) % 3 == 0, 0.25, 0.0)
    for _ in range(20):
        lash.step(lash.delta_for_target(target[None]))
        fast.step(fast.delta_for_target(target[None]))
    err_lash = np.abs(lash.joint_positions()[0] - target)[0::3]
    err_fast = np.abs(fast.joint_positions()[0] - target)[0::3]
    assert err_fast.max() < 0.01
    assert (err_lash > b / 2 - 0.02).all() and (err_lash < b / 2 + 0.02).all()  # stops at the dead zone's edge


def test_period_jitter_delays_within_bounds_and_size_scales_the_object():
    seeds = np.arange(2000, dtype=np.uint64)
    d = randomization.draw_jitter_substeps(replace(QUIET, period_jitter_s=0.02), seeds, np.zeros(2000), 10)
    assert d.min() == 0 and d.max() == 4  # 0..20 ms in 5 ms substeps
    big, _ = _env(replace(randomization.NO_DR, object_size_scale=1.2))
    nominal = objects.get_object("cylinder_a_medium")
    assert big.rest_height[0] == pytest.approx(1.2 * nominal.rest_height)
    assert big.env_model(0).geom("object_geom").size[0] == pytest.approx(1.2 * nominal.size[0])


def test_hold_push_comes_once_half_way_through_the_hold():
    calm, c0 = _env(QUIET)
    pushed, p0 = _env(replace(QUIET, hold_push_n=20.0))
    _, info_c = _pinch(calm, c0, 90)
    _, info_p = _pinch(pushed, p0, 90)
    lift_c = np.array([i["lift"][0] for i in info_c])
    lift_p = np.array([i["lift"][0] for i in info_p])
    first = int(np.argmax(lift_c >= spec.SUCCESS_LIFT_M))
    push_step = first + HOLD_PUSH_AFTER_STEPS - 1  # lifted_steps reaches 10 here; the push acts in the next step
    np.testing.assert_array_equal(lift_p[: push_step + 1], lift_c[: push_step + 1])
    assert np.abs(lift_p[push_step + 1 :] - lift_c[push_step + 1 :]).max() > 1e-4
    assert pushed.hold_push.given[0]
    f = randomization.draw_hold_push(replace(QUIET, hold_push_n=5.0), np.arange(50, dtype=np.uint64), np.zeros(50))
    np.testing.assert_allclose(np.linalg.norm(f, axis=1), 5.0)


def test_defaults_are_the_paper_sim_and_bad_values_are_refused():
    for name in randomization.ROBUSTNESS_FIELDS:
        assert getattr(randomization.EVAL_DR, name) == getattr(randomization.DomainRandomization(), name)
    assert not randomization.PAPER_DR.substep_servo
    with pytest.raises(ValueError, match="force_gain"):
        randomization.DomainRandomization(force_gain=0.0)
    with pytest.raises(ValueError, match="dead_force_sensor"):
        randomization.DomainRandomization(dead_force_sensor=3)
