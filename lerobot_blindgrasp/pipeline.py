"""`blindgrasp-pipeline --preset {quick,cpu,paper}`: the whole method, end to end, ending in a report.

    blindgrasp-pipeline --preset quick     # README command 1: the shipped teacher -> demos -> student -> eval, ~15 min
    blindgrasp-pipeline --preset cpu      # trains its own teacher from scratch: hours on 2 cores
    blindgrasp-pipeline --preset paper --device cuda    # the paper's tables: a GPU machine
    blindgrasp-pipeline --preset quick --teacher runs/teacher_cpu     # any teacher folder instead

Stages, each a real CLI run as a subprocess (its command and log are kept in <out>/logs/):
1. the teacher: the shipped default teacher (`quick`), a given `--teacher`, or trained from scratch
   (`blindgrasp-train-teacher`, presets `cpu`, `paper`, `smoke`);
2. curated demos (`blindgrasp-collect-demos`) as a LeRobotDataset;
3. the student (`lerobot-train --policy.type=blindgrasp_transformer`);
4. the student in sim (`lerobot-eval --env.type=blindgrasp`) and the teacher on the *same* start states
   (`blindgrasp-eval-teacher --seed` = lerobot-eval's `--seed`; see spec.eval_env_seed);
5. `report.md` with PNG plots: which teacher, teacher vs student success per object with 95 % Wilson intervals
   and paired counts, learning curves, demo yield, and the commands to go bigger.
A stage whose output is complete is skipped, so re-running after an interruption continues where it stopped.
Env seeds: teacher training from `--seed`, demos from the demo range, evaluation from the eval range
(`spec.SEED_RANGES`), so no start state is used twice.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shlex
import shutil
import subprocess
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path

from lerobot_blindgrasp import spec

SHIPPED = "shipped"  # PipelinePreset.teacher_preset: use the shipped default teacher, train nothing
# Each pipeline --seed gets its own block of demo env seeds, so reruns with another seed are new draws.
DEMO_SEED_BLOCK = 1 << 24


@dataclass(frozen=True)
class PipelinePreset:
    name: str
    teacher_preset: str  # a teacher preset to train from scratch, or SHIPPED
    teacher_eval_episodes: int  # per object and mode; = eval_episodes_per_object keeps teacher and student paired
    demo_episodes_per_object: int
    demo_max_rollouts_per_object: int
    demo_num_envs: int
    # Below this many curated episodes the student cannot learn anything; the pipeline then also collects the
    # uncurated ("w/o curation") set and trains on it, and says so in the report.
    min_curated_episodes: int
    student_size: str
    student_steps: int
    student_batch: int
    eval_episodes_per_object: int
    eval_task: str = "all"  # lerobot-eval --env.task
    teacher_iterations: int | None = None  # None: the teacher preset's own
    teacher_num_envs: int | None = None
    device: str = "cpu"  # student training and eval; --device overrides
    student_threads: int = 1  # OMP threads of lerobot-train (nothing else runs during that stage)
    eval_async_envs: bool = False  # lerobot-eval worker processes: worth it only with many cores (paper)
    # The paired comparison is the deterministic teacher's; the stochastic one (what demos come from) costs as
    # much again and is in the teacher's own card.
    teacher_eval_modes: tuple[str, ...] = ("deterministic", "stochastic")


PRESETS = {
    p.name: p
    for p in (
        # The method on the shipped teacher. 1200 steps at batch 128 is the recipe of docs/results/student_cpu.md
        # (~8 min on 2 idle cores); 20 episodes per object is the evaluation protocol's minimum.
        PipelinePreset("quick", SHIPPED, 20, 40, 400, 720, 18, "cpu", 1200, 128, 20, student_threads=2,
                       teacher_eval_modes=("deterministic",)),
        # lerobot-train reads ~2 ms per 30-frame sample here: 5000 steps at batch 256 is about an hour.
        PipelinePreset("cpu", "cpu", 20, 40, 400, 360, 90, "cpu", 5_000, 256, 20, student_threads=2),
        # Paper: 89,500 curated samples, 2000 epochs at batch 256 (Table IV) = 700k steps; 500 envs per object.
        PipelinePreset("paper", "paper", 50, 5000, 20_000, 9000, 1000, "paper", 700_000, 256, 50, device="cuda",
                       eval_async_envs=True),
        # CI smoke test of the plumbing only: every stage runs for seconds, a tiny teacher trained from scratch.
        PipelinePreset("smoke", "quick", 1, 1, 2, 36, 18, "quick", 4, 8, 1, eval_task="cylinder_a_medium",
                       teacher_iterations=2, teacher_num_envs=36),
    )
}

BIGGER = """\
Go bigger (same command, another preset):

    blindgrasp-pipeline --preset cpu     # trains a teacher from scratch on 2 cores: ~1.5-2 h teacher, then demos, student
    blindgrasp-pipeline --preset paper --device cuda   # GPU machine, the paper's Tables III-IV; see scripts/paper_recipe.sh
