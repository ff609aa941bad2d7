"""Each term of the task, torch over the env axis, against the numpy implementation it replaced, on the same states.

The states come from a short rollout of the env itself (random actions, two randomization settings: Table II with
its pushes, and every sensor and servo factor beyond it switched on, so that each branch runs). For every recorded
step the test feeds the same physics state to the env's torch terms and to `_Reference`, the numpy code the sim ran
before its terms moved to torch (kept here, and only here, as the reference), and compares term by term.

Tolerance. Both sides compute in float64 from the same inputs with the same formulas; they differ only in how the
last bit is rounded: torch's reductions sum 3 to 9 elements in another order than NumPy's pairwise sum, and its
vectorized sqrt, tanh and cos (SLEEF on AVX-512 CPUs) are within 1 ulp but not always correctly rounded. Each op
then adds at most ~1 ulp of the largest magnitude it combines, and the longest chain in a term is under 32 ops, so
a term of scale S (the largest |value| its inputs and result take in the rollout, at least 1) agrees within
TOL_ULPS = 64 ulps of S: 64 x 2.2e-16 x S = 1.4e-14 S. Cancellation (1 - sqrt(x) near 1, -F_z/|F| at small |F|)
cannot exceed that, because the error is bounded by the inputs' scale, not the result's. The float32 observations
the policy sees may then differ by one float32 ulp where a float64 value sits within 1.4e-14 of a float32 rounding
boundary. Integer and boolean terms (contact counts, hold counters, success, termination, push schedules, jitter
delays) must agree exactly.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import torch

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.sim import events, observations, randomization, rewards, rng, termination
from lerobot_blindgrasp.sim.batched_config import GraspEnvConfig
from lerobot_blindgrasp.sim.batched_env import BatchedGraspEnv

TOL_ULPS = 64
EPS = np.finfo(np.float64).eps
F32_ULP = np.finfo(np.float32).eps
# Every factor beyond Table II that acts on a term (sensor gain, bias, range, a dead cell, calibration, hold push).
FACTORS = replace(
    randomization.PAPER_DR,
    force_gain=0.8,
    force_bias_n=0.3,
    force_range_n=4.0,
    dead_force_sensor=1,
    joint_calibration_rad=0.05,
    hold_push_n=2.0,
)


class _Reference:
    """The numpy implementation of the terms before they moved to torch (NumPy over the env axis)."""

    M64, GOLDEN = np.uint64(0xFFFFFFFFFFFFFFFF), np.uint64(0x9E3779B97F4A7C15)

    @classmethod
    def splitmix(cls, x):
        with np.errstate(over="ignore"):
            z = x + cls.GOLDEN
            z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
            z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
            return z ^ (z >> np.uint64(31))

    @classmethod
    def uniform(cls, seeds, stream, counter, n):
        seeds = np.asarray(seeds, dtype=np.uint64)
        counter = np.broadcast_to(np.asarray(counter, dtype=np.uint64), seeds.shape)
        with np.errstate(over="ignore"):
            key = cls.splitmix(seeds * np.uint64(0xD1B54A32D192ED03) + np.uint64(stream))
            key = cls.splitmix(key ^ (counter * np.uint64(0x8CB92BA72F3D8DD7)))
            bits = cls.splitmix(key[:, None] + np.arange(n, dtype=np.uint64)[None, :] * cls.GOLDEN)
        return (bits >> np.uint64(11)).astype(np.float64) * (1.0 / (1 << 53))

    @classmethod
    def normal(cls, seeds, stream, counter, n):
        u = cls.uniform(seeds, stream, counter, 2 * n)
        return np.sqrt(-2.0 * np.log(np.maximum(u[:, :n], 1e-300))) * np.cos(2.0 * np.pi * u[:, n:])

    @staticmethod
    def quat_to_mat(q):
        w, x, y, z = np.moveaxis(q, -1, 0)
        rows = [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
        return np.stack([np.stack(r, -1) for r in rows], -2)

    @staticmethod
    def deadband(f):
        return np.where(np.abs(f) < spec.FORCE_THRESHOLD_N, 0.0, f)

    @classmethod
    def observe(cls, qpos, qvel, sd, cols, rest_height, prev_action, noise, dr, bias, offset):
        def read(kind):
            return sd[:, cols[kind]]

        contact, tip_quat, tip_obj = read("contact"), read("quat"), read("objcontact")
        uni_true = np.einsum("nfi,nfi->nf", contact, read("zaxis"))
        obj_pos, norm = qpos[:, 9:12], np.linalg.norm(tip_obj, axis=2)
        raw = {
            "q": qpos[:, :9],
            "uniaxial_clean": cls.deadband(uni_true),
            "d_xy": np.linalg.norm(obj_pos[:, :2], axis=-1),
            "lift": obj_pos[:, 2] - rest_height,
            "tip_object_distance": read("objdist")[:, :, 0],
            "tip_object_force": norm,
            "tip_object_downward": -tip_obj[..., 2] / np.maximum(norm, 1e-9),
        }
        nz = np.split(noise, np.cumsum([n for _, n in observations.NOISE_LAYOUT])[:-1], axis=1)
        nz = [nz[0] * dr.joint_noise_rad] + [x * dr.force_noise_n for x in nz[1:]]
        signal = uni_true * dr.force_gain if dr.force_gain != 1.0 else uni_true
        signal = signal + bias if dr.force_bias_n else signal
        signal = signal + nz[1]
        signal = np.clip(signal, -dr.force_range_n, dr.force_range_n) if dr.force_range_n > 0 else signal
        if dr.dead_force_sensor >= 0:
            signal[:, dr.dead_force_sensor] = 0.0
        n = len(qpos)
        joint_pos = raw["q"] + nz[0] + (offset if dr.joint_calibration_rad else 0.0)
        rot = cls.quat_to_mat(tip_quat)
        parts = {
            "joint_pos": joint_pos,
            "joint_vel": qvel[:, :9],
            "fingertip_pos": read("pos").reshape(n, -1),
            "fingertip_quat": tip_quat.reshape(n, -1),
            "object_pos": obj_pos,
            "object_quat": qpos[:, 12:16],
            "object_linvel": qvel[:, 9:12],
            "object_angvel": qvel[:, 12:15],
            "fingertip_contact_force": -np.einsum("nfji,nfj->nfi", rot, contact).reshape(n, -1) + nz[2],
            "object_planar_distance": raw["d_xy"][:, None],
            "uniaxial_force": cls.deadband(signal),
            "fingertip_wrench": np.concatenate([read("force"), read("torque")], axis=2).reshape(n, -1) + nz[3],
            "previous_action": prev_action,
        }
        return raw, parts

    @staticmethod
    def rewards(raw, action, prev_action, cfg):
        n_contact = (raw["uniaxial_clean"] > cfg.contact_threshold_n).sum(axis=-1)
        h_t, d, q = cfg.target_lift_m, raw["d_xy"], raw["q"]
        h_o = np.clip(raw["lift"], 0.0, None)
        centred = 1.0 - np.sqrt(np.clip(d / cfg.workspace_radius_m, 0.0, 1.0))
        height = np.where(h_o < h_t, 1.0 - np.sqrt(np.clip((h_t - h_o) / h_t, 0.0, 1.0)), 1.0)
        active = (n_contact >= 1) & (d < cfg.workspace_radius_m)
        limit = np.clip(spec.JOINT_LOWER - q, 0.0, None) + np.clip(q - spec.JOINT_UPPER, 0.0, None)
        reach = 1.0 - np.tanh(cfg.reach_scale * np.clip(raw["tip_object_distance"], 0.0, None))
        return {
            "task": np.where(active, height * centred, 0.0),
            "incentive": (n_contact == spec.NUM_FORCES).astype(np.float64),
            "joint_limit": limit.sum(axis=-1),
            "action": np.square(action).sum(axis=-1),
            "action_rate": np.square(action - prev_action).sum(axis=-1),
            "reach": reach.mean(axis=-1),
            "touch": (raw["tip_object_force"] > cfg.contact_threshold_n).mean(axis=-1),
        }


def _close(new, old, what: str, scale: float | None = None) -> None:
    new = np.asarray(new.cpu() if isinstance(new, torch.Tensor) else new, dtype=np.float64)
    old = np.asarray(old, dtype=np.float64)
    s = max(1.0, float(np.abs(old).max(initial=0.0))) if scale is None else scale
    err = float(np.abs(new - old).max(initial=0.0))
    assert err <= TOL_ULPS * EPS * s, f"{what}: |new - old| = {err:.3g} > {TOL_ULPS} ulps of {s:.3g}"


def _rollout(dr: randomization.DomainRandomization, steps: int = 30) -> tuple[BatchedGraspEnv, list[dict]]:
    """States of a short rollout: each step's physics state and what the terms read with it."""
    env = BatchedGraspEnv(GraspEnvConfig(num_envs=18, seed=11, dr=dr, episode_s=1.0, nthread=1))
    env.reset()
    actions = np.random.default_rng(0).uniform(-0.3, 0.3, (steps, env.num_envs, spec.NUM_JOINTS))
    states = []
    for a in actions:
        prev = env.prev_action.clone()
        env.step(a)
        raw = dict(env._raw)  # what the reward terms read this step, as the env computed it
        state = {k: getattr(env, f"_{k}").clone() for k in ("qpos", "qvel", "sensordata")}
        states.append({**state, "action": torch.as_tensor(a).clamp(-0.3, 0.3), "prev": prev, "raw": raw})
        states[-1]["counter"] = (env.episode * 100_003 + env.episode_length).clone()
    return env, states


