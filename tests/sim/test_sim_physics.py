"""Physics checks of the gripper model: kinematics, joint limits, force sensing in newtons, a real grasp."""

from __future__ import annotations

import math
from dataclasses import replace

import mujoco
import numpy as np
import pytest
import torch

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.hardware import force
from lerobot_blindgrasp.sim import gripper, objects, randomization, sensors
from lerobot_blindgrasp.sim.batched_config import GraspEnvConfig
from lerobot_blindgrasp.sim.batched_env import BatchedGraspEnv
from lerobot_blindgrasp.sim.scripted import PinchLiftScript


# The scripted pinch-and-lift as the physics tests run it (test_sim_warp and test_sim_observations too).
def run_pinch_lift(
    env, steps: int, object_radius: float = 0.03, grasp_height: float = 0.045, lift_m: float = 0.03
):
    """Pinch a reset `BatchedGraspEnv` for `steps` steps: lifts (steps, N), clean forces (steps, N, 3), last info."""
    script = PinchLiftScript(object_radius, grasp_height, lift_m)
    lifts, forces = [], []
    for _ in range(steps):
        _, _, _, _, info = env.step(script(env.joint_positions()))
        lifts.append(info["lift"].copy())
        forces.append(info["uniaxial_force"].copy())
    return np.array(lifts), np.array(forces), info


def _model(obj="cylinder_a_medium"):
    o = objects.get_object(obj)
    return gripper.compile_model(objects.object_mjcf(o, gripper.OBJECT_CONTYPE, gripper.OBJECT_CONAFFINITY))


def _tip_positions(m, q):
    d = mujoco.MjData(m)
    d.qpos[: spec.NUM_JOINTS] = q
    mujoco.mj_forward(m, d)
    return np.array([d.site(f"{f}_tipsite").xpos.copy() for f in spec.FINGERS])


def test_fingertip_reach_matches_dclaw_geometry():
    m = _model()
    # q = 0: every finger hangs straight down from its base on the 6 cm circle.
    tips = _tip_positions(m, np.zeros(9))
    np.testing.assert_allclose(np.linalg.norm(tips[:, :2], axis=1), gripper.BASE_RADIUS, atol=1e-6)
    below_plate = gripper.PLATE_TO_J10 + gripper.LINK_J10_J11 + gripper.LINK_J11_J12 + gripper.LINK_J12_TIPSITE
    np.testing.assert_allclose(tips[:, 2], gripper.PLATE_HEIGHT - below_plate, atol=1e-6)
    # Paper start pose (0, pi/3, 0): proximal + distal (0.144 m) tilted 60 deg outward.
    tips = _tip_positions(m, spec.HOME_POSE)
    reach = gripper.LINK_J11_J12 + gripper.LINK_J12_TIPSITE
    np.testing.assert_allclose(
        np.linalg.norm(tips[:, :2], axis=1), gripper.BASE_RADIUS + reach * math.sin(math.pi / 3), atol=1e-6
    )
    # Finger bases 120 deg apart.
    ang = np.sort(np.degrees(np.arctan2(tips[:, 1], tips[:, 0])) % 360)
    np.testing.assert_allclose(np.diff(ang), 120.0, atol=1e-4)


def test_sign_convention_j11_opens_j10_turns_ccw():
    m = _model()
    base = _tip_positions(m, np.zeros(9))[0]
    q = np.zeros(9)
    q[1] = 0.3  # ff proximal flexion > 0 -> tip moves away from the claw axis
    assert np.linalg.norm(_tip_positions(m, q)[0, :2]) > np.linalg.norm(base[:2]) + 0.01
    q = np.zeros(9)
    q[1], q[0] = 0.5, 0.3  # ff abduction > 0 -> tip turns counter-clockwise seen from above
    tip = _tip_positions(m, q)[0]
    assert math.atan2(tip[1], tip[0]) > math.radians(60) + 0.05


