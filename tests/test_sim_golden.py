"""The simulation's task definition reproduces bit for bit: the shipped teacher, driven deterministically through
`BatchedGraspEnv`, sees the same observations, rewards (term by term), targets and successes as when this file's
golden digests were recorded (tests/data/sim_golden.json, written by `python tests/test_sim_golden.py --record`
from the code before a refactor: the current record from commit c75800d, before the reward terms were named and
the rejected teacher experiments retired). Two settings: evaluation (`EVAL_DR`, on the shipped teacher's own evaluation
start states, whose successes must also match its recorded `models/teacher_cpu_bc/eval/eval.json`) and training
(`PAPER_DR`: Table II's pushes, a multi-object batch with autoreset).

Any change that moves a float here changes the teacher's evaluation: such a change must re-record the teacher's
evaluation too, not only this file."""

from __future__ import annotations

import hashlib
import json
import sys
from pathlib import Path

import numpy as np
import pytest

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.durable import atomic_write_text
from lerobot_blindgrasp.sim import objects, randomization, rewards
from lerobot_blindgrasp.sim.env import BatchedGraspEnv, GraspEnvConfig
from lerobot_blindgrasp.sim.gym_env import start_seed
from lerobot_blindgrasp.teacher.policy import TeacherPolicy, default_teacher

GOLDEN = Path(__file__).parent / "data" / "sim_golden.json"
ROOT = Path(__file__).resolve().parents[1]
EVAL_OBJECTS = ("capsule_small", "sphere_small", "cuboid_a_large")
EPISODES = 2  # evaluation indices spec.EVAL_SEED .. + 1 of each object


def _digest(chunks: dict[str, list[np.ndarray]]) -> dict[str, str]:
    return {k: hashlib.sha256(b"".join(np.ascontiguousarray(a, dtype=np.float64).tobytes() for a in v)).hexdigest()
            for k, v in sorted(chunks.items())}


def _rollout(env: BatchedGraspEnv, teacher: TeacherPolicy, steps: int) -> tuple[dict[str, str], np.ndarray]:
    obs = env.reset()
    chunks: dict[str, list[np.ndarray]] = {"policy": [obs["policy"]], "privileged": [obs["privileged"]]}
    success = np.zeros(env.num_envs, dtype=bool)
    for _ in range(steps):
        obs, reward, terminated, truncated, info = env.step(teacher(obs, stochastic=False))
        for key, value in (("policy", obs["policy"]), ("privileged", obs["privileged"]), ("reward", reward),
                           ("joint_target", info["joint_target"]), ("lift", info["lift"]),
                           ("done", terminated | truncated), ("success", info["success"])):
            chunks.setdefault(key, []).append(value)
        for name, term in info["terms"].items():
            chunks.setdefault(f"term/{name}", []).append(term)
        success |= info["success"]
    env.close()
    return _digest(chunks), success


def compute() -> dict:
    """One torch thread: a matrix product's rounding depends on how many threads split it, and earlier tests in the
    same process may have changed the count."""
    import torch

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        return _compute()
    finally:
        torch.set_num_threads(threads)


def _compute() -> dict:
    teacher = TeacherPolicy(default_teacher())
    reward = rewards.RewardConfig.from_record(teacher.config["reward"]) if hasattr(
        rewards.RewardConfig, "from_record") else rewards.RewardConfig(**teacher.config["reward"])
    # Evaluation: one batch, each env on the start state blindgrasp-eval-teacher gives that episode
    seeds = tuple(start_seed(spec.EVAL_SEED + k, name) for name in EVAL_OBJECTS for k in range(EPISODES))
    names = tuple(name for name in EVAL_OBJECTS for _ in range(EPISODES))
    env = BatchedGraspEnv(GraspEnvConfig(num_envs=len(seeds), objects=names, env_seeds=seeds,
                                         dr=randomization.EVAL_DR, reward=reward, autoreset=False, nthread=1))
    evaluation, success = _rollout(env, teacher, env.max_episode_steps)
    # Training: Table II with pushes, 18 objects, autoreset across two short episodes
    env = BatchedGraspEnv(GraspEnvConfig(num_envs=18, seed=7, dr=randomization.PAPER_DR, reward=reward,
                                         episode_s=4.0, nthread=1))
    training, _ = _rollout(env, teacher, 2 * env.max_episode_steps + 5)
    return {"evaluation": evaluation, "training": training,
            "evaluation_success": {n: [bool(s) for s in success[i * EPISODES:(i + 1) * EPISODES]]
                                   for i, n in enumerate(EVAL_OBJECTS)}}


def _cpu() -> str:
    """The CPU model: MuJoCo's floats differ in the last bits between CPU families (the same code gave other
    digests on an AMD EPYC than on the machine of the first record, with every success and `done` equal)."""
    for line in Path("/proc/cpuinfo").read_text().splitlines() if Path("/proc/cpuinfo").exists() else []:
        if line.startswith("model name"):
            return line.split(":", 1)[1].strip()
    import platform

    return platform.processor() or platform.machine()


@pytest.mark.skipif(not GOLDEN.exists(), reason="no golden record")
def test_the_shipped_teacher_sees_the_same_simulation_bit_for_bit():
    """Bit for bit against one of the recorded CPU families' digests (`other_platforms`, added with
    `python tests/test_sim_golden.py --record-platform` on a machine whose floats differ, only after checking that
    the code is the recorded one); the successes must match on every machine."""
    golden = json.loads(GOLDEN.read_text())
    got = compute()
    assert got["evaluation_success"] == golden["evaluation_success"]
    records = [golden, *golden.get("other_platforms", [])]
    misses = []
    for record in records:
        changed = {setting: sorted(k for k in record[setting] if got[setting].get(k) != record[setting][k])
                   for setting in ("evaluation", "training")}
        if not any(changed.values()):
            for setting in ("evaluation", "training"):
                assert set(got[setting]) == set(record[setting])
            return
        misses.append(f"{record.get('cpu', 'first record')}: " + "; ".join(
            f"{setting}: these quantities changed: {keys}" for setting, keys in changed.items() if keys))
    raise AssertionError(f"on {_cpu()!r}, no recorded platform matches: " + " | ".join(misses))


def test_the_golden_successes_are_the_shipped_teachers_recorded_evaluation():
    recorded = json.loads((ROOT / "models/teacher_cpu_bc/eval/eval.json").read_text())
    per_object = recorded["modes"]["deterministic"]["per_object"]
    golden = json.loads(GOLDEN.read_text())
    assert recorded["seed"] == spec.EVAL_SEED and set(golden["evaluation_success"]) == set(EVAL_OBJECTS)
    for name, flags in golden["evaluation_success"].items():
        assert flags == per_object[name]["successes"][:EPISODES], name
    assert set(objects.CATALOGUE) >= set(EVAL_OBJECTS)


if __name__ == "__main__" and "--record" in sys.argv:
    atomic_write_text(GOLDEN, json.dumps(compute(), indent=1) + "\n")
    print("wrote", GOLDEN)
elif __name__ == "__main__" and "--record-platform" in sys.argv:
    golden, got = json.loads(GOLDEN.read_text()), compute()
    assert got["evaluation_success"] == golden["evaluation_success"], "the successes differ: not a float-only change"
    golden.setdefault("other_platforms", []).append(
        {"cpu": _cpu(), "evaluation": got["evaluation"], "training": got["training"]})
    atomic_write_text(GOLDEN, json.dumps(golden, indent=1) + "\n")
    print("added", _cpu(), "to", GOLDEN)
