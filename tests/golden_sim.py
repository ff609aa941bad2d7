"""The golden simulation record's machinery (tests/sim/test_sim_golden.py says what it checks and why).

    rollouts(nudge=None)      the shipped teacher, deterministic, through both settings: per-step arrays
    summary(runs, horizons)   what the record stores: digests, exact quantities, the first steps' floats
    compare(record, runs, here) every mismatch, in words (an empty list: the simulation is the recorded one)

A contact-rich closed loop amplifies a last-bit difference: the floats of two CPU families agree closely for the
first steps and not at all a few seconds later (docs/results/cpu_portability.md). So the record keeps the floats of
the first `horizon` steps only, each with a per-step tolerance measured across stand-ins for other CPU families;
the rest of the rollout is checked through what does not drift: successes, dones, episode lengths, shapes, and
eq. 1's identity (the reward is the recorded weights times the logged terms, in IEEE arithmetic that every CPU
rounds alike).
"""

from __future__ import annotations

import hashlib
from collections.abc import Mapping

import float_platform
import numpy as np

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.sim import randomization, rewards
from lerobot_blindgrasp.sim.batched_config import GraspEnvConfig
from lerobot_blindgrasp.sim.batched_env import BatchedGraspEnv
from lerobot_blindgrasp.sim.gym_env import start_seed
from lerobot_blindgrasp.teacher.policy import TeacherPolicy, default_teacher

EVAL_OBJECTS = ("capsule_small", "sphere_small", "cuboid_a_large")
EPISODES = 2  # evaluation indices spec.EVAL_SEED .. + 1 of each object
SETTINGS = ("evaluation", "training")
VECTORS = ("policy", "privileged", "joint_target")  # stored as PROJECTIONS fixed +-1 projections per env and step
SCALARS = ("reward", "lift", *(f"term/{n}" for n in rewards.TERM_NAMES))
FLAGS = ("done", "success", "failed")
PROJECTIONS = 3
MARGIN = 100.0  # tolerance = MARGIN x the largest deviation any stand-in showed by that step, + FLOOR x scale
FLOOR = 1e-9
MAX_TOLERANCE = 0.01  # of the quantity's scale: the horizon ends where the tolerance would pass more than this


def rollouts(
    nudge: str | None = None, settings: tuple[str, ...] = SETTINGS, threads: int = 1
) -> dict[str, dict[str, np.ndarray]]:
    """Per-step arrays of both settings, on one torch thread (a matrix product's rounding depends on how many
    threads split it, and earlier tests in the same process may have changed the count; `threads` other than 1
    is a stand-in for another family). `nudge` names a reward term whose weight moves by one ulp: the deliberate
    real change the tests must catch."""
    import torch

    before = torch.get_num_threads()
    torch.set_num_threads(threads)
    try:
        teacher = TeacherPolicy(default_teacher())
        reward = rewards.RewardConfig.from_record(teacher.config["reward"])
        if nudge:
            reward = reward.with_weights(**{nudge: float(np.nextafter(reward.weight(nudge), np.inf))})
        return {s: _run(_env(s, reward), teacher) for s in settings}
    finally:
        torch.set_num_threads(before)


def _env(setting: str, reward: rewards.RewardConfig) -> BatchedGraspEnv:
    if setting == "evaluation":  # one batch, each env on the start state blindgrasp-eval-teacher gives it
        seeds = tuple(start_seed(spec.EVAL_SEED + k, name) for name in EVAL_OBJECTS for k in range(EPISODES))
        names = tuple(name for name in EVAL_OBJECTS for _ in range(EPISODES))
        return BatchedGraspEnv(
            GraspEnvConfig(
                num_envs=len(seeds),
                objects=names,
                env_seeds=seeds,
                dr=randomization.EVAL_DR,
                reward=reward,
                autoreset=False,
                nthread=1,
            )
        )
    # training: Table II with pushes, 18 objects, autoreset across two short episodes
    return BatchedGraspEnv(
        GraspEnvConfig(num_envs=18, seed=7, dr=randomization.PAPER_DR, reward=reward, episode_s=4.0, nthread=1)
    )


