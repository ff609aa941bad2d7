"""The MuJoCo Warp backend against the batch backend, on CPU (Warp's CPU device; no GPU needed).

Both envs are built from the same config and seed, so they hold the same objects, the same Table II draws and the
same reset states; they are stepped with the same actions. Tolerances, and why:
- Before any contact (open-loop, first 5 control steps = 50 physics steps): physics is smooth, so the only
  difference is Warp's float32 against MuJoCo's float64. Joints agree to 1e-5 rad and objects to 1e-4 m (the
  capsules settle on the table through different collision code: 1.6e-5 m measured); fingertip forces to 1e-3 N,
  rewards to 1e-4, terminations exactly; 99 % of the teacher observation to 2e-3 (a link grazing an object on
  one backend only shows up as a few hundredths of a newton in a few contact-force entries).
- Through contact, trajectories of a chaotic system part ways (float32 and a different collision pipeline
  change contact points in the last digits, which a stick-slip transition amplifies), so open-loop contact
  phases are not compared step by step. Instead a closed-loop scripted pinch-and-lift, which corrects its own
  deviations, must give the same outcome: success in every env, lift heights within 2 mm over the held second,
  and held fingertip forces within 25 % of each other (they are statically indeterminate: three tips squeezing
  one object may share the load differently and still hold it).
"""

from dataclasses import replace

import numpy as np
import pytest
import torch
from test_sim_physics import run_pinch_lift

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.sim import objects, randomization
from lerobot_blindgrasp.sim.batched_env import BatchedGraspEnv, GraspEnvConfig

NO_PUSH = randomization.EVAL_DR


def _pair(**kw):
    batch = BatchedGraspEnv(GraspEnvConfig(nthread=1, **kw))
    warp = BatchedGraspEnv(GraspEnvConfig(backend="warp", device="cpu", **kw))
    return batch, warp


@pytest.fixture(scope="module")
def pair36():
    """Two envs per catalogue object on each backend, built once for the tests that only read or reset them."""
    return _pair(num_envs=36, seed=5, dr=NO_PUSH)


def _assert_worlds_are_the_cpu_models(backend, env_model) -> None:
    """Every model field that differs between the CPU per-env models (the batch backend's, `env_model(i)`) is a
    per-world field of the Warp model, and each world's row equals its env's model within float32: the fields
    written on the device are the float64 rows cast once (half an ulp); the constants Warp's set_const derives
    in float32 (subtree masses, centres of mass, the inverse weights from a factorized 15 x 15 mass matrix) take
    a few float32 operations each, so 8 ulps of the field's scale bound both."""
    from lerobot_blindgrasp.sim.backends.warp import _UNUSED, _array_fields

    for g in backend.groups:
        models = [env_model(int(i)) for i in g.ids]
        first = _array_fields(models[0])
        differ = {k for m in models[1:] for k, v in _array_fields(m).items() if not np.array_equal(v, first[k])}
        assert {"geom_friction", "body_mass", "body_inertia", "actuator_gainprm", "body_invweight0"} <= differ
        for k in sorted(differ - _UNUSED):
            if not hasattr(g.model, k):
                continue  # MjModel arrays Warp has no field for (the BVH, dof_M0) are not read by its physics
            rows = getattr(g.model, k).numpy().reshape(len(g.ids), -1)  # one row per world, or it raises
            expect = np.stack([getattr(m, k).reshape(-1) for m in models])
            tol = 8 * F32 * np.abs(expect).max()
            np.testing.assert_allclose(rows, expect, rtol=0, atol=tol, err_msg=k)


def test_warp_writes_each_worlds_table_ii_draw_as_the_cpu_models_carry_it(pair36):
    """18 objects become 4 Warp models (box, capsule, cylinder, sphere), each built from one object's MjModel; the
    objects' sizes and masses, each env's Table II draw and the constants derived from them are per-world fields
    written on the device, equal to the batch backend's per-env MjModels for the same seeds."""
    from lerobot_blindgrasp.sim.backends.warp import WarpBackend

    _, warp = pair36
    groups = warp.physics.groups
    assert sorted(len(g.ids) for g in groups) == [6, 6, 12, 12]
    _assert_worlds_are_the_cpu_models(warp.physics, warp.env_model)
    # the torque limit beyond Table II, on one group's envs
    ids = groups[0].ids
    capped = WarpBackend(warp._templates, warp.object_index[ids], warp.physics_draw.rows(ids), 0.5, device="cpu")
    draw = warp.physics_draw.rows(ids)

    def capped_model(i):
        return randomization.apply_physics_draw(warp._templates[warp.object_index[ids[i]]], draw, i, 0.5)

    _assert_worlds_are_the_cpu_models(capped, capped_model)
    limit = capped.groups[0].model.actuator_forcerange.numpy()
    full = warp.env_model(int(ids[0])).actuator_forcerange
    np.testing.assert_allclose(limit, np.broadcast_to(0.5 * full, limit.shape), rtol=1e-6)
    # every group steps with the scene's solver settings (no silent fallback)
    opt = groups[0].model.opt
    assert opt.noslip_iterations == 3 and int(opt.cone) == 1 and int(opt.solver) == 2