@pytest.fixture(scope="module", params=["table_ii", "factors"])
def rollout(request):
    env, states = _rollout(randomization.PAPER_DR if request.param == "table_ii" else FACTORS)
    yield env, states
    env.close()


def test_observation_terms_match_the_numpy_implementation(rollout):
    env, states = rollout
    cols = {k: v.numpy() for k, v in env.sensor_index.cols.items()}
    bias, offset = env.sensor_draw.force_bias.numpy(), env.sensor_draw.joint_offset.numpy()
    for t, s in enumerate(states):
        noise = rng.normal(env._seeds, rng.STREAM_OBS_NOISE, s["counter"], observations.NOISE_DIM)
        old_noise = _Reference.normal(env.env_seeds, rng.STREAM_OBS_NOISE, s["counter"].numpy(), noise.shape[1])
        _close(noise, old_noise, f"step {t} noise", scale=8.0)  # |N(0,1)| < 8 in any draw this size
        args = (
            s["qpos"],
            s["qvel"],
            s["sensordata"],
            env.sensor_index,
            env.rest_height,
            s["prev"],
            noise,
            env.cfg.dr,
        )
        raw, obs = observations.observe(
            *args, randomization.SensorDraw(env.sensor_draw.force_bias, env.sensor_draw.joint_offset)
        )
        np_args = [x.numpy() for x in (s["qpos"], s["qvel"], s["sensordata"])]
        old_raw, old_parts = _Reference.observe(
            *np_args[:3], cols, env.rest_height.numpy(), s["prev"].numpy(), old_noise, env.cfg.dr, bias, offset
        )
        for k, v in old_raw.items():
            _close(raw[k], v, f"step {t} raw {k}")
        old_priv = np.concatenate([old_parts[n] for n, _ in spec.PRIVILEGED_LAYOUT], axis=1)
        for name, sl in spec.PRIVILEGED_SLICES.items():
            part = obs["privileged"][:, sl].numpy()
            want = old_priv[:, sl].astype(np.float32)
            np.testing.assert_allclose(part, want, rtol=F32_ULP, atol=F32_ULP * 1e-3, err_msg=f"step {t} {name}")
        policy = np.concatenate([old_parts["joint_pos"], old_parts["uniaxial_force"]], axis=1).astype(np.float32)
        np.testing.assert_allclose(obs["policy"].numpy(), policy, rtol=F32_ULP, atol=F32_ULP * 1e-3)