def _run(env: BatchedGraspEnv, teacher: TeacherPolicy) -> dict[str, np.ndarray]:
    steps = env.max_episode_steps if not env.cfg.autoreset else 2 * env.max_episode_steps + 5
    obs = env.reset()
    chunks: dict[str, list[np.ndarray]] = {"policy": [obs["policy"]], "privileged": [obs["privileged"]]}
    for _ in range(steps):
        obs, reward, terminated, truncated, info = env.step(teacher(obs, stochastic=False))
        for key, value in (
            ("policy", obs["policy"]),
            ("privileged", obs["privileged"]),
            ("reward", reward),
            ("joint_target", info["joint_target"]),
            ("lift", info["lift"]),
            ("done", terminated | truncated),
            ("success", info["success"]),
            ("failed", info["physics_failed"]),
        ):
            chunks.setdefault(key, []).append(np.asarray(value))
        for name, term in info["terms"].items():
            chunks.setdefault(f"term/{name}", []).append(term)
    env.close()
    return {k: np.stack(v) for k, v in chunks.items()}


def digests(run: Mapping[str, np.ndarray]) -> dict[str, str]:
    """sha256 of each quantity's float64 bytes, as the first records made them (their digests stay comparable)."""
    return {
        k: hashlib.sha256(np.ascontiguousarray(v, dtype=np.float64).tobytes()).hexdigest()
        for k, v in sorted(run.items())
        if k != "failed"
    }


def _signs(name: str, dim: int) -> np.ndarray:
    """Fixed +-1 projection vectors: any component's change shows in some projection, and integer draws make
    them the same on every machine."""
    rng = np.random.default_rng(int.from_bytes(hashlib.sha256(name.encode()).digest()[:4], "little"))
    return rng.integers(0, 2, size=(dim, PROJECTIONS)).astype(np.float64) * 2.0 - 1.0