def test_open_loop_steps_match_before_contact(pair36):
    batch, warp = pair36
    ob, ow = batch.reset(), warp.reset()
    np.testing.assert_array_equal(warp.joint_positions(), batch.joint_positions())  # same draws, same start
    for k in ob:  # sensors computed in float32
        np.testing.assert_allclose(ow[k], ob[k], atol=1e-5)
    rng = np.random.default_rng(0)
    for _ in range(5):
        a = rng.uniform(-0.15, 0.15, (36, spec.NUM_JOINTS))
        ob, rb, tb, trb, ib = batch.step(a)
        ow, rw, tw, trw, iw = warp.step(a)
        np.testing.assert_allclose(warp.joint_positions(), batch.joint_positions(), atol=1e-5)
        np.testing.assert_allclose(warp.object_position(), batch.object_position(), atol=1e-4)
        np.testing.assert_allclose(iw["uniaxial_force"], ib["uniaxial_force"], atol=1e-3)
        np.testing.assert_allclose(rw, rb, atol=1e-4)
        np.testing.assert_array_equal(tw, tb)
        np.testing.assert_array_equal(trw, trb)
        assert not iw["physics_failed"].any()
        # The whole teacher observation (joint velocities, tip poses, wrenches, ...) agrees to float32 noise, except
        # where a link grazes the object on one backend only: a few contact-force entries of a few hundredths of a
        # newton (measured: 6 of 3312 entries, at most 0.023).
        diff = np.abs(ow["privileged"] - ob["privileged"])
        assert (diff <= 2e-3).mean() >= 0.99 and diff.max() < 0.1


@pytest.mark.slow
def test_scripted_grasp_holds_the_same_on_both_backends():
    """Closed loop through contact: the scripted pinch lifts the medium cylinder on both backends, under the
    paper's gain randomization. Warp keeps MuJoCo's noslip iterations, so the hold does not creep there either."""
    dr = replace(NO_PUSH, joint_offset_rad=0.0, object_xy_m=0.0)
    kw = {"num_envs": 4, "seed": 5, "objects": ("cylinder_a_medium",), "dr": dr, "autoreset": False}
    runs = {}
    for name, env in zip(("batch", "warp"), _pair(**kw)):
        env.reset()
        lifts, forces, info = run_pinch_lift(env, 85)
        runs[name] = (lifts, forces, info["success"])
    (lb, fb, sb), (lw, fw, sw) = runs["batch"], runs["warp"]
    assert sb.all() and sw.all()
    np.testing.assert_allclose(lw[-20:], lb[-20:], atol=0.002)
    assert np.all(np.abs(lw[-20:] - 0.03) < 0.003)  # held at the lift height, no creep
    held_b, held_w = fb[-20:].sum(axis=2).mean(axis=0), fw[-20:].sum(axis=2).mean(axis=0)
    np.testing.assert_allclose(held_w, held_b, rtol=0.25)
    assert objects.get_object("cylinder_a_medium").mjcf_type == "cylinder"