def test_random_actions_keep_joints_within_hard_stops_and_targets_within_limits():
    env = BatchedGraspEnv(GraspEnvConfig(num_envs=18, seed=3))
    env.reset()
    rng = np.random.default_rng(0)
    lo = spec.JOINT_LOWER - spec.HARD_STOP_MARGIN_RAD - 0.02
    hi = spec.JOINT_UPPER + spec.HARD_STOP_MARGIN_RAD + 0.02
    for _ in range(60):
        _, _, _, _, info = env.step(rng.uniform(-1, 1, (18, 9)))  # out-of-bound actions get clipped to 0.3
        q = env.joint_positions()
        assert (q >= lo).all() and (q <= hi).all()
        t = info["joint_target"]
        assert (t >= spec.JOINT_LOWER - 1e-9).all() and (t <= spec.JOINT_UPPER + 1e-9).all()
    assert env.physics_resets == 0


def test_uniaxial_sensor_reads_a_known_load_in_newtons():
    """A 200 g block pressed on a straight fingertip along its axis reads M g; a free tip reads 0.

    Gravity is flipped upward in this test scene so that the block rests *on* the downward-pointing fingertip:
    the load then acts exactly along the tip axis, as on a load cell under test.
    """
    box = objects.ObjectSpec("load", "test", "n/a", "box", (0.02, 0.02, 0.02))
    m = gripper.compile_model(objects.object_mjcf(box, gripper.OBJECT_CONTYPE, gripper.OBJECT_CONAFFINITY))
    m.geom("table").contype = m.geom("table").conaffinity = 0
    m.opt.gravity[:] = [0.0, 0.0, 9.81]
    mass = 0.2
    obj = m.body("object").id
    m.body_inertia[obj] *= mass / m.body_mass[obj]
    m.body_mass[obj] = mass
    d = mujoco.MjData(m)
    q = spec.HOME_POSE.copy()
    q[:3] = 0.0  # ff straight down; mf, th stay open, far away
    d.qpos[:9] = q
    d.ctrl[:] = q
    si = sensors.SensorIndex.from_model(m)

    def uni():
        sd = torch.from_numpy(d.sensordata[None])
        return sensors.uniaxial_force(si.read(sd, "contact"), si.read(sd, "zaxis"))[0].numpy()

    mujoco.mj_forward(m, d)
    tip_end = d.site("ff_tipsite").xpos[2] - (0.084 - gripper.LINK_J12_TIPSITE)
    d.qpos[9:12] = [d.site("ff_tipsite").xpos[0], d.site("ff_tipsite").xpos[1], tip_end - 0.0205]
    mujoco.mj_forward(m, d)
    assert np.all(np.abs(uni()) < 1e-9)  # no contact yet
    readings = []
    for _ in range(40):  # 0.2 s: settles on the tip, before the (unstable) balance tips over
        mujoco.mj_step(m, d)
        readings.append(uni()[0])
    settled = np.array(readings[20:])
    np.testing.assert_allclose(settled, mass * 9.81, rtol=0.03)
    # The tip-on-object sensor sees the same load as a push straight down on the object: |F| = M g and
    # -F_z / |F| = 1, the direction the directional touch term (rewards.r_touch_directional) refuses to pay for.
    from lerobot_blindgrasp.sim import observations

    raw, _ = observations.observe(
        *(torch.from_numpy(x[None]) for x in (d.qpos, d.qvel, d.sensordata)),
        si,
        torch.zeros(1, dtype=torch.float64),
        torch.zeros((1, 9), dtype=torch.float64),
        torch.zeros((1, observations.NOISE_DIM), dtype=torch.float64),
        randomization.NO_DR,
    )
    assert raw["tip_object_force"][0, 0] == pytest.approx(mass * 9.81, rel=0.03)
    assert raw["tip_object_downward"][0, 0] == pytest.approx(1.0, abs=0.02)
    assert raw["tip_object_force"][0, 1:].max() == 0.0 and raw["tip_object_downward"][0, 1:].max() == 0.0
    # The other two sensors see nothing, and the deadband maps small readings to exactly 0.
    assert np.all(force.reading(uni()[1:]) == 0.0)