def test_the_scenes_tip_readings_are_views_of_sensordata(rollout):
    """The fingers' readings share one layout in the scene, so each read is a view (no gather per reading per step);
    it holds what the columns say."""
    env, _ = rollout
    si, sd = env.sensor_index, env.physics.sensordata
    assert si.block is not None
    for kind, cols in si.cols.items():
        view = si.read(sd, kind)
        assert view.untyped_storage().data_ptr() == sd.untyped_storage().data_ptr()
        assert torch.equal(view, sd[:, cols])


def test_reward_terms_match_the_numpy_implementation(rollout):
    env, states = rollout
    cfg = rewards.PAPER_REWARD.with_weights(reach=0.5, touch=0.5)
    for t, s in enumerate(states):
        raw = s["raw"]
        step = rewards.StepQuantities(
            lift=raw["lift"],
            d_xy=raw["d_xy"],
            uniaxial_force=raw["uniaxial_clean"],
            q=s["qpos"][:, :9],  # raw["q"] is a view of the live state; the recorded copy is this step's
            action=s["action"],
            prev_action=s["prev"],
            tip_object_distance=raw["tip_object_distance"],
            tip_object_force=raw["tip_object_force"],
        )
        terms = rewards.compute_terms(step, cfg)
        old_raw = {k: v.numpy() for k, v in raw.items()} | {"q": step.q.numpy()}
        old = _Reference.rewards(old_raw, s["action"].numpy(), s["prev"].numpy(), cfg)
        for k, v in old.items():
            _close(terms[k], v, f"step {t} r_{k}")
        np.testing.assert_array_equal(
            rewards.num_contacts(step.uniaxial_force).numpy(), (old_raw["uniaxial_clean"] > 0.1).sum(-1)
        )