"""


class Stage:
    """Runs one CLI with its output in logs/<name>.log, and records command and wall time."""

    def __init__(self, out: Path, record: dict):
        self.out = out
        self.record = record
        (out / "logs").mkdir(parents=True, exist_ok=True)

    def run(self, name: str, cmd: list[str], env: dict | None = None, ok: tuple[int, ...] = (0,)) -> int:
        log_path = self.out / "logs" / f"{name}.log"
        print(f"[pipeline] {name}: {shlex.join(cmd)}", flush=True)
        t = time.time()
        with open(log_path, "w") as log:
            proc = subprocess.run(cmd, stdout=log, stderr=subprocess.STDOUT, env={**os.environ, **(env or {})})
        wall = time.time() - t
        self.record["stages"][name] = {"command": shlex.join(cmd), "wall_s": wall, "log": str(log_path)}
        self._save()
        if proc.returncode not in ok:
            tail = log_path.read_text().splitlines()[-25:]
            raise SystemExit(f"[pipeline] {name} failed (exit {proc.returncode}); last lines of {log_path}:\n" + "\n".join(tail))
        print(f"[pipeline] {name} done in {wall:.0f} s", flush=True)
        return proc.returncode

    def skip(self, name: str, why: str) -> None:
        print(f"[pipeline] {name}: skipped ({why})", flush=True)

    def _save(self) -> None:
        (self.out / "pipeline.json").write_text(json.dumps(self.record, indent=2))


def _bin(name: str) -> str:
    """The console script next to this interpreter (the venv's), so subprocesses use the same install."""
    cand = Path(sys.executable).parent / name
    return str(cand) if cand.exists() else name


def run_pipeline(preset: PipelinePreset, out: Path, seed: int, teacher: Path | None = None,
                 eval_seed: int = spec.EVAL_SEED, device: str | None = None) -> Path:
    device = device or preset.device
    demo_seed = spec.DEMO_SEED + seed * DEMO_SEED_BLOCK
    spec.check_seeds("demos", demo_seed, DEMO_SEED_BLOCK)  # one-line errors before any stage runs
    spec.eval_env_seed(eval_seed + max(preset.eval_episodes_per_object, preset.teacher_eval_episodes) - 1, 0)
    out.mkdir(parents=True, exist_ok=True)
    record_path = out / "pipeline.json"
    record = json.loads(record_path.read_text()) if record_path.exists() else {"stages": {}}
    record["preset"] = asdict(preset)
    record["seeds"] = {"pipeline": seed, "demos_first_env_seed": demo_seed, "eval_index": eval_seed}
    record["device"] = device
    stage = Stage(out, record)
    # One torch thread per process: on 2 cores, intra-op threads of several processes fight (measured ~50x slower
    # lerobot-train steps at the quick size); MuJoCo's own threads are unaffected.
    env1 = {"OMP_NUM_THREADS": "1", "HF_HUB_OFFLINE": "1", "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}

    teacher_dir, record["teacher"] = _teacher(stage, preset, out, seed, teacher)
    eval_objects = _objects(preset.eval_task)
    teacher_eval = out / "teacher_eval"
    if (teacher_eval / "eval.json").exists():
        stage.skip("teacher_eval", "done")
    elif _reuse_teacher_eval(teacher_dir, teacher_eval, preset, eval_seed, eval_objects):
        stage.skip("teacher_eval", f"the same start states were evaluated for this teacher in {teacher_dir / 'eval'}")
        record["teacher"]["eval_reused_from"] = str(teacher_dir / "eval")
    else:
        stage.run(
            "teacher_eval",
            [_bin("blindgrasp-eval-teacher"), str(teacher_dir), "--episodes", str(preset.teacher_eval_episodes),
             "--objects", ",".join(eval_objects), "--seed", str(eval_seed), "--modes",
             ",".join(preset.teacher_eval_modes), "--out", str(teacher_eval)],
        )

    repo = f"local/blindgrasp_{preset.name}"
    demos = _collect(stage, preset, teacher_dir, out / "demos", repo, demo_seed, curate=True)
    kept = _kept(demos)
    train_set = demos
    record["student_dataset"] = "curated"
    if kept < preset.min_curated_episodes:
        print(f"[pipeline] only {kept} curated episodes (< {preset.min_curated_episodes}); also collecting the "
              "uncurated set and training the student on it", flush=True)
        repo = f"local/blindgrasp_{preset.name}_uncurated"
        train_set = _collect(stage, preset, teacher_dir, out / "demos_uncurated", repo, demo_seed + DEMO_SEED_BLOCK // 2,
                             curate=False)
        record["student_dataset"] = "uncurated (too few curated episodes)"
    if _kept(train_set) == 0:
        raise SystemExit(f"[pipeline] error: the demo dataset {train_set} has no episodes, so there is nothing to "
                         "train the student on; use a better teacher (--teacher) or more rollouts")

    student = out / "student"
    ckpt = student / "checkpoints" / "last" / "pretrained_model"
    if ckpt.exists():
        stage.skip("student", "trained")
    else:
        if student.exists():  # an interrupted lerobot-train: its output dir must not exist unless resuming
            os.replace(student, out / f"student_interrupted_{int(time.time())}")
        stage.run(
            "student",
            [_bin("lerobot-train"), "--policy.type=blindgrasp_transformer", f"--policy.size={preset.student_size}",
             f"--dataset.repo_id={repo}", f"--dataset.root={train_set}", f"--output_dir={student}",
             f"--steps={preset.student_steps}", f"--batch_size={preset.student_batch}",
             f"--save_freq={preset.student_steps}", f"--log_freq={max(1, preset.student_steps // 50)}",
             "--policy.push_to_hub=false", f"--policy.device={device}", "--num_workers=0", "--wandb.enable=false",
             f"--seed={seed}"],
            env={**env1, "OMP_NUM_THREADS": str(preset.student_threads)},
        )
    student_eval = out / "student_eval"
    if (student_eval / "eval_info.json").exists():
        stage.skip("student_eval", "done")
    else:
        stage.run(
            "student_eval",
            [_bin("lerobot-eval"), f"--policy.path={ckpt}", "--env.type=blindgrasp", f"--env.task={preset.eval_task}",
             f"--eval.n_episodes={preset.eval_episodes_per_object}",
             f"--eval.batch_size={preset.eval_episodes_per_object}", f"--policy.device={device}",
             # In-process envs: on a few cores, one worker process per env only adds start-up and contention.
             f"--eval.use_async_envs={'true' if preset.eval_async_envs else 'false'}",
             f"--output_dir={student_eval}", f"--seed={eval_seed}"],
            env=env1,
        )
    from lerobot_blindgrasp.report import write_report  # matplotlib, only now

    report = write_report(out, record, BIGGER)
    print(f"[pipeline] report: {report}", flush=True)
    return report


def _objects(task: str) -> tuple[str, ...]:
    from lerobot_blindgrasp.sim import objects

    return objects.resolve_objects(task)


def _teacher(stage: Stage, preset: PipelinePreset, out: Path, seed: int, given: Path | None) -> tuple[Path, dict]:
    """The teacher folder for this run and what the report says about it."""
    from lerobot_blindgrasp.teacher.policy import TeacherError, TeacherPolicy, default_teacher

    if given is not None or preset.teacher_preset == SHIPPED:
        try:
            path = Path(given) if given is not None else default_teacher()
            t = TeacherPolicy(path)
        except TeacherError as e:
            raise SystemExit(f"[pipeline] error: {e}") from None
        stage.skip("teacher", f"using {'the given' if given is not None else 'the shipped default'} teacher {path}")
        source = "given (--teacher)" if given is not None else "shipped default"
        return path, {"source": source, "path": str(path), "file": t.name, "sha256": t.sha256,
                      "iteration": t.iteration, "preset": t.config.get("preset")}
    teacher_dir = out / "teacher"
    summary = teacher_dir / "train_summary.json"
    if summary.exists() and not json.loads(summary.read_text()).get("interrupted"):
        stage.skip("teacher", "trained")
    else:
        spec.check_seeds("teacher_train", seed, preset.teacher_num_envs or 1)
        cmd = [_bin("blindgrasp-train-teacher"), f"--preset={preset.teacher_preset}", f"--output_dir={teacher_dir}",
               f"--seed={seed}"]
        if preset.teacher_iterations:
            cmd.append(f"--iterations={preset.teacher_iterations}")
        if preset.teacher_num_envs:
            cmd.append(f"--num_envs={preset.teacher_num_envs}")
        stage.run("teacher", cmd)
    t = TeacherPolicy(teacher_dir)
    return teacher_dir, {"source": f"trained from scratch in this run (teacher preset `{preset.teacher_preset}`)",
                         "path": str(teacher_dir), "file": t.name, "sha256": t.sha256, "iteration": t.iteration,
                         "preset": preset.teacher_preset}


def _reuse_teacher_eval(teacher_dir: Path, dest: Path, preset: PipelinePreset, eval_seed: int,
                        eval_objects: tuple[str, ...]) -> bool:
    """A shipped teacher may carry its eval (`<folder>/eval/eval.json`). Rollouts are functions of (teacher, start
    states, torch seed, sim code), so an eval of the same weights on the same start states under the same sim
    sources is the paired eval; reuse it rather than spend minutes recomputing it."""
    from lerobot_blindgrasp.teacher.evaluate import sim_fingerprint
    from lerobot_blindgrasp.teacher.policy import TeacherPolicy

    src = teacher_dir / "eval" / "eval.json"
    if not src.is_file():
        return False
    prev = json.loads(src.read_text())
    same = (
        prev.get("checkpoint_sha256") == TeacherPolicy(teacher_dir).sha256
        and prev.get("sim_fingerprint") == sim_fingerprint()
        and prev.get("seed") == eval_seed
        and prev.get("episodes_per_object") == preset.teacher_eval_episodes
        and prev.get("objects") == list(eval_objects)
        and set(preset.teacher_eval_modes) <= set(prev.get("modes", {}))
    )
    if same:
        shutil.copytree(src.parent, dest)
    return same


def _collect(stage: Stage, preset: PipelinePreset, teacher: Path, root: Path, repo_id: str, first_seed: int,
             curate: bool) -> Path:
    name = "demos" if curate else "demos_uncurated"
    if (root / "yield_report.json").exists() and (root / "meta" / "info.json").exists():
        stage.skip(name, "collected")
        return root
    cmd = [_bin("blindgrasp-collect-demos"), "--teacher", str(teacher), "--out", str(root), "--repo-id", repo_id,
           "--episodes-per-object", str(preset.demo_episodes_per_object),
           "--max-rollouts-per-object", str(preset.demo_max_rollouts_per_object),
           "--num-envs", str(preset.demo_num_envs), "--seed", str(first_seed), "--no-progress"]
    if not curate:
        cmd.append("--no-curation")
    if root.exists():
        cmd.append("--resume")
    from lerobot_blindgrasp.demos.collect import EXIT_EMPTY

    stage.run(name, cmd, ok=(0, EXIT_EMPTY))  # an empty curated set is handled by the caller (uncurated fallback)
    return root


def _kept(root: Path) -> int:
    report = json.loads((root / "yield_report.json").read_text())
    return int(report["total"]["kept"])


def parse_step(s: str) -> float:
    m = re.fullmatch(r"([\d.]+)([KMB]?)", s)
    if not m:
        raise ValueError(s)
    return float(m.group(1)) * {"": 1, "K": 1e3, "M": 1e6, "B": 1e9}[m.group(2)]


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--preset", choices=sorted(PRESETS), default="quick")
    p.add_argument("--output-dir", type=Path, default=None, help="default: outputs/pipeline_<preset>")
    p.add_argument("--seed", type=int, default=spec.TEACHER_TRAIN_SEED,
                   help="teacher-training env seed and torch seed; also picks the block of demo env seeds")
    p.add_argument("--teacher", type=Path, default=None,
                   help="use this teacher folder instead of the preset's (shipped or trained from scratch)")
    p.add_argument("--eval-seed", type=int, default=spec.EVAL_SEED,
                   help="lerobot-eval --seed, and the teacher eval's: both run the same start states")
    p.add_argument("--device", default=None, help="torch device for the student (default: the preset's)")
    args = p.parse_args(argv)
    out = args.output_dir or Path("outputs") / f"pipeline_{args.preset}"
    try:
        run_pipeline(PRESETS[args.preset], out, args.seed, args.teacher, args.eval_seed, args.device)
    except ValueError as e:  # seeds outside their ranges
        raise SystemExit(f"[pipeline] error: {e}") from None


if __name__ == "__main__":
    main()