def test_deadband_threshold():
    f = np.array([0.0, 0.05, -0.099, 0.1, -0.5, 3.0])
    np.testing.assert_array_equal(force.reading(f), [0.0, 0.0, 0.0, 0.1, -0.5, 3.0])


def test_scripted_closing_motion_lifts_the_medium_cylinder():
    """Grasps hold: a scripted pinch lifts the cylinder 3 cm and holds it, under the paper's gain randomization."""
    dr = replace(randomization.PAPER_DR, joint_offset_rad=0.0, object_xy_m=0.0, external_force=False)
    env = BatchedGraspEnv(GraspEnvConfig(num_envs=8, objects=("cylinder_a_medium",), dr=dr, autoreset=False))
    env.reset()
    lifts, forces, info = run_pinch_lift(env, 100)
    assert info["success"].all()
    # Held for the last second without creep: within 3 mm of the 3 cm lift, and never launched.
    assert np.all(np.abs(lifts[-20:] - 0.03) < 0.003)
    assert lifts.max() < 0.045
    # All three tips press on the object while it is held (tens of newtons at most, not physics blow-ups).
    held = forces[-20:]
    assert (held > spec.FORCE_THRESHOLD_N).all() and held.max() < 100.0
    # A lifting grasp squeezes sideways: no tip presses the object down, so the directional touch pays in full.
    assert np.abs(info["tip_object_downward"]).max() < 0.3


@pytest.mark.parametrize("name", objects.PAPER_OBJECTS)
def test_each_object_rests_stably_on_the_table(name):
    env = BatchedGraspEnv(
        GraspEnvConfig(num_envs=1, objects=(name,), dr=randomization.NO_DR, autoreset=False, episode_s=1.0)
    )
    env.reset()
    for _ in range(10):
        env.step(np.zeros((1, 9)))
    o = objects.get_object(name)
    pos = env.object_position()[0]
    assert abs(pos[2] - o.rest_height) < 0.003, f"{name} did not rest at its expected height"
    assert np.linalg.norm(pos[:2]) < 0.005


def test_contact_directions_tell_a_sideways_lift_from_a_press_from_above():
    """`teacher.contacts` on two scripted grasps: the pinch at mid-height of the medium cylinder squeezes sideways
    and lifts it; the same pinch closed on top of the small capsule presses it into the table (what the `cpu`
    teacher does to that capsule: -F_z/|F| ~ 0.86, tips ~21 mm above its axis)."""
    from lab.diagnosis.contacts import contact_directions
    from lerobot_blindgrasp.sim.scripted import PinchLiftScript

    dr = replace(randomization.PAPER_DR, joint_offset_rad=0.0, object_xy_m=0.0, external_force=False)
    on_top = 0.04 + gripper.TIP_CAPSULE_RADIUS - 0.004  # the capsule lies on its side, 4 cm high
    found = {}
    grasps = (("cylinder_a_medium", 0.03, 0.045, 0.03), ("capsule_small", 0.0, on_top, -0.005))
    for obj, radius, height, lift in grasps:
        env = BatchedGraspEnv(GraspEnvConfig(num_envs=2, objects=(obj,), dr=dr, autoreset=False))
        obs = env.reset()
        script = PinchLiftScript(radius, height, lift)
        found[obj] = contact_directions(env, obs, lambda o: script(env.joint_positions()), 100, after_steps=40)  # noqa: B023
    side, above = found["cylinder_a_medium"], found["capsule_small"]
    assert side["success_rate"] == 1.0 and side["contacts"] > 0
    assert abs(side["mean_downward"]) < 0.3 and side["share_pressing_down"] == 0.0
    assert above["success_rate"] == 0.0 and above["contacts"] > 0
    assert above["mean_downward"] > 0.7 and above["share_pressing_down"] == 1.0
    assert above["mean_tip_height_mm"] > 15.0 > abs(side["mean_tip_height_mm"])