def test_collect_demos_on_warp_writes_the_same_start_states(tmp_path):
    """`blindgrasp-collect-demos --backend=warp`: the shipped teacher's demos, one per geometry type, written as a
    LeRobotDataset that LeRobot's loader reads, starting from the same observations as on the batch backend
    (same env seeds, same draws; trajectories part ways only through contact, see above)."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    from lerobot_blindgrasp.demos import collection_loop, curation, provenance
    from lerobot_blindgrasp.demos import dataset as demo_dataset
    from lerobot_blindgrasp.demos.config import CollectConfig

    names = "cuboid_a_medium,capsule_medium,cylinder_a_medium,sphere_medium"
    first = {}
    for backend in ("batch", "warp"):
        out = tmp_path / backend
        cfg = CollectConfig(
            output_dir=out,
            repo_id="test/warp_demos",
            episodes_per_object=1,
            objects=names,
            num_envs=4,
            seed=spec.DEMO_SEED + 7,
            curation=curation.NO_CURATION,
            stochastic=False,
            progress=False,
            backend=backend,
            threads=1,
        )
        stats = collection_loop.collect_demos(cfg)
        assert stats.kept == 4 and stats.stop_reason == "done"
        assert provenance.load_provenance(out)["runs"][0]["backend"] == backend
        ds = LeRobotDataset("test/warp_demos", root=out, video_backend="pyav")
        frames = ds.hf_dataset.with_format("numpy")
        state = np.stack(frames[spec.STATE_KEY])
        starts = np.flatnonzero(np.asarray(frames["frame_index"]) == 0)
        episode_object = dict(zip(*demo_dataset.episode_table(out)[["episode_index", "object"]].to_numpy().T))
        first[backend] = {episode_object[int(frames["episode_index"][i])]: state[i] for i in starts}
    assert sorted(first["warp"]) == sorted(names.split(","))
    for name in first["batch"]:
        # o_t at reset: the noisy joint readings and (zero) forces of the same draw; float32 on Warp
        np.testing.assert_allclose(first["warp"][name], first["batch"][name], atol=1e-5)
    with pytest.raises(ValueError, match="backend"):
        CollectConfig(output_dir=tmp_path / "x", repo_id="a/b", backend="gpu")


# Per-term tolerance, derived. Both backends start from the same state (Warp's is its float32 rounding) and step
# the same commands through 10 physics substeps per control step. Each substep's float32 arithmetic leaves each
# state component within a few ulps of its float64 counterpart; ULPS_PER_SUBSTEP = 8 bounds that, so after t
# control steps the state differs by at most DRIFT(t) = 8 x 10 t x eps32 x (largest |qpos|). A term then differs by
# its Lipschitz constant in the state times that, plus its own float32 rounding (ULPS_PER_SUBSTEP ulps of its scale):
# joints, lift and planar distance 1; a tip-to-object distance 2 (the tip moves at most 1 m per rad of the 3 joints
# of a 0.3 m finger, plus the object's own motion); the joint-limit penalty 9 (a sum over 9 clamped joints); r_reach
# reach_scale x 2. Before contact the contact-driven terms (uniaxial force counts, r_task's active gate, r_incentive,
# r_touch, success, termination) are equal, and forces agree within 1e-3 N (a link grazing an object on one
# backend only, see the module docstring) which is far below the 0.1 N contact threshold that turns them into
# counts. r_action and r_action_rate read only the actions, the same float64 values on both.
# The object is not in free flight: it rests on the table from the first step, and the two collision pipelines
# settle a capsule differently in that first step (one contact against two along its side: 1.6e-5 m apart after it,
# converging to the joints' drift once at rest). OBJECT_SETTLE_M, that first step's difference with a 6x margin,
# is added to the drift of everything that reads the object's position.
ULPS_PER_SUBSTEP = 8
OBJECT_SETTLE_M = 1e-4
F32 = float(np.finfo(np.float32).eps)


def _term_values(env, a, prev):
    from lerobot_blindgrasp.sim import rewards

    raw = {k: v.cpu().double() for k, v in env._raw.items()}
    step = rewards.StepQuantities(
        lift=raw["lift"],
        d_xy=raw["d_xy"],
        uniaxial_force=raw["uniaxial_clean"],
        q=raw["q"],
        action=torch.as_tensor(a, dtype=torch.float64),
        prev_action=prev,
        tip_object_distance=raw["tip_object_distance"],
        tip_object_force=raw["tip_object_force"],
        contact_threshold_n=env.cfg.reward.contact_threshold_n,
    )
    terms = rewards.compute_terms(step, env.cfg.reward)
    return raw, {k: v.cpu().double() for k, v in terms.items()}, rewards.num_contacts(step.uniaxial_force)


def _close(new, old, lipschitz: float, drift: float, what: str) -> None:
    tol = lipschitz * drift + ULPS_PER_SUBSTEP * F32 * max(1.0, float(old.abs().max()))
    err = float((new - old).abs().max())
    assert err <= tol, f"{what}: |warp - batch| = {err:.3g} > {tol:.3g}"


def test_each_term_per_step_within_float32_of_the_batch_backend():
    """Every raw quantity and reward term, control step by control step, CPU (float64) against Warp (float32),
    within the tolerance derived above; the integer and boolean terms exactly."""
    from lerobot_blindgrasp.sim import rewards

    batch, warp = _pair(num_envs=18, seed=9, dr=NO_PUSH)
    batch.reset(), warp.reset()
    substeps, reach_scale = batch.cfg.physics.substeps, batch.cfg.reward.reach_scale
    rng = np.random.default_rng(1)
    for t in range(1, 6):
        a = rng.uniform(-0.1, 0.1, (18, spec.NUM_JOINTS))
        prev_b, prev_w = batch.prev_action.cpu().clone(), warp.prev_action.cpu().clone()
        _, _, term_b, trunc_b, info_b = batch.step(a)
        _, _, term_w, trunc_w, info_w = warp.step(a)
        qpos_b = batch.physics.qpos.cpu().numpy()
        drift = ULPS_PER_SUBSTEP * substeps * t * F32 * max(1.0, float(np.abs(qpos_b).max()))
        qpos_w = warp.physics.qpos.cpu().numpy()
        np.testing.assert_allclose(qpos_w[:, :9], qpos_b[:, :9], rtol=0, atol=drift)  # the joints
        np.testing.assert_allclose(qpos_w[:, 9:12], qpos_b[:, 9:12], rtol=0, atol=drift + OBJECT_SETTLE_M)
        (raw_b, terms_b, n_b), (raw_w, terms_w, n_w) = (
            _term_values(batch, a, prev_b),
            _term_values(warp, a, prev_w),
        )

        _close(raw_w["q"], raw_b["q"], 1, drift, f"step {t} q")
        for k, lip in (("lift", 1), ("d_xy", 1), ("tip_object_distance", 2)):
            _close(raw_w[k], raw_b[k], lip, drift + OBJECT_SETTLE_M, f"step {t} {k}")
        for k in ("uniaxial_clean", "tip_object_force"):
            np.testing.assert_allclose(raw_w[k], raw_b[k], atol=1e-3, err_msg=f"step {t} {k}")
        torch.testing.assert_close(n_w, n_b, rtol=0, atol=0)
        _close(terms_w["joint_limit"], terms_b["joint_limit"], 9, drift, f"step {t} r_joint_limit")
        _close(terms_w["reach"], terms_b["reach"], 2 * reach_scale, drift, f"step {t} r_reach")
        for k in ("task", "incentive", "touch", "action", "action_rate"):
            torch.testing.assert_close(terms_w[k], terms_b[k], rtol=0, atol=1e-12, msg=f"step {t} r_{k}")
        assert set(terms_b) == set(rewards.TERM_NAMES)
        np.testing.assert_array_equal(term_w, term_b)
        np.testing.assert_array_equal(trunc_w, trunc_b)
        np.testing.assert_array_equal(info_w["success"], info_b["success"])


def test_one_group_shares_warps_own_memory_and_steps_as_the_copying_layout(pair36):
    """With one geometry group (the default `share_arrays`), the contract's tensors are the Warp arrays themselves
    (same memory, float32): the task resets and steps through them, auto-reset included, and stepping them gives
    bit for bit what the copying layout gives. With several groups they cannot be, and are copies."""
    from lerobot_blindgrasp.sim.backends.warp import WarpBackend

    assert not pair36[1].physics.shares_memory  # four groups
    env = BatchedGraspEnv(
        GraspEnvConfig(
            backend="warp",
            device="cpu",
            num_envs=3,
            seed=5,
            objects=("cylinder_a_medium",),
            dr=NO_PUSH,
            episode_s=4 / spec.CONTROL_HZ,
        )
    )
    shared = env.physics
    assert shared.shares_memory
    data = shared.groups[0].data
    for k in ("qpos", "qvel", "ctrl", "xfrc_applied", "sensordata"):
        view = getattr(shared, k)
        assert view.dtype == torch.float32 and view.data_ptr() == getattr(data, k).ptr, k
    env.reset()  # the task's reset writes its float64 draws into the float32 arrays
    np.testing.assert_array_equal(data.qpos.numpy(), shared.qpos.numpy())  # written in place, no copy
    copying = WarpBackend(env._templates, env.object_index, env.physics_draw, device="cpu", share_arrays=False)
    assert not copying.shares_memory and copying.qpos.dtype == torch.float64
    everyone = np.arange(3)
    copying.reset(everyone)
    for k in ("qpos", "qvel", "ctrl"):
        getattr(copying, k)[:] = getattr(shared, k)  # the env's reset state
    copying.forward(everyone)
    target = copying.ctrl + 0.1
    for _ in range(3):
        copying.ctrl[:] = target
        shared.ctrl[:] = target
        assert not copying.step(10).any() and not shared.step(10).any()
        for k in ("qpos", "qvel", "sensordata"):
            np.testing.assert_array_equal(
                getattr(shared, k).numpy(), getattr(copying, k).numpy().astype(np.float32)
            )
    ended = 0
    for _ in range(5):  # the 4-step episodes end and auto-reset through the shared arrays
        obs, reward, _, truncated, info = env.step(np.zeros((3, spec.NUM_JOINTS)))
        ended += int(truncated.sum())
        assert np.isfinite(obs["privileged"]).all() and np.isfinite(reward).all()
    assert ended == 3 and (env.episode_length.numpy() == 1).all()