def test_success_and_termination_match_the_numpy_implementation(rollout):
    _, states = rollout
    held, old_held = torch.zeros(18, dtype=torch.int64), np.zeros(18, dtype=np.int64)
    for t, s in enumerate(states):
        lift, d = s["raw"]["lift"], s["raw"]["d_xy"]
        held = termination.held_steps(held, lift)
        old_held = np.where(lift.numpy() >= spec.SUCCESS_LIFT_M, old_held + 1, 0)
        np.testing.assert_array_equal(held.numpy(), old_held)
        np.testing.assert_array_equal(termination.is_success(held).numpy(), old_held >= spec.SUCCESS_HOLD_STEPS)
        np.testing.assert_array_equal(termination.out_of_workspace(d).numpy(), d.numpy() > spec.WORKSPACE_RADIUS_M)
        length = torch.full((18,), t)
        term = termination.out_of_workspace(d)
        np.testing.assert_array_equal(
            termination.timed_out(length, 20, term).numpy(), (length.numpy() >= 20) & ~term.numpy()
        )


def test_randomization_draws_match_the_numpy_implementation():
    dr, n = FACTORS, 500
    seeds = np.uint64(2**63 + 5) + np.arange(n, dtype=np.uint64) * np.uint64(7919)  # seeds past int64's range too
    counter = np.arange(n, dtype=np.int64) * 100_003 + 3
    np.testing.assert_array_equal(
        rng.uniform(seeds, 4, counter, 7).numpy(), _Reference.uniform(seeds, 4, counter, 7)
    )
    u = _Reference.uniform(seeds, rng.STREAM_RESET, counter, spec.NUM_JOINTS + 2)
    q0, xy = randomization.draw_reset(dr, seeds, counter)
    _close(q0, spec.HOME_POSE + (-dr.joint_offset_rad + 2 * dr.joint_offset_rad * u[:, :9]), "draw_reset q0")
    _close(xy, -dr.object_xy_m + 2 * dr.object_xy_m * u[:, 9:], "draw_reset xy")
    u = _Reference.uniform(seeds, rng.STREAM_PUSH, counter, 4)
    force, steps = randomization.draw_push(dr, seeds, counter)
    _close(force, -0.3 + 0.6 * u[:, :3], "draw_push force")
    np.testing.assert_array_equal(steps.numpy(), np.maximum(1, np.ceil(10.0 * u[:, 3] * spec.CONTROL_HZ)))
    u = _Reference.uniform(seeds, rng.STREAM_DR, 0, 5)
    p = randomization.draw_physics(dr, seeds)
    _close(p.kp_scale, np.exp(np.log(0.3) + (np.log(3.0) - np.log(0.3)) * u[:, 3]), "draw_physics kp", scale=3.0)
    _close(p.object_friction, 0.7 + 0.6 * u[:, 0], "draw_physics friction")
    u = _Reference.uniform(seeds, rng.STREAM_SENSOR, 0, spec.NUM_FORCES + spec.NUM_JOINTS)
    sd = randomization.draw_sensors(dr, seeds)
    np.testing.assert_array_equal(sd.force_bias.numpy(), dr.force_bias_n * np.where(u[:, :3] < 0.5, -1.0, 1.0))
    g = _Reference.normal(seeds, rng.STREAM_HOLD_PUSH, counter, 3)
    want = dr.hold_push_n * g / np.maximum(np.linalg.norm(g, axis=1, keepdims=True), 1e-12)
    _close(randomization.draw_hold_push(dr, seeds, counter), want, "draw_hold_push")
    jit = replace(dr, period_jitter_s=0.02)
    u = _Reference.uniform(seeds, rng.STREAM_JITTER, counter, 1)[:, 0]
    want = np.minimum(np.floor(u * (0.02 / (spec.CONTROL_DT / 10) + 1)), 9)
    np.testing.assert_array_equal(randomization.draw_jitter_substeps(jit, seeds, counter, 10).numpy(), want)