def floats(run: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The compared floats, (steps, envs[, projections]): vectors projected (the observations' index 0 is the
    reset, the others' is the first step)."""
    out = {k: np.asarray(run[k], dtype=np.float64) for k in SCALARS}
    for k in VECTORS:
        v = np.asarray(run[k], dtype=np.float64)
        out[k] = (v[..., :, None] * _signs(k, v.shape[-1])).sum(axis=-2)
    return out


def exact(run: Mapping[str, np.ndarray], setting: str) -> dict:
    """What every CPU must reproduce exactly: shapes, the steps each env was done at, physics failures, and each
    episode's success (training: per env, each episode that ended; a success latches a step earlier or later
    between families, but which episodes succeed does not, docs/results/cpu_portability.md)."""
    done, success = run["done"], run["success"]
    out = {
        "shapes": {k: list(v.shape) for k, v in sorted(run.items())},
        "done_steps": [np.flatnonzero(done[:, i]).tolist() for i in range(done.shape[1])],
        "physics_failures": int(run["failed"].sum()),
    }
    if setting == "evaluation":
        out["success"] = [bool(s) for s in success[-1]]
    else:
        out["episode_successes"] = [
            [bool(success[start : end + 1, i].any()) for start, end in _episodes(done[:, i])]
            for i in range(done.shape[1])
        ]
    return out


def _episodes(done: np.ndarray) -> list[tuple[int, int]]:
    """(first step, last step) of each episode of one env that ended (an autoreset env's success flag is the
    episode's, latched, until the step its episode is done)."""
    ends = np.flatnonzero(done).tolist()
    return list(zip([0] + [e + 1 for e in ends[:-1]], ends, strict=True))


def successful_episodes(run: Mapping[str, np.ndarray]) -> int:
    return sum(map(sum, exact(run, "training")["episode_successes"]))


def _round(a: np.ndarray) -> list:
    return np.vectorize(lambda x: float(f"{x:.13g}"))(a).tolist() if a.size else []


def summary(
    runs: Mapping[str, Mapping[str, np.ndarray]],
    tolerance: Mapping[str, Mapping[str, list]],
    reward: Mapping[str, float],
) -> dict:
    """The record: exact quantities, the first steps' floats with their tolerances, the reward weights."""
    out: dict = {"reward_weights": dict(reward), "margin": MARGIN, "settings": {}}
    for s, run in runs.items():
        horizon = len(next(iter(tolerance[s].values())))
        out["settings"][s] = {
            "exact": exact(run, s),
            "horizon": horizon,
            "tolerance": tolerance[s],
            "floats": {k: _round(v[:horizon]) for k, v in floats(run).items()},
        }
    return out


def tolerances(base: Mapping[str, np.ndarray], stand_ins: list[Mapping[str, np.ndarray]]) -> dict[str, list]:
    """Per quantity and step: MARGIN x the largest deviation from `base` that any stand-in showed up to that
    step, plus FLOOR x the quantity's scale; cut at the first step where any tolerance passes MAX_TOLERANCE."""
    ref = floats(base)
    runs = [floats(r) for r in stand_ins]
    tol, horizon = {}, len(next(iter(ref.values())))
    for k, a in ref.items():
        scale = max(float(np.abs(a).max()), 1e-12)
        dev = np.zeros(len(a))
        for r in runs:
            dev = np.maximum(dev, np.abs(r[k] - a).reshape(len(a), -1).max(axis=1))
        tol[k] = MARGIN * np.maximum.accumulate(dev) + FLOOR * scale
        over = np.flatnonzero(tol[k] > MAX_TOLERANCE * scale)
        horizon = min(horizon, int(over[0]) if over.size else horizon)
    return {k: [float(f"{x:.3g}") for x in v[:horizon]] for k, v in tol.items()}


def _reward_identity(run: Mapping[str, np.ndarray], weights: Mapping[str, float]) -> int:
    """Steps x envs where the reward is not eq. 1 of the logged terms under the recorded weights (0 where the
    physics failed), summed in eq. 1's order as `rewards.total` does."""
    expected = 0.0
    for name, w in weights.items():
        expected = expected + w * run[f"term/{name}"]
    expected = np.where(run["failed"], 0.0, expected)
    return int((run["reward"] != expected).sum())


def compare(record: Mapping, runs: Mapping[str, Mapping[str, np.ndarray]], here: dict) -> list[str]:
    """Every way `runs` differs from `record`: always the exact quantities, eq. 1's identity and the first steps'
    floats within tolerance; bit for bit where a digest record of this platform exists."""
    problems = []
    weights = {k[2:]: v for k, v in record["reward_weights"].items() if k.startswith("w_")}
    for s, run in runs.items():
        rec = record["settings"][s]
        got = exact(run, s)
        for key, want in rec["exact"].items():
            if got[key] != want:
                problems.append(f"{s}: {key} differ: {got[key]} (recorded {want})")
        bad = _reward_identity(run, weights)
        if bad:
            problems.append(
                f"{s}: the reward is not eq. 1 of the terms under the recorded weights at {bad} "
                f"steps x envs (a reward weight or eq. 1 changed)"
            )
        problems += _compare_floats(s, rec, floats(run))
    problems += _compare_digests(record, runs, here)
    return problems


def _compare_floats(s: str, rec: Mapping, got: Mapping[str, np.ndarray]) -> list[str]:
    out = []
    h = rec["horizon"]
    for k, want in rec["floats"].items():
        want = np.asarray(want, dtype=np.float64)
        tol = np.asarray(rec["tolerance"][k]).reshape((h,) + (1,) * (want.ndim - 1))
        if got[k][:h].shape != want.shape:
            out.append(f"{s}: {k} has shape {got[k][:h].shape}, recorded {want.shape}")
            continue
        over = np.abs(got[k][:h] - want) > tol
        if over.any():
            t = int(np.flatnonzero(over.reshape(h, -1).any(axis=1))[0])
            dev = float(np.abs(got[k][t] - want[t]).max())
            out.append(
                f"{s}: {k} leaves its tolerance at index {t}: off by {dev:.3g}, tolerance {tol[t].max():.3g}"
            )
    return out


def _compare_digests(record: Mapping, runs: Mapping, here: dict) -> list[str]:
    got = {s: digests(run) for s, run in runs.items()}
    ours = [p for p in record.get("platforms", []) if float_platform.same(p.get("platform"), here)]
    if not ours or set(runs) != set(SETTINGS):
        return []  # an unrecorded family (or a partial run): the tolerant checks above are the whole check
    if any(all(got[s] == p["digests"][s] for s in SETTINGS) for p in ours):
        return []
    changed = sorted(
        {
            f"{s}/{k}"
            for p in ours
            for s in SETTINGS
            for k in p["digests"][s]
            if got[s].get(k) != p["digests"][s][k]
        }
    )
    return [
        f"on {float_platform.describe(here)}, a recorded platform, these quantities are no longer bit-identical: "
        f"{changed}"
    ]


def matching_platforms(record: Mapping, runs: Mapping) -> list[str]:
    """The recorded platforms (with or without a full platform record) whose digests `runs` reproduces."""
    got = {s: digests(run) for s, run in runs.items()}
    return [
        float_platform.describe(p.get("platform")) if p.get("platform") else repr(p.get("cpu"))
        for p in record.get("platforms", [])
        if all(got[s] == p["digests"][s] for s in SETTINGS)
    ]
