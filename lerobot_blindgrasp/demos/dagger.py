"""`blindgrasp-dagger`: DAgger-style relabelling of a student's own rollouts. Beyond the paper.

    blindgrasp-dagger --student=outputs/x/student/checkpoints/last/pretrained_model \
        --demos=outputs/x/demos --output_dir=outputs/x/dagger --episodes_per_object=10

The paper trains the student offline, on curated rollouts of the stochastic teacher. A student trained that way
meets states its demos never show once its own small errors add up (compounding error), and nothing taught it how
to recover from them. DAgger (Ross et al., 2011) closes that gap: the *student* drives the episodes, and every state
it visits is labelled with the action the privileged *teacher* would take there (its deterministic mean). Only the
student's own actions move the gripper; the teacher only labels.

Output: `<output_dir>/relabelled`, a LeRobotDataset of those episodes (same schema as the demos; each episode whole,
10 s or until the object left the workspace; `episode.outcome` says whether the student succeeded), and
`<output_dir>/aggregate`, the demos and the relabelled episodes merged with LeRobot's own `aggregate_datasets`:
the dataset the next student trains on. Start states come from their own block of the demo seed range, disjoint
from the demos' and from evaluation.

Label: target = clip(q + clip(a_teacher, +-0.3 rad), joint limits), exactly the target the env would have commanded
for the teacher's action (`BatchedGraspEnv.step`), with q the true joint positions.
"""

from __future__ import annotations

import json
import shutil
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.cli import parse_config
from lerobot_blindgrasp.demos import curation
from lerobot_blindgrasp.demos import dataset as demo_dataset
from lerobot_blindgrasp.demos.loop import _cleanup, _finalize_or_abandon
from lerobot_blindgrasp.demos.rollout import RANDOMIZATION_NAMES, Episode
from lerobot_blindgrasp.durable import atomic_write_json
from lerobot_blindgrasp.sim import objects

# Block 2^10 of the demo seed range (blocks of 2^24 env seeds; the pipeline's demos use block `--seed`, 1 by
# default): never shared with a demo collection.
DAGGER_SEED = spec.DEMO_SEED + (1 << 10) * (1 << 24)
DONE = "dagger_done.json"  # written last: its presence means both datasets are complete


@dataclass
class DaggerConfig:
    """Roll out a student, label what it visits with the teacher's mean action, aggregate with its demos."""

    student: Path | None = None  # a LeRobot pretrained_model folder of blindgrasp_transformer
    teacher: Path | None = None  # teacher folder; default: the shipped teacher
    demos: Path | None = None  # the student's training dataset, merged with the relabelled episodes
    output_dir: Path | None = None
    repo_id: str = "local/blindgrasp_dagger"
    episodes_per_object: int = 10
    objects: str = "all"  # "all", "medium", or a comma-separated list of catalogue names
    num_envs: int = 360  # envs stepped together (episodes of all objects at once)
    seed: int = DAGGER_SEED  # first env seed, in the demo seed range
    device: str = "cpu"
    progress: bool = True

    def __post_init__(self):
        for name in ("student", "demos", "output_dir"):
            if getattr(self, name) is None:
                raise ValueError(f"--{name} is required")
        self.student, self.demos, self.output_dir = Path(self.student), Path(self.demos), Path(self.output_dir)
        n = len(objects.resolve_objects(self.objects)) * self.episodes_per_object
        spec.check_seeds("demos", self.seed, n)


def label_targets(q: np.ndarray, teacher_action: np.ndarray) -> np.ndarray:
    """The absolute targets the env commands for a teacher action at true joints q (both (n, 9))."""
    step = np.clip(teacher_action, -spec.ACTION_BOUND_RAD, spec.ACTION_BOUND_RAD)
    return np.clip(q + step, spec.JOINT_LOWER, spec.JOINT_UPPER)


