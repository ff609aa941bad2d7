"""The blind-approach teachers (teacher/blind_approach.py): the actor sees nothing of the object until a touch (or
until some steps of touch), and the calibration-blind one reads its fingertips from the measured joints."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from lerobot_blindgrasp import shipped, spec
from lerobot_blindgrasp.presets import teacher as presets
from lerobot_blindgrasp.sim import randomization
from lerobot_blindgrasp.sim.batched_config import GraspEnvConfig
from lerobot_blindgrasp.sim.batched_env import BatchedGraspEnv
from lerobot_blindgrasp.teacher import blind_approach
from lerobot_blindgrasp.teacher.policy import TeacherPolicy
from lerobot_blindgrasp.teacher.vecenv import RslRlGraspEnv

S = spec.PRIVILEGED_SLICES
UNI = S["uniaxial_force"]


def _touch(priv: np.ndarray, rows, newtons: float = 5.0) -> np.ndarray:
    priv = priv.copy()
    priv[rows, UNI.start] = newtons  # one tip reads a touch
    return priv


def test_mask_hides_exactly_the_object_state_until_a_load_cell_reads_a_touch():
    rng = np.random.default_rng(0)
    priv = rng.normal(size=(4, spec.PRIVILEGED_DIM)).astype(np.float32)
    priv[:, UNI] = [0.0, 0.3, 1.9]  # below TOUCH_N: noise and a light brush
    priv = _touch(priv, [2, 3])
    before = priv.copy()
    out = blind_approach.BlindGroup().mask(priv)
    np.testing.assert_array_equal(priv, before)  # the input is not changed
    hidden = np.zeros(spec.PRIVILEGED_DIM, bool)
    for name in blind_approach.HIDDEN:
        hidden[S[name]] = True
    assert hidden.sum() == 3 + 4 + 3 + 3 + 1
    assert (out[:2][:, hidden] == 0).all() and (out[:2][:, ~hidden] == priv[:2][:, ~hidden]).all()
    np.testing.assert_array_equal(out[2:], priv[2:])  # touching: everything seen


def test_shipped_blind_teacher_acts_the_same_wherever_the_object_is_until_it_touches():
    teacher = TeacherPolicy(shipped.path("teacher_cpu_bc_calib"))
    plain = TeacherPolicy(shipped.path("teacher_cpu_bc"))
    assert teacher.obs_groups["actor"] == [blind_approach.GROUP]
    assert teacher.config["preset"] == presets.CPU_BC_CALIB_BLIND.name
    assert teacher.actor_input == presets.CPU_BC_CALIB_BLIND.actor_input
    env = BatchedGraspEnv(
        GraspEnvConfig(
            num_envs=4, objects=("capsule_small",), seed=spec.DEMO_SEED, dr=randomization.EVAL_DR, nthread=1
        )
    )
    obs = env.reset()
    env.close()
    assert (obs["privileged"][:, UNI] < blind_approach.TOUCH_N).all()
    moved = obs["privileged"].copy()
    moved[:, S["object_pos"].start] += 0.02  # the object 2 cm further along x
    moved[:, S["object_quat"]] = [0.0, 0.0, 0.0, 1.0]  # and turned
    again = {**obs, "privileged": moved}
    np.testing.assert_array_equal(teacher(obs), teacher(again))
    assert np.abs(plain(obs) - plain(again)).max() > 1e-3  # the shipped teacher steers by it

    # Revealed after more than reveal_delay_steps consecutive touching steps (one fresh teacher per trajectory:
    # the touch counts are per env batch).
    def after_touching(priv: np.ndarray, steps: int) -> np.ndarray:
        t = TeacherPolicy(shipped.path("teacher_cpu_bc_calib"))
        priv = _touch(priv, slice(None))
        for k in range(steps):
            priv[:, S["previous_action"]] = 0.01 * (k + 1)  # no longer an episode's first step
            a = t({**obs, "privileged": priv.copy()})
        return a

    delay = teacher.actor_input.reveal_delay_steps
    np.testing.assert_array_equal(after_touching(obs["privileged"], delay), after_touching(moved, delay))
    assert np.abs(after_touching(obs["privileged"], delay + 1) - after_touching(moved, delay + 1)).max() > 1e-3


def test_the_blind_group_flows_from_the_env_through_ppo_to_the_loaded_teacher(tmp_path, monkeypatch):
    env = BatchedGraspEnv(GraspEnvConfig(num_envs=6, seed=0, episode_s=0.25, dr=randomization.NO_DR, nthread=1))
    assert blind_approach.GROUP not in RslRlGraspEnv(env).get_observations().keys()  # only when a model reads it
    actor_input = blind_approach.ActorInput(reveal_delay_steps=2, fingertips_from_joints=True)
    obs = RslRlGraspEnv(env, blind_group=actor_input).get_observations()
    np.testing.assert_array_equal(
        obs[blind_approach.GROUP].numpy(), blind_approach.BlindGroup(actor_input).mask(obs["privileged"].numpy())
    )
    env.close()
    # A one-iteration run of a small preset whose actor reads the blind group; the run records its actor input,
    # the loaded teacher applies it by itself, and a resume under another actor input is refused.
    from lerobot_blindgrasp.teacher import train

    runner = presets.QUICK.runner_cfg()
    runner["obs_groups"] = presets.CPU_BC_BLIND_APPROACH.runner["obs_groups"]
    quick_blind = replace(
        presets.QUICK, name="quick_blind", runner=runner, actor_input=actor_input, joint_calibration_rad=0.05
    )
    monkeypatch.setitem(presets.TEACHER_PRESETS, "quick_blind", quick_blind)
    assert train.build_env_config(quick_blind, 18, 0).dr.joint_calibration_rad == 0.05
    train.train(
        train.TrainTeacherConfig(
            output_dir=tmp_path, preset="quick_blind", iterations=1, num_envs=18, threads=1, export=False
        )
    )
    teacher = TeacherPolicy(tmp_path)
    assert teacher.actor_input == actor_input and teacher.config["joint_calibration_rad"] == 0.05
    monkeypatch.setitem(
        presets.TEACHER_PRESETS, "quick_blind", replace(quick_blind, actor_input=blind_approach.ActorInput())
    )
    with pytest.raises(SystemExit, match="actor_input"):
        train.train(
            train.TrainTeacherConfig(
                output_dir=tmp_path, preset="quick_blind", iterations=2, num_envs=18, threads=1, export=False
            )
        )
    priv = np.random.default_rng(1).normal(size=(3, spec.PRIVILEGED_DIM)).astype(np.float32)
    priv[:, UNI] = 0.0
    moved = priv.copy()
    moved[:, S["object_pos"]] += 0.05
    moved[:, S["fingertip_pos"]] += 0.01  # not read: the tips come from the joints
    state = np.zeros((3, spec.STATE_DIM), np.float32)
    a = teacher({"policy": state, "privileged": priv})
    np.testing.assert_array_equal(a, teacher({"policy": state, "privileged": moved}))
    assert a.shape == (3, spec.NUM_JOINTS) and np.isfinite(a).all()


def test_blind_preset_continues_the_shipped_teachers_run_with_an_asymmetric_actor_critic():
    p = presets.TEACHER_PRESETS["cpu_bc_blind_approach"]
    assert p.stages[-1] == (presets.CPU_BC_CAPSULE.name, presets.CPU_BC_CAPSULE.max_iterations)
    assert p.runner["obs_groups"] == {"actor": [blind_approach.GROUP], "critic": ["privileged"]}
    assert p.object_weights == presets.CPU_BC_CAPSULE.object_weights
    assert p.max_iterations - presets.CPU_BC_CAPSULE.max_iterations == 250
    assert "until a fingertip load cell" in p.deviations[-1]


def test_blind_presets_chain_reveal6_then_calibration_blind():
    r6, cal = presets.TEACHER_PRESETS["cpu_bc_blind_reveal6"], presets.TEACHER_PRESETS["cpu_bc_calib_blind"]
    assert r6.stages[-1] == (presets.CPU_BC_BLIND_APPROACH.name, presets.CPU_BC_BLIND_APPROACH.max_iterations)
    assert cal.stages[-1] == (r6.name, r6.max_iterations) and (r6.max_iterations, cal.max_iterations) == (
        2550,
        2950,
    )
    assert r6.actor_input == blind_approach.ActorInput(reveal_delay_steps=6) and r6.joint_calibration_rad == 0
    assert cal.actor_input == blind_approach.ActorInput(reveal_delay_steps=6, fingertips_from_joints=True)
    assert (
        cal.joint_calibration_rad == 0.05
        and presets.CPU_BC_BLIND_APPROACH.actor_input == blind_approach.ActorInput()
    )
    assert cal.deviations[:-1] == r6.deviations and "measured joint" in cal.deviations[-1]
    with pytest.raises(ValueError, match="reveal_delay_steps"):
        blind_approach.ActorInput(reveal_delay_steps=-1)


def test_the_reveal_waits_for_more_than_delay_consecutive_touching_steps_and_resets_with_the_episode():
    group = blind_approach.BlindGroup(blind_approach.ActorInput(reveal_delay_steps=2))
    priv = np.ones((3, spec.PRIVILEGED_DIM), np.float32)  # previous action 1: mid-episode
    obj = S["object_pos"]
    touch = [[9, 0, 0], [9, 0, 0], [0, 0, 0]]  # envs 0, 1 touch; env 2 does not
    seen = []
    for step in range(5):
        p = priv.copy()
        p[:, UNI] = touch
        p[:, S["previous_action"]] = step + 1
        if step == 3:
            p[1, UNI] = 0.0  # env 1 loses the contact for one step
        if step == 4:
            p[0, S["previous_action"]] = 0.0  # env 0 was reset: its first step, touching again
        seen.append((group.mask(p)[:, obj] != 0).all(axis=1))
    seen = np.array(seen)  # (steps, envs): whether the object is revealed
    np.testing.assert_array_equal(seen[:, 0], [False, False, True, True, False])  # 3rd touching step; reset hides
    np.testing.assert_array_equal(seen[:, 1], [False, False, True, False, False])  # a lost touch starts over
    assert not seen[:, 2].any()
    again = p.copy()
    np.testing.assert_array_equal(group.mask(again), group.mask(p))  # the same step asked twice counts once


def test_first_steps_are_exactly_the_envs_own_resets():
    """The reset signal the touch counts use (previous action exactly 0) against the env's own episode lengths,
    over auto-resets with random actions, some of which are clipped. The env writes an action into the privileged
    vector's previous_action one observation late, so an episode's first two observations carry 0."""
    env = BatchedGraspEnv(GraspEnvConfig(num_envs=6, seed=0, episode_s=0.3, dr=randomization.EVAL_DR, nthread=1))
    obs = env.reset()
    rng = np.random.default_rng(0)
    starts = 0
    for _ in range(20):
        first = blind_approach.first_steps(obs["privileged"])
        np.testing.assert_array_equal(first, env.episode_length <= 1)
        starts += first.sum()
        obs, *_ = env.step(rng.uniform(-0.5, 0.5, size=(6, spec.NUM_JOINTS)))
    env.close()
    assert starts >= 6 * 3  # every env started several episodes


def test_measured_kinematics_are_the_fingertip_sensors_without_an_offset_and_the_readings_with_one():
    from lerobot_blindgrasp.teacher.blind_approach import MeasuredKinematics

    fk = MeasuredKinematics()
    for cal in (0.0, 0.05):
        dr = replace(randomization.EVAL_DR, joint_calibration_rad=cal, joint_noise_rad=0.0)
        env = BatchedGraspEnv(GraspEnvConfig(num_envs=6, seed=3, dr=dr, nthread=1))
        priv = env.reset()["privileged"]
        for _ in range(3):  # fingers at rest after a few zero steps
            priv = env.step(np.zeros((6, spec.NUM_JOINTS)))[0]["privileged"]
        env.close()
        out = fk(priv)
        gap = np.abs(out[:, S["fingertip_pos"]] - priv[:, S["fingertip_pos"]]).max()
        np.testing.assert_array_equal(out[:, S["joint_pos"]], priv[:, S["joint_pos"]])  # only the tips change
        quat = out[:, S["fingertip_quat"]].reshape(-1, 4)
        np.testing.assert_allclose(np.linalg.norm(quat, axis=1), 1.0, atol=1e-6)
        if cal == 0.0:
            assert gap < 2e-4, gap  # the sensors' poses, to a fraction of a millimetre
            np.testing.assert_allclose(quat, priv[:, S["fingertip_quat"]].reshape(-1, 4), atol=2e-3)
        else:
            assert gap > 2e-3, (
                gap
            )  # 0.05 rad on three joints moves a tip by millimetres: what the true pose betrays
