"""`python -m lab.bench --bench.type=onemodel`: one MuJoCo Warp model with a geom of each type per object steps the
same physics as the object groups, on Warp's CPU device (where the derived tolerance is zero: see `check`)."""

import numpy as np
import pytest
import torch
import warp as wp

from lab.bench import onemodel_bench as om
from lerobot_blindgrasp.sim import gripper, objects


def test_the_four_geom_object_is_the_object_to_the_physics_and_the_sensors():
    options = gripper.PhysicsOptions()
    for name in objects.PAPER_OBJECTS:
        o = objects.get_object(name)
        own = gripper.compile_model(objects.object_mjcf(o, gripper.OBJECT_CONTYPE, gripper.OBJECT_CONAFFINITY))
        four = om.one_model_template(o, options)
        b, b4 = own.body("object").id, four.body("object").id
        for k in ("body_mass", "body_inertia", "body_ipos", "body_iquat", "body_pos", "body_quat"):
            np.testing.assert_array_equal(getattr(four, k)[b4], getattr(own, k)[b], err_msg=f"{name} {k}")
        assert four.nq == own.nq and four.nv == own.nv and four.nu == own.nu
        assert [four.sensor(i).name for i in range(four.nsensor)] == [
            own.sensor(i).name for i in range(own.nsensor)
        ]
        np.testing.assert_array_equal(four.sensor_adr, own.sensor_adr)
        sizes = {four.geom_type[four.geom(n).id]: four.geom_size[four.geom(n).id] for n in om.SLOT_NAMES}
        mine = own.geom_type[own.geom("object_geom").id]
        np.testing.assert_array_equal(sizes.pop(mine), own.geom_size[own.geom("object_geom").id])
        assert all(np.all(s == om.OFF_SIZE) for s in sizes.values())


@pytest.fixture(scope="module")
def pair():
    env, one = om.build_pair(18, device="cpu")  # one world per object
    yield env, one
    env.close()
    one.close()


def test_one_model_steps_the_groups_physics_to_the_bit(pair):
    env, one = pair
    assert (len(env.physics.groups), len(one.groups)) == (4, 1)
    out = om.check(env, one, steps=12)
    assert out["worlds_with_a_tip_on_the_object"] == 18  # the comparison covers grasp contacts on every object
    assert out["groups_rerun_max_pose_diff"] == 0.0 and out["tolerance"] == 0.0  # Warp's CPU device: in order
    assert out["max_pose_diff"] == 0.0 and out["max_sensor_diff"] == 0.0 and out["agree"]


def test_the_check_sees_a_world_whose_object_differs(pair):
    """A 10 % smaller sphere in one world of the one model (the control: the check is not blind)."""
    env, one = pair
    world = env.object_names.index("sphere_medium")
    size = wp.to_torch(one.groups[0].model.geom_size)
    sphere = om.one_model_template(objects.get_object("sphere_medium"), gripper.PhysicsOptions()).geom(
        "object_sphere"
    )
    saved = size[world, sphere.id].clone()
    size[world, sphere.id] *= 0.9
    try:
        out = om.check(env, one, steps=4)
    finally:
        size[world, sphere.id] = saved
    assert not out["agree"] and out["max_pose_diff"] > 1e-4  # it settles ~4 mm lower


def test_both_paths_are_timed_from_the_same_grasp(pair):
    env, one = pair
    out = om.time_paths(env, one, steps=2, blocks=1, deadline=0.0)
    assert out["blocks"] == 1 and out["control_steps_per_block"] == 2
    for path in ("groups", "one"):
        assert out[path]["raw_control_steps_per_s"] > 0 and out[path]["step_control_steps_per_s"] > 0
    ratio = out["one"]["raw_control_steps_per_s"] / out["groups"]["raw_control_steps_per_s"]
    assert out["one_over_groups"]["raw_control_steps_per_s"] == pytest.approx(ratio)
    assert torch.isfinite(one.qpos).all() and torch.isfinite(env.physics.qpos).all()