def relabelled_episodes(act_student, reset_student, teacher, names: list[str], seed: int):
    """Run one batch (env i: object names[i], seed + i) for 10 s under the student; yield one Episode per env with
    the teacher's labels."""
    from lerobot_blindgrasp.analysis.student_diagnosis import Outcomes
    from lerobot_blindgrasp.sim.env import BatchedGraspEnv, GraspEnvConfig
    from lerobot_blindgrasp.sim.randomization import EVAL_DR

    env = BatchedGraspEnv(
        GraspEnvConfig(
            num_envs=len(names), objects=tuple(dict.fromkeys(names)), seed=seed, dr=EVAL_DR, autoreset=False
        )
    )
    if list(env.object_names) != list(names):
        raise RuntimeError("object allocation differs from the requested batch")
    n, horizon = env.num_envs, env.max_episode_steps
    state = np.zeros((n, horizon, spec.STATE_DIM), np.float32)
    label = np.zeros((n, horizon, spec.ACTION_DIM), np.float32)
    task = np.zeros((n, horizon))
    force = np.zeros((n, horizon, spec.NUM_FORCES))
    ends = Outcomes(n, horizon)
    reset_student()
    obs = env.reset()
    start_xy = env.object_position()[:, :2].copy()
    for t in range(horizon):
        q = env.joint_positions()
        state[:, t] = obs["policy"]
        label[:, t] = label_targets(q, teacher(obs, stochastic=False))
        obs, _, term, trunc, info = env.step(act_student(obs) - q)
        task[:, t] = info["terms"]["task"]
        force[:, t] = info["uniaxial_force"]
        if not ends.update(t, info, term, trunc):
            break
    draws = [env.physics_draw.row(i) for i in range(n)]
    env.close()
    for i in range(n):
        k = int(ends.length[i])
        yield Episode(
            object_name=names[i],
            state=state[i, :k],
            action=label[i, :k],
            task_reward=task[i, :k],
            uniaxial_force=force[i, :k],
            success=bool(ends.success[i]),
            left_workspace=bool(ends.left[i]),
            physics_failed=False,
            env_seed=seed + i,
            env_episode=0,
            randomization=np.array([*(draws[i][p] for p in RANDOMIZATION_NAMES[:5]), *start_xy[i]], np.float64),
        )


def run(cfg: DaggerConfig) -> dict:
    from lerobot_blindgrasp.analysis.student_diagnosis import load_student, student_actor
    from lerobot_blindgrasp.teacher.policy import TeacherPolicy, default_teacher

    out = cfg.output_dir
    if (out / DONE).is_file():
        return json.loads((out / DONE).read_text())
    # An unfinished earlier run left partial datasets: start them over (minutes of rollouts, nothing else lost).
    for part in ("relabelled", "aggregate"):
        if (out / part).exists():
            shutil.rmtree(out / part)
    out.mkdir(parents=True, exist_ok=True)
    policy, pre, post = load_student(cfg.student, cfg.device)
    act = student_actor(policy, pre, post)
    teacher = TeacherPolicy(cfg.teacher or default_teacher())
    names = objects.resolve_objects(cfg.objects)
    todo = [name for _ in range(cfg.episodes_per_object) for name in names]
    ds = demo_dataset.create(out / "relabelled", cfg.repo_id + "_relabelled")
    t0 = time.perf_counter()
    stats = {"episodes": 0, "frames": 0, "student_successes": 0}
    per_object = {name: [] for name in names}
    torch.manual_seed(0)
    bar = tqdm(total=len(todo), desc="dagger", unit="ep", disable=not cfg.progress)
    try:
        for start in range(0, len(todo), cfg.num_envs):
            batch = todo[start : start + cfg.num_envs]
            for ep in relabelled_episodes(act, policy.reset, teacher, batch, cfg.seed + start):
                cut = curation.CurationResult(
                    passed=False,
                    keep=True,
                    keep_steps=ep.length,
                    longest_hold_steps=0,
                    force_sum_n=float(ep.uniaxial_force.sum()),
                    criteria_step=-1,
                )
                stats["frames"] += demo_dataset.write_episode(ds, ep, cut)
                stats["episodes"] += 1
                stats["student_successes"] += ep.success
                per_object[ep.object_name].append(ep.success)
                bar.update(1)
    finally:
        bar.close()
        with _cleanup("finalizing the dataset", sys.exc_info()[1]):  # never masks the error that ended the run
            _finalize_or_abandon(ds)
    demo_dataset.aggregate(
        [_repo_id(cfg.demos), cfg.repo_id + "_relabelled"],
        [cfg.demos, out / "relabelled"],
        cfg.repo_id,
        out / "aggregate",
    )
    record = {
        "student": str(cfg.student),
        "teacher": str(teacher.checkpoint),
        "teacher_sha256": teacher.sha256,
        "demos": str(cfg.demos),
        "episodes_per_object": cfg.episodes_per_object,
        "first_env_seed": cfg.seed,
        "wall_s": time.perf_counter() - t0,
        **stats,
        "student_success_per_object": {k: float(np.mean(v)) for k, v in per_object.items() if v},
        "aggregate": str(out / "aggregate"),
    }
    atomic_write_json(out / DONE, record, indent=2)
    return record


def _repo_id(root: Path) -> str:
    info = json.loads((Path(root) / "meta" / "info.json").read_text())
    return info.get("repo_id") or f"local/{Path(root).name}"


def main(argv=None) -> None:
    cfg = parse_config(DaggerConfig, argv)
    record = run(cfg)
    print(
        f"relabelled {record['episodes']} student episodes ({record['frames']} frames; the student succeeded in "
        f"{record['student_successes']}) in {record['wall_s']:.0f} s; training set: {record['aggregate']}"
    )


if __name__ == "__main__":
    main()