def test_push_events_match_the_numpy_schedule():
    """Table II's pushes over 400 control steps (several pushes per env): the same envs pushed at the same steps
    with the same forces as the index-list schedule they replaced, written into the applied forces."""
    dr, n = randomization.PAPER_DR, 64
    seeds = np.arange(n, dtype=np.uint64) + np.uint64(100)
    pushes = events.Pushes(dr, rng.as_words(seeds))
    xfrc = torch.zeros((n, 3, 6), dtype=torch.float64)
    counter, to_push, pushing = np.zeros(n, dtype=np.int64), np.zeros(n, dtype=np.int64), np.zeros(n, dtype=bool)
    old = np.zeros((n, 3, 6))

    def draw(ids):
        u = _Reference.uniform(seeds[ids], rng.STREAM_PUSH, counter[ids], 4)
        return -0.3 + 0.6 * u[:, :3], np.maximum(1, np.ceil(10.0 * u[:, 3] * spec.CONTROL_HZ)).astype(np.int64)

    pushes.reset(torch.arange(n))
    _, to_push[:] = draw(np.arange(n))
    counter += 1
    for t in range(400):
        pushes(xfrc, 1)
        old[pushing, 1, :3] = 0.0
        pushing[:] = False
        to_push -= 1
        due = np.flatnonzero(to_push <= 0)
        force, to_push[due] = draw(due)
        counter[due] += 1
        pushing[due] = True
        old[due, 1, :3] = force
        _close(xfrc, old, f"step {t} applied force", scale=1.0)
        np.testing.assert_array_equal(pushes.schedule.counter.numpy(), counter)


def test_short_sums_round_as_torchs_own_sum_signed_zeros_included():
    """`sensors.sum_short` replaces `sum` over the tips' 2- and 3-entry axes: bit for bit the same, on the strided
    views the sensors are read through, with the zeros (+0 and -0) a tip without contact reports."""
    from lerobot_blindgrasp.sim import sensors

    g = torch.Generator().manual_seed(0)
    rows = torch.randn(1026, 130, dtype=torch.float64, generator=g)
    rows[torch.rand(rows.shape, generator=g) < 0.3] = 0.0
    rows[torch.rand(rows.shape, generator=g) < 0.2] = -0.0
    tips = rows[:, 10:130].unflatten(1, (3, 40))  # (n, tip, reading) views, as SensorIndex.read gives
    force, axis = tips[:, :, 0:3], tips[:, :, 3:6]
    rot = torch.randn(1026, 3, 3, 3, dtype=torch.float64, generator=g)
    rot[rot.abs() < 0.3] = -0.0
    cases = [(force * axis, -1), (force, -1), (rows[:, :2].square(), -1), (rot * force[..., :, None], -2)]
    for x, dim in cases:
        ours, torchs = sensors.sum_short(x, dim), x.sum(dim)
        assert torch.equal(ours.view(torch.int64), torchs.view(torch.int64))
    all_negative_zero = torch.full((4, 3), -0.0, dtype=torch.float64)
    assert sensors.sum_short(all_negative_zero, -1).signbit().logical_not().all()  # +0, as torch's sum
