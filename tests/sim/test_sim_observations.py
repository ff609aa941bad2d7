"""The privileged observation is what `spec.PRIVILEGED_LAYOUT` says it is: each named slice, read back from the env's
92-d vector, against the MuJoCo state it claims to be, computed here independently of the env's own code."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
from test_sim_physics import run_pinch_lift

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.hardware import force
from lerobot_blindgrasp.sim import randomization
from lerobot_blindgrasp.sim.batched_config import GraspEnvConfig
from lerobot_blindgrasp.sim.batched_env import BatchedGraspEnv

N = 3


@pytest.fixture(scope="module")
def pinched():
    """Noise-free envs mid-pinch (fingertips pressing on the object), with the privileged vector recomputed at
    the final state so that it and MjData describe the same instant (a step's sensors are read before its last
    integration)."""
    env = BatchedGraspEnv(
        GraspEnvConfig(
            num_envs=N, objects=("cylinder_a_medium",), dr=randomization.NO_DR, autoreset=False, nthread=1
        )
    )
    env.reset()
    run_pinch_lift(env, 40)
    action = np.tile(np.linspace(-0.5, 0.5, spec.NUM_JOINTS), (N, 1))  # some entries beyond the 0.3 rad bound
    env.step(action)
    env.physics.forward(np.arange(N))
    priv = env._observe()["privileged"].numpy().astype(np.float64)
    yield env, priv, action
    env.close()


def test_layout_is_contiguous_and_refuses_drift():
    ends = [(s.start, s.stop) for s in spec.PRIVILEGED_SLICES.values()]
    assert ends[0][0] == 0 and ends[-1][1] == spec.PRIVILEGED_DIM == 92
    assert all(a[1] == b[0] for a, b in zip(ends, ends[1:]))
    parts = {name: np.zeros((2, n)) for name, n in spec.PRIVILEGED_LAYOUT}
    assert np.concatenate(spec.privileged_parts(parts), axis=1).shape == (2, 92)
    with pytest.raises(ValueError, match="missing"):
        spec.privileged_parts({k: v for k, v in parts.items() if k != "object_quat"})
    with pytest.raises(ValueError, match="extra"):
        spec.privileged_parts({**parts, "object_colour": np.zeros((2, 1))})
    with pytest.raises(ValueError, match="object_pos"):
        spec.privileged_parts({**parts, "object_pos": np.zeros((2, 4))})


def _same_quat(a, b, atol):
    a, b = np.asarray(a), np.asarray(b)
    assert min(np.abs(a - b).max(), np.abs(a + b).max()) < atol  # q and -q are one rotation


def _force_on_tip(m, d, finger: str) -> np.ndarray:
    """World-frame force that everything touching the fingertip geom exerts on it, from MuJoCo's contact list."""
    tip = m.geom(f"{finger}_tipgeom").id
    total, f6 = np.zeros(3), np.zeros(6)
    for k in range(d.ncon):
        c = d.contact[k]
        if tip not in (c.geom1, c.geom2):
            continue
        mujoco.mj_contactForce(m, d, k, f6)
        on_geom2 = c.frame.reshape(3, 3).T @ f6[:3]  # the contact frame's normal points from geom1 to geom2
        total += on_geom2 if c.geom2 == tip else -on_geom2
    return total


def test_each_named_slice_is_the_sim_state_it_names(pinched):
    env, priv, action = pinched
    atol = 1e-5  # the observation is float32
    touching = 0
    for i in range(N):
        m, d = env.mj_model_data(i)
        part = {name: priv[i, s] for name, s in spec.PRIVILEGED_SLICES.items()}
        # The claw centre is the origin of the table plane: positions are relative to the point below it.
        centre = d.site("claw_centre").xpos * np.array([1.0, 1.0, 0.0])
        np.testing.assert_array_equal(centre, 0.0)

        np.testing.assert_allclose(part["joint_pos"], [d.joint(j).qpos[0] for j in spec.JOINT_NAMES], atol=atol)
        np.testing.assert_allclose(part["joint_vel"], [d.joint(j).qvel[0] for j in spec.JOINT_NAMES], atol=1e-4)
        tips = [d.site(f"{f}_tipsite") for f in spec.FINGERS]
        np.testing.assert_allclose(
            part["fingertip_pos"], np.concatenate([t.xpos - centre for t in tips]), atol=atol
        )
        for k, t in enumerate(tips):
            q = np.zeros(4)
            mujoco.mju_mat2Quat(q, t.xmat)
            _same_quat(part["fingertip_quat"][4 * k : 4 * k + 4], q, atol)
        body = d.body("object")
        np.testing.assert_allclose(part["object_pos"], body.xpos - centre, atol=atol)
        _same_quat(part["object_quat"], body.xquat, atol)
        vel = np.zeros(6)
        mujoco.mj_objectVelocity(m, d, mujoco.mjtObj.mjOBJ_BODY, body.id, vel, 0)
        np.testing.assert_allclose(part["object_linvel"], vel[3:], atol=1e-4)
        mujoco.mj_objectVelocity(m, d, mujoco.mjtObj.mjOBJ_BODY, body.id, vel, 1)
        np.testing.assert_allclose(part["object_angvel"], vel[:3], atol=1e-4)
        np.testing.assert_allclose(part["object_planar_distance"], [np.linalg.norm(body.xpos[:2])], atol=atol)

        for k, (f, t) in enumerate(zip(spec.FINGERS, tips)):
            on_tip = _force_on_tip(m, d, f)
            touching += np.linalg.norm(on_tip) > 0.5
            tip_frame = t.xmat.reshape(3, 3).T @ on_tip
            np.testing.assert_allclose(part["fingertip_contact_force"][3 * k : 3 * k + 3], tip_frame, atol=1e-3)
            # The load cell's z axis points from the distal joint to the tip: a push on the tip compresses it.
            z = d.site(f"{f}_loadcell").xmat.reshape(3, 3)[:, 2]
            np.testing.assert_allclose(part["uniaxial_force"][k], force.reading(-(on_tip @ z)), atol=1e-3)
            wrench = np.concatenate([d.sensor(f"{f}_force").data, d.sensor(f"{f}_torque").data])
            np.testing.assert_allclose(part["fingertip_wrench"][6 * k : 6 * k + 6], wrench, rtol=1e-5, atol=1e-4)

        clipped = np.clip(action[i], -spec.ACTION_BOUND_RAD, spec.ACTION_BOUND_RAD)
        np.testing.assert_allclose(part["previous_action"], clipped, atol=1e-7)
    assert touching >= 2 * N  # the force checks were not all zeros against zeros


def test_the_student_observation_is_the_named_joint_and_force_readings(pinched):
    env, priv, _ = pinched
    obs = env._observe()
    named = spec.PRIVILEGED_SLICES
    np.testing.assert_array_equal(
        obs["policy"][:, spec.STATE_JOINT_SLICE], obs["privileged"][:, named["joint_pos"]]
    )
    np.testing.assert_array_equal(
        obs["policy"][:, spec.STATE_FORCE_SLICE], obs["privileged"][:, named["uniaxial_force"]]
    )
