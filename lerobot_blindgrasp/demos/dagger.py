"""`blindgrasp-dagger`: DAgger-style relabelling of a student's own rollouts (Ross et al., 2011). Beyond the paper.
A student trained offline meets states its demos never show once its own errors add up, so the *student* drives and
every state it visits is labelled with the target the env would command for the *teacher's* mean action.
`<output_dir>/aggregate`, those episodes merged with the demos, is the next student's training set.
"""

from __future__ import annotations

import functools
import json
import shutil
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from lerobot_blindgrasp import compat, spec
from lerobot_blindgrasp.cli import parse_config
from lerobot_blindgrasp.demos import curation
from lerobot_blindgrasp.demos import dataset as demo_dataset
from lerobot_blindgrasp.demos.collection_loop import _cleanup
from lerobot_blindgrasp.demos.episode_writer import EpisodeWriter
from lerobot_blindgrasp.durable import atomic_write_json
from lerobot_blindgrasp.rollout.actors import StudentActor, TeacherActor
from lerobot_blindgrasp.rollout.envs import make_batched_env
from lerobot_blindgrasp.rollout.loop import Episode, run_batch
from lerobot_blindgrasp.sim import objects
from lerobot_blindgrasp.teacher.policy import TeacherPolicy, default_teacher

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
    writer_queue: int = 256  # episodes waiting for the writer thread (as blindgrasp-collect-demos); 0: in the loop
    progress: bool = True

    def __post_init__(self):
        for name in ("student", "demos", "output_dir"):
            if getattr(self, name) is None:
                raise ValueError(f"--{name} is required")
        self.student, self.demos, self.output_dir = Path(self.student), Path(self.demos), Path(self.output_dir)
        n = len(objects.resolve_objects(self.objects)) * self.episodes_per_object
        spec.check_seeds("demos", self.seed, n)


# What a relabelled episode keeps of each step: o_t, r_t and the forces; its action is the teacher's label.
TRACES = ("state", "task_reward", "uniaxial_force")


def relabelled_episodes(
    student: StudentActor, teacher: TeacherPolicy, names: list[str], seed: int
) -> list[Episode]:
    """One batch (env i: object names[i], seed + i) for 10 s under the student; each episode's action is what the
    env would have commanded for the teacher's mean action on the states the student visited."""
    env = make_batched_env("dagger", tuple(dict.fromkeys(names)), num_envs=len(names), seed=seed)
    if list(env.object_names) != list(names):
        raise RuntimeError("object allocation differs from the requested batch")
    label = TeacherActor(teacher).target
    student.reset()
    return run_batch(env, student, record=TRACES, labels={"action": (spec.ACTION_DIM, label)})


def run_dagger(cfg: DaggerConfig) -> dict:
    out = cfg.output_dir
    if (out / DONE).is_file():
        return json.loads((out / DONE).read_text())
    # An unfinished earlier run left partial datasets: start them over (minutes of rollouts, nothing else lost).
    for part in ("relabelled", "aggregate"):
        if (out / part).exists():
            shutil.rmtree(out / part)
    out.mkdir(parents=True, exist_ok=True)
    names = objects.resolve_objects(cfg.objects)
    student = StudentActor.load(cfg.student, names, cfg.device)
    teacher = TeacherPolicy(cfg.teacher or default_teacher())
    todo = [name for _ in range(cfg.episodes_per_object) for name in names]
    ds = demo_dataset.create(out / "relabelled", cfg.repo_id + "_relabelled")
    t0 = time.perf_counter()
    stats = {"episodes": 0, "frames": 0, "student_successes": 0}
    per_object = {name: [] for name in names}
    torch.manual_seed(0)
    bar = tqdm(total=len(todo), desc="dagger", unit="ep", disable=not cfg.progress)
    writer = EpisodeWriter(cfg.writer_queue)  # the next batch rolls out while this one is written
    try:
        for start in range(0, len(todo), cfg.num_envs):
            batch = todo[start : start + cfg.num_envs]
            for ep in relabelled_episodes(student, teacher, batch, cfg.seed + start):
                cut = _whole(ep)
                writer.submit(functools.partial(demo_dataset.write_episode, ds, ep, cut))
                stats["frames"] += cut.keep_steps
                stats["episodes"] += 1
                stats["student_successes"] += ep.success
                per_object[ep.object_name].append(ep.success)
                bar.update(1)
        writer.flush()
    finally:
        bar.close()
        try:
            with _cleanup("writing the queued episodes", sys.exc_info()[1]):
                writer.close()  # what was rolled out is written, also on Ctrl-C
        finally:
            with _cleanup("finalizing the dataset", sys.exc_info()[1]):  # never masks the error that ended it
                compat.finalize_or_abandon(ds)
    demo_dataset.aggregate(
        [f"local/{cfg.demos.name}", cfg.repo_id + "_relabelled"],  # info.json keeps no repo id
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


def _whole(ep: Episode) -> curation.CurationResult:
    """A relabelled episode is kept whole: the student's own rollout, whatever happened."""
    return curation.CurationResult(
        passed=False,
        keep=True,
        keep_steps=ep.length,
        longest_hold_steps=0,
        force_sum_n=float(ep.uniaxial_force.sum()),
        criteria_step=-1,
    )


def main(argv=None) -> None:
    cfg = parse_config(DaggerConfig, argv)
    record = run_dagger(cfg)
    print(
        f"relabelled {record['episodes']} student episodes ({record['frames']} frames; the student succeeded in "
        f"{record['student_successes']}) in {record['wall_s']:.0f} s; training set: {record['aggregate']}"
    )


if __name__ == "__main__":
    main()
