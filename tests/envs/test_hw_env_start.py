"""`--env.start_pose=sim`: a real trial starts where the sim env starts the same evaluation index on the same object
(the start pose plus the sim's drawn joint offsets), so that the physics twin's runs compare like for like."""

from __future__ import annotations

import numpy as np
from emulators.harness import trial_env

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.envs.real_trial import sim_start_pose
from lerobot_blindgrasp.sim import observations
from lerobot_blindgrasp.sim.gym_env import BlindGraspGymEnv

OBJECT = "sphere_medium"


def test_the_sim_start_pose_is_the_sim_envs_own_start_state():
    sim = BlindGraspGymEnv(OBJECT, render_mode=None)
    try:
        for seed in (0, 7):
            sim.reset(seed=seed)
            q0 = sim._sim._qpos[0, observations.JOINTS]
            np.testing.assert_allclose(sim_start_pose(OBJECT, seed), q0, atol=1e-12)
            assert np.abs(q0 - spec.HOME_POSE).max() > 0.05  # the draw moved it off the home pose
    finally:
        sim.close()


def test_a_real_trial_starts_at_the_sim_start_pose(calibrated):
    env = trial_env(
        calibrated, OBJECT, success_mode="force", start_pose="sim", unattended_reset_s=0.0, episode_s=0.1
    )
    try:
        obs, _ = env.reset(seed=7)
    finally:
        env.close()
    q = obs["agent_pos"][: spec.NUM_JOINTS]
    np.testing.assert_allclose(q, sim_start_pose(OBJECT, 7), atol=env.cfg.home_tolerance_rad)
