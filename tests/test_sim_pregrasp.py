"""Pre-grasp start states (sim/pregrasp.py): where they put the fingers, that nothing starts inside the object,
that only training presets use them, and that a closing pinch from one lifts the small capsule."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
import torch

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.presets import teacher as teacher_presets
from lerobot_blindgrasp.sim import gripper, objects, pregrasp, randomization, scripted
from lerobot_blindgrasp.sim.env import BatchedGraspEnv, GraspEnvConfig
from lerobot_blindgrasp.teacher.vecenv import RslRlGraspEnv

# The default hard objects, and two large ones whose fingers start farther out (nothing may start inside them
# either).
CHECKED = pregrasp.HARD_OBJECTS + ("cuboid_a_large", "sphere_large")
ALL = pregrasp.PregraspStarts(fraction=1.0, objects=CHECKED)


def _env(num_envs=2 * len(CHECKED), cfg=ALL, objs=CHECKED, seed=3, episode_s=spec.EPISODE_S):
    return BatchedGraspEnv(
        GraspEnvConfig(
            num_envs=num_envs,
            objects=objs,
            seed=seed,
            episode_s=episode_s,
            dr=randomization.EVAL_DR,
            pregrasp=cfg,
            nthread=1,
        )
    )


def _data(env, i):
    m = env.env_model(i)
    d = mujoco.MjData(m)
    d.qpos[:] = env._qpos[i]
    mujoco.mj_forward(m, d)
    return m, d


def test_pregrasp_tips_start_low_beside_every_object_and_nothing_starts_inside_it():
    env = _env()
    env.reset()
    assert env.pregrasp_start.all()
    q = env._qpos[:, :9]
    assert (q >= spec.JOINT_LOWER - 1e-9).all() and (q <= spec.JOINT_UPPER + 1e-9).all()
    for i in range(env.num_envs):
        m, d = _data(env, i)
        obj = objects.get_object(env.object_names[i])
        centre = d.body("object").xpos
        for c in d.contact[: d.ncon]:
            assert c.dist > -1e-4, f"{obj.name}: a geom starts {-c.dist * 1e3:.1f} mm inside another"
        for f in spec.FINGERS:
            # The tip sphere's centre, 3 mm above the tip site (TIP_CAPSULE_END vs LINK_J12_TIPSITE).
            lift = gripper.LINK_J12_TIPSITE - gripper.TIP_CAPSULE_END
            tip = d.site(f"{f}_tipsite").xpos + np.array([0.0, 0.0, lift])
            clearance = (
                np.linalg.norm(tip[:2] - centre[:2]) - pregrasp.bounding_radius(obj) - gripper.TIP_CAPSULE_RADIUS
            )
            assert ALL.gap_m[0] - 2e-3 < clearance < ALL.gap_m[1] + 2e-3, (obj.name, f, clearance)
            if obj.name in pregrasp.HARD_OBJECTS:  # almost straight fingers: tips below the small capsule's top
                assert tip[2] < 0.04, (obj.name, f, tip[2])


def test_fraction_and_object_list_choose_which_resets_start_in_a_pregrasp():
    objs = ("cuboid_a_large", "capsule_small")
    env = _env(num_envs=80, cfg=pregrasp.PregraspStarts(fraction=0.5, objects=("capsule_small",)), objs=objs)
    env.reset()
    capsule = np.array([n == "capsule_small" for n in env.object_names])
    assert not env.pregrasp_start[~capsule].any()
    assert 0.25 < env.pregrasp_start[capsule].mean() < 0.75
    # The others start from the paper's pose: exactly what an env without the option draws.
    plain = _env(num_envs=80, cfg=None, objs=objs)
    plain.reset()
    keep = ~env.pregrasp_start
    np.testing.assert_array_equal(env._qpos[keep], plain._qpos[keep])


def test_training_logs_success_from_the_paper_start_pose_apart():
    capsule_only = pregrasp.PregraspStarts(fraction=1.0, objects=("capsule_small",))
    env = _env(num_envs=4, cfg=capsule_only, objs=("capsule_small", "cuboid_a_large"), episode_s=0.1)
    assert env.max_episode_steps == 2
    vec = RslRlGraspEnv(env, device="cpu")
    vec.step(torch.zeros(4, 9))
    _, _, dones, extras = vec.step(torch.zeros(4, 9))
    assert dones.all()
    log = extras["log"]
    assert log["Metrics/success_pregrasp_start"] == 0.0 and log["Metrics/success"] == 0.0
    assert "Success/cuboid_a_large" in log and "Success/capsule_small" not in log  # per object: paper pose only


def test_closing_from_a_pregrasp_start_lifts_the_small_capsule():
    """The premise of the option: from these states a plain inward pinch (the scripted one's squeeze and lift)
    holds the capsule that the teacher only ever pressed into the table."""
    cfg = pregrasp.PregraspStarts(fraction=1.0, objects=("capsule_small",))
    env = BatchedGraspEnv(
        GraspEnvConfig(
            num_envs=3, objects=("capsule_small",), seed=0, dr=randomization.NO_DR, pregrasp=cfg, nthread=1
        )
    )
    env.reset()
    script = scripted.PinchLiftScript(objects.get_object("capsule_small").size[0], grasp_height=0.027)
    for t in range(100):
        q = env._qpos[:, :9]
        target = script.target(max(t, 15))  # skip the approach: the fingers already stand beside the capsule
        _, _, _, _, info = env.step(np.clip(target - q, -spec.ACTION_BOUND_RAD, spec.ACTION_BOUND_RAD))
    assert info["success"].all(), info["lift"]


def test_only_the_pregrasp_teacher_preset_uses_it_and_it_is_validated():
    cpu, pre = teacher_presets.CPU, teacher_presets.get_preset("cpu_pregrasp")
    assert cpu.pregrasp is None and teacher_presets.PAPER.pregrasp is None
    assert pre.pregrasp == pregrasp.PregraspStarts() and pre.runner_cfg() == cpu.runner_cfg()
    assert pre.reward == cpu.reward and pre.deviations[: len(cpu.deviations)] == cpu.deviations
    assert GraspEnvConfig().pregrasp is None  # evaluation and demo collection build envs without it
    with pytest.raises(ValueError, match="fraction"):
        pregrasp.PregraspStarts(fraction=1.5)
    with pytest.raises(ValueError, match="catalogue"):
        pregrasp.PregraspStarts(objects=("teapot",))


def test_contacts_tool_can_start_every_episode_beside_the_object():
    """`teacher.contacts --pregrasp_starts=true` asks whether a teacher lifts an object once its tips are there."""
    from lerobot_blindgrasp.analysis.contacts import ContactsConfig, env_config

    plain = env_config(ContactsConfig(episodes=3), "capsule_small")
    assert plain.pregrasp is None and plain.seed == env_config(ContactsConfig(), "capsule_small").seed
    env = BatchedGraspEnv(env_config(ContactsConfig(episodes=3, pregrasp_starts=True), "capsule_small"))
    env.reset()
    assert env.pregrasp_start.all()
