"""The blind-approach teacher (teacher/blind_approach.py): its actor sees nothing of the object until a touch."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.presets import teacher as presets
from lerobot_blindgrasp.sim import randomization
from lerobot_blindgrasp.sim.env import BatchedGraspEnv, GraspEnvConfig
from lerobot_blindgrasp.teacher import blind_approach
from lerobot_blindgrasp.teacher.policy import TeacherPolicy, models_dir
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
    out = blind_approach.mask_before_touch(priv)
    np.testing.assert_array_equal(priv, before)  # the input is not changed
    hidden = np.zeros(spec.PRIVILEGED_DIM, bool)
    for name in blind_approach.HIDDEN:
        hidden[S[name]] = True
    assert hidden.sum() == 3 + 4 + 3 + 3 + 1
    assert (out[:2][:, hidden] == 0).all() and (out[:2][:, ~hidden] == priv[:2][:, ~hidden]).all()
    np.testing.assert_array_equal(out[2:], priv[2:])  # touching: everything seen


def test_shipped_blind_teacher_acts_the_same_wherever_the_object_is_until_it_touches():
    teacher = TeacherPolicy(models_dir() / "teacher_cpu_bc_blind")
    plain = TeacherPolicy(models_dir() / "teacher_cpu_bc")
    assert teacher.obs_groups["actor"] == [blind_approach.GROUP]
    assert teacher.config["preset"] == presets.CPU_BC_BLIND_APPROACH.name
    env = BatchedGraspEnv(GraspEnvConfig(num_envs=4, objects=("capsule_small",), seed=spec.DEMO_SEED,
                                         dr=randomization.EVAL_DR, nthread=1))
    obs = env.reset()
    env.close()
    assert (obs["privileged"][:, UNI] < blind_approach.TOUCH_N).all()
    moved = obs["privileged"].copy()
    moved[:, S["object_pos"].start] += 0.02  # the object 2 cm further along x
    moved[:, S["object_quat"]] = [0.0, 0.0, 0.0, 1.0]  # and turned
    again = {**obs, "privileged": moved}
    np.testing.assert_array_equal(teacher(obs), teacher(again))
    assert np.abs(plain(obs) - plain(again)).max() > 1e-3  # the shipped teacher steers by it
    touched = {**obs, "privileged": _touch(obs["privileged"], slice(None))}
    touched_moved = {**obs, "privileged": _touch(moved, slice(None))}
    assert np.abs(teacher(touched) - teacher(touched_moved)).max() > 1e-3


def test_the_blind_group_flows_from_the_env_through_ppo_to_the_loaded_teacher(tmp_path, monkeypatch):
    env = BatchedGraspEnv(GraspEnvConfig(num_envs=6, seed=0, episode_s=0.25, dr=randomization.NO_DR, nthread=1))
    assert blind_approach.GROUP not in RslRlGraspEnv(env).get_observations().keys()  # only when a model reads it
    obs = RslRlGraspEnv(env, blind_group=True).get_observations()
    np.testing.assert_array_equal(obs[blind_approach.GROUP].numpy(),
                                  blind_approach.mask_before_touch(obs["privileged"].numpy()))
    env.close()
    # A one-iteration run of a small preset whose actor reads the blind group; the loaded teacher masks by itself.
    from lerobot_blindgrasp.teacher import train

    runner = presets.QUICK.runner_cfg()
    runner["obs_groups"] = presets.CPU_BC_BLIND_APPROACH.runner["obs_groups"]
    monkeypatch.setitem(presets.PRESETS, "quick_blind", replace(presets.QUICK, name="quick_blind", runner=runner))
    train.train(train.TrainTeacherConfig(output_dir=tmp_path, preset="quick_blind", iterations=1, num_envs=18,
                                         threads=1, export=False))
    teacher = TeacherPolicy(tmp_path)
    priv = np.random.default_rng(1).normal(size=(3, spec.PRIVILEGED_DIM)).astype(np.float32)
    priv[:, UNI] = 0.0
    moved = priv.copy()
    moved[:, S["object_pos"]] += 0.05
    state = np.zeros((3, spec.STATE_DIM), np.float32)
    a = teacher({"policy": state, "privileged": priv})
    np.testing.assert_array_equal(a, teacher({"policy": state, "privileged": moved}))
    assert a.shape == (3, spec.NUM_JOINTS) and np.isfinite(a).all()


def test_blind_preset_continues_the_shipped_teachers_run_with_an_asymmetric_actor_critic():
    p = presets.get_preset("cpu_bc_blind_approach")
    assert p.continues == (presets.CPU_BC_CAPSULE.name, presets.CPU_BC_CAPSULE.max_iterations)
    assert p.runner["obs_groups"] == {"actor": [blind_approach.GROUP], "critic": ["privileged"]}
    assert p.object_weights == presets.CPU_BC_CAPSULE.object_weights
    assert p.max_iterations - presets.CPU_BC_CAPSULE.max_iterations == 250
    assert "until a fingertip load cell" in p.deviations[-1]
